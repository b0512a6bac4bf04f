"""The default weights travel with the package (``dgstereo/assets/weights``), and a package
without them refuses to guess: ``Model()`` raises an error naming the missing file."""

import os
import pathlib
import shutil
import subprocess
import sys

import dgstereo


def test_the_default_model_is_the_packaged_one():
    model = dgstereo.Model()
    packaged = pathlib.Path(dgstereo.BUNDLED_ASSETS) / "weights" / "raft-stereo-default.safetensors"
    assert packaged.is_file()
    assert pathlib.Path(model.weights).samefile(packaged)
    assert (pathlib.Path(dgstereo.BUNDLED_ASSETS) / "weights" / "README.md").is_file()


def test_a_package_without_its_weights_raises_naming_them(tmp_path):
    # A copy of the package (native module included) with no assets/, imported from elsewhere.
    source = pathlib.Path(dgstereo.__file__).parent
    shutil.copytree(source, tmp_path / "dgstereo", ignore=shutil.ignore_patterns("assets", "__pycache__"))
    env = {k: v for k, v in os.environ.items() if k not in ("DGSTEREO_ASSETS", "PYTHONPATH")}
    script = (
        "import dgstereo\n"
        "try:\n"
        "    dgstereo.Model()\n"
        "except dgstereo.Error as e:\n"
        "    print('ERROR', e)\n"
        "else:\n"
        "    print('LOADED')\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True, check=True
    ).stdout
    assert out.startswith("ERROR"), out
    assert "weights/raft-stereo-default.safetensors" in out and "weights list" in out, out
    assert str(tmp_path / "dgstereo" / "assets") in out, out


def test_an_unknown_weights_name_lists_the_known_ones():
    try:
        dgstereo.Model("raftstereo-kitti")
    except dgstereo.Error as e:
        assert "raftstereo-middlebury" in str(e) and "weights list" in str(e), e
    else:
        raise AssertionError("an unknown name loaded")


def test_a_missing_name_offline_names_the_fetch_command(tmp_path):
    env = dict(os.environ, DGSTEREO_CACHE=str(tmp_path), DGSTEREO_OFFLINE="1")
    script = (
        "import dgstereo\n"
        "try:\n"
        "    dgstereo.Model('raftstereo-eth3d')\n"
        "except dgstereo.Error as e:\n"
        "    print('ERROR', e)\n"
    )
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True).stdout
    assert "dgstereo weights fetch raftstereo-eth3d" in out, out
