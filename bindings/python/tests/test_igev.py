"""IGEV-Stereo from an official checkpoint in Python: the seeded weights of the conformance file
(``../shared/golden/igev_stereo_seeded.activations.safetensors``) written as an official ``.pth``
load with ``Model(path)``, the configuration read from the tensors; the model predicts from the
geometry volume's soft-argmin start, and its ONNX export (3D convolutions, the hourglass's
transposed 3D convolutions, the combined lookup's masks) matches ``predict`` within 1e-3 px in
ONNX Runtime."""

import numpy as np
import pytest

import dgstereo
from official_pth import golden_state_dict, write_pth
from test_onnx_export import golden, need, nchw, run_onnx

SIZE = (64, 96)


@pytest.fixture(scope="module")
def igev_pth(tmp_path_factory):
    state = golden_state_dict(golden("igev_stereo_seeded.activations.safetensors"))
    path = tmp_path_factory.mktemp("igev") / "sceneflow.pth"
    write_pth(state, path)
    return path


@pytest.fixture(scope="module")
def pair():
    rng = np.random.default_rng(13)
    left = rng.integers(0, 256, (*SIZE, 3), dtype=np.uint8)
    return left, np.roll(left, -3, axis=1)


def test_an_official_igev_checkpoint_loads_and_predicts(igev_pth, pair):
    model = dgstereo.Model(igev_pth)
    assert "IGEV-Stereo: geometry volume max_disp 192" in model.summary, model.summary
    assert model.default_iters == 32
    disp, info = model.predict(*pair, iters=2, min_size=None, return_info=True)
    assert disp.shape == SIZE and disp.dtype == np.float32 and np.isfinite(disp).all()
    assert info["network_size"] == SIZE
    # The update iterations refine the soft-argmin start: another count gives another disparity.
    assert np.abs(model.predict(*pair, iters=3, min_size=None) - disp).max() > 0


def test_the_igev_model_exports_to_onnx_matching_predict(igev_pth, pair, tmp_path):
    need("onnxruntime")
    model = dgstereo.Model(igev_pth)
    info = model.export_onnx(tmp_path / "igev.onnx", SIZE, iters=2)
    assert [n for n, _ in info["inputs"]] == ["left", "right"]
    left, right = pair
    got = run_onnx(tmp_path / "igev.onnx", {"left": nchw(left), "right": nchw(right)})[0, 0]
    want = model.predict(left, right, iters=2, min_size=None)
    assert np.abs(got - want).max() <= 1e-3, np.abs(got - want).max()
