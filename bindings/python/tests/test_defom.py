"""DEFOM-Stereo from an official checkpoint in Python: the seeded ViT-S of the conformance file
(``../shared/golden``) written as an official ``.pth`` loads with ``Model(path)``, its
configuration read from the tensors; it predicts, and its ONNX export matches ``predict`` within
1e-3 px in ONNX Runtime, the scale and the normal update iterations included. A name published
only on a page (IGEV-Stereo's) says where to download it."""

import numpy as np
import pytest

import dgstereo
from official_pth import golden_state_dict, write_pth
from test_onnx_export import golden, need, nchw, run_onnx

SIZE = (64, 96)


@pytest.fixture(scope="module")
def defom_pth(tmp_path_factory):
    state = golden_state_dict(golden("defom_stereo_vits_seeded.activations.safetensors"))
    path = tmp_path_factory.mktemp("defom") / "defomstereo_vits_sceneflow.pth"
    write_pth(state, path)
    return path


@pytest.fixture(scope="module")
def pair():
    rng = np.random.default_rng(11)
    left = rng.integers(0, 256, (*SIZE, 3), dtype=np.uint8)
    return left, np.roll(left, -3, axis=1)


def test_an_official_defom_checkpoint_loads_and_predicts(defom_pth, pair):
    model = dgstereo.Model(defom_pth)
    assert "DEFOM-Stereo: Depth Anything V2 vits, scale update 8 iterations" in model.summary, model.summary
    assert "preset: DEFOM-Stereo" in model.summary and model.default_iters == 32
    disp, info = model.predict(*pair, iters=2, min_size=None, return_info=True)
    assert disp.shape == SIZE and disp.dtype == np.float32 and np.isfinite(disp).all()
    assert info["network_size"] == SIZE
    # The disparity starts from the monocular network's and is refined: other iterations differ.
    assert np.abs(model.predict(*pair, iters=3, min_size=None) - disp).max() > 0


def test_the_defom_model_exports_to_onnx_matching_predict(defom_pth, pair, tmp_path):
    need("onnxruntime")
    model = dgstereo.Model(defom_pth)
    # 9 iterations: the 8 scale iterations and one of the normal update block.
    info = model.export_onnx(tmp_path / "defom.onnx", SIZE, iters=9)
    assert [n for n, _ in info["inputs"]] == ["left", "right"]
    left, right = pair
    got = run_onnx(tmp_path / "defom.onnx", {"left": nchw(left), "right": nchw(right)})[0, 0]
    want = model.predict(left, right, iters=9, min_size=None, corr="reg")
    assert np.abs(got - want).max() <= 1e-3, np.abs(got - want).max()


def test_a_name_downloaded_by_hand_says_where_to_get_it(tmp_path, monkeypatch):
    monkeypatch.setenv("DGSTEREO_CACHE", str(tmp_path))
    monkeypatch.setenv("DGSTEREO_OFFLINE", "1")
    with pytest.raises(dgstereo.Error, match="drive.google.com/drive/folders/"):
        dgstereo.Model("igev-stereo-sceneflow")
    assert not (tmp_path / "igev-stereo-sceneflow" / "sceneflow.pth").exists()
