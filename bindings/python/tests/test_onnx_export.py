"""ONNX export: the exported official checkpoints of ../shared/golden (the default and the
realtime architecture) and the bundled paper model (DGIA's deformable convolution as ONNX
DeformConv, the prior maps as inputs) run in ONNX Runtime on a crop of the Cones pair and match
``dgstereo infer --min-size off`` / ``Model.predict(min_size=None)`` within 1e-3 px; the files
pass ``onnx.checker``; what cannot be exported is an error and no file.

Needs ``onnx`` and ``onnxruntime`` (scripts/test installs them into the test venv); without
them the tests are skipped, and under CI=true they fail."""

import os
import pathlib
import struct
import subprocess
import zlib

import numpy as np
import pytest

import dgstereo
from conftest import CONES, ROOT, cli_binary

CI = os.environ.get("CI") == "true"
SIZE = (96, 128)


def need(module):
    try:
        return __import__(module)
    except ImportError:
        if CI:
            raise
        pytest.skip(f"no {module} (pip install onnx onnxruntime)")


def golden(name):
    shared = pathlib.Path(os.environ.get("DGSTEREO_SHARED") or ROOT.parent / "shared")
    path = shared / "golden" / name
    if not path.exists():
        assert not CI, f"CI=true and the reference checkpoint {path} is missing"
        pytest.skip(f"no {path}")
    return path


def cli():
    exe = cli_binary()
    if exe is None:
        assert not CI, "CI=true and no dgstereo binary"
        pytest.skip("no dgstereo binary (build it with cargo, or set DGSTEREO_CLI)")
    return exe


def write_png(path, rgb):
    """An 8-bit RGB PNG (the standard library suffices)."""
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].tobytes() for y in range(h))

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


@pytest.fixture(scope="module")
def crop():
    left = dgstereo.read_image(CONES / "left_rgb.png")[100 : 100 + SIZE[0], 200 : 200 + SIZE[1]]
    right = dgstereo.read_image(CONES / "right_rgb.png")[100 : 100 + SIZE[0], 200 : 200 + SIZE[1]]
    return np.ascontiguousarray(left.astype(np.uint8)), np.ascontiguousarray(right.astype(np.uint8))


def nchw(image):
    return np.ascontiguousarray(image.astype(np.float32).transpose(2, 0, 1)[None])


def run_onnx(path, feed):
    onnx = need("onnx")
    ort = need("onnxruntime")
    onnx.checker.check_model(onnx.load(str(path)), full_check=True)
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    assert [i.name for i in session.get_inputs()] == list(feed)
    assert [o.name for o in session.get_outputs()] == ["disparity"]
    return session.run(None, feed)[0]


@pytest.mark.parametrize("checkpoint,iters", [("raft_stereo_random.pth", 4), ("raft_stereo_realtime_random.pth", None)])
def test_exported_checkpoints_match_infer(tmp_path, crop, checkpoint, iters):
    need("onnxruntime")
    exe, weights = cli(), golden(checkpoint)
    left, right = crop
    write_png(tmp_path / "left.png", left)
    write_png(tmp_path / "right.png", right)
    its = [] if iters is None else ["--iters", str(iters)]
    out = subprocess.run(
        [exe, "export", "onnx", "--weights", str(weights), "--size", f"{SIZE[0]}x{SIZE[1]}", *its, "-o", str(tmp_path / "m.onnx")],
        check=True, capture_output=True, text=True,
    ).stdout
    assert "opset 19" in out and "disparity 1x1x96x128" in out, out
    subprocess.run(
        [exe, "infer", "-l", str(tmp_path / "left.png"), "-r", str(tmp_path / "right.png"), "--weights", str(weights),
         *its, "--min-size", "off", "--save", "pfm", "-o", str(tmp_path / "infer")],
        check=True, capture_output=True,
    )
    want = dgstereo.read_pfm(next((tmp_path / "infer").glob("*.pfm")))
    got = run_onnx(tmp_path / "m.onnx", {"left": nchw(left), "right": nchw(right)})[0, 0]
    assert got.shape == want.shape
    assert np.abs(got - want).max() <= 1e-3, np.abs(got - want).max()


def test_the_paper_model_exports_with_its_prior_maps_as_inputs(tmp_path, crop):
    need("onnxruntime")
    model = dgstereo.Model(weights=ROOT / "assets" / "weights" / "paper-default.safetensors")
    left, right = crop
    y, x = np.mgrid[0 : SIZE[0], 0 : SIZE[1]]
    prior_left = (0.3 + 0.5 * y / SIZE[0] + 0.1 * np.sin(x / 9.0)).astype(np.float32)
    prior_right = np.roll(prior_left, -2, axis=1)
    info = model.export_onnx(tmp_path / "paper.onnx", SIZE, iters=3)
    assert info["opset"] == 19
    assert [n for n, _ in info["inputs"]] == ["left", "right", "left_prior", "right_prior"]
    got = run_onnx(
        tmp_path / "paper.onnx",
        {"left": nchw(left), "right": nchw(right), "left_prior": prior_left[None, None], "right_prior": prior_right[None, None]},
    )[0, 0]
    want = model.predict(left, right, iters=3, min_size=None, corr="reg", prior=(prior_left, prior_right))
    assert np.abs(got - want).max() <= 1e-3, np.abs(got - want).max()


def test_what_cannot_be_exported_is_an_error_and_no_file(tmp_path):
    exe = cli()
    target = tmp_path / "m.onnx"
    for extra, says in [(["--size", "96x128", "--dynamic"], "--dynamic"), (["--size", "96"], "HxW")]:
        run = subprocess.run([exe, "export", "onnx", *extra, "-o", str(target)], capture_output=True, text=True)
        assert run.returncode != 0 and says in run.stderr, run.stderr
        assert not target.exists() and not list(tmp_path.iterdir())
    with pytest.raises(dgstereo.Error, match="size"):
        dgstereo.Model().export_onnx(target, (0, 64), iters=1)
    assert not target.exists()


def test_the_bundled_default_exports_at_its_narrowest_sizes(tmp_path, capfd):
    # The 1/8-resolution default pools its correlation pyramid below one column at these widths.
    need("onnxruntime")
    model = dgstereo.Model()
    rng = np.random.default_rng(5)
    for size in [(64, 64), (32, 48)]:
        info = model.export_onnx(tmp_path / "small.onnx", size, iters=1)
        assert info["outputs"] == [("disparity", [1, 1, *size])]
        left = rng.integers(0, 256, (*size, 3), dtype=np.uint8)
        right = np.roll(left, -2, axis=1)
        got = run_onnx(tmp_path / "small.onnx", {"left": nchw(left), "right": nchw(right)})[0, 0]
        want = model.predict(left, right, iters=1, min_size=None, corr="reg")
        assert np.abs(got - want).max() <= 1e-3, (size, np.abs(got - want).max())
    with pytest.raises(dgstereo.Error, match="16x64"):
        model.export_onnx(tmp_path / "tiny.onnx", (16, 64), iters=1)
    err = capfd.readouterr().err
    assert "panicked" not in err and "backtrace" not in err, err
