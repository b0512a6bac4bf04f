"""metrics against NumPy, depth, PFM round trips."""

import numpy as np
import pytest

import dgstereo
from conftest import CONES


def numpy_metrics(pred, gt, mask=None):
    valid = np.isfinite(gt) & (gt > 0)
    if mask is not None:
        valid &= mask
    p = np.where(np.isfinite(pred), pred, 0.0)[valid].astype(np.float64)
    g = gt[valid].astype(np.float64)
    e = np.abs(p - g)
    out = {"epe": e.mean()}
    for t in (0.5, 1, 2, 3, 4):
        out[f"bad-{t}"] = 100.0 * (e > t).mean()
    out["d1-all"] = 100.0 * ((e > 3) & (e > 0.05 * g)).mean()
    return out, int(valid.sum())


def test_metrics_match_numpy():
    rng = np.random.default_rng(0)
    gt = rng.uniform(1, 60, (40, 50)).astype(np.float32)
    gt[::7, ::3] = np.nan
    gt[5, :] = 0
    pred = (gt + rng.normal(0, 3, gt.shape)).astype(np.float32)
    pred[1, ::4] = np.inf
    mask = rng.random(gt.shape) > 0.3
    for m in (None, mask):
        got = dgstereo.metrics(pred, gt, m)
        want, n = numpy_metrics(pred, gt, m)
        assert got["valid_pixels"] == n
        for key, value in want.items():
            name = key.replace("bad-1", "bad-1").replace(".0", "") if key != "bad-0.5" else key
            assert got[name] == pytest.approx(value, rel=1e-6, abs=1e-9), name


def test_metrics_on_the_cones_ground_truth():
    gt = dgstereo.read_pfm(CONES / "disp_left.pfm")
    m = dgstereo.metrics(gt, gt)
    assert m["epe"] == 0 and m["bad-2"] == 0 and m["valid_pixels"] > 0
    with pytest.raises(dgstereo.InputError, match="prediction is"):
        dgstereo.metrics(gt[:10], gt)
    assert np.isnan(dgstereo.metrics(gt, np.zeros_like(gt))["epe"])


def test_depth():
    disp = np.array([[10.0, 20.0], [np.nan, 0.0]], np.float32)
    z = dgstereo.depth(disp, fx=500.0, baseline=0.1)
    np.testing.assert_allclose(z[0], [5.0, 2.5])
    assert np.isinf(z[1]).all()
    np.testing.assert_allclose(dgstereo.depth(disp, 500.0, 0.1, doffs=10.0)[0], [2.5, 50 / 30], rtol=1e-6)
    with pytest.raises(dgstereo.InputError, match="fx"):
        dgstereo.depth(disp, fx=-1.0, baseline=0.1)
    with pytest.raises(dgstereo.InputError):
        dgstereo.depth(disp)


def test_pfm_round_trip(tmp_path):
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    a[0, 0] = np.inf
    dgstereo.write_pfm(tmp_path / "a.pfm", a)
    np.testing.assert_array_equal(dgstereo.read_pfm(tmp_path / "a.pfm"), a)
    rgb = np.random.default_rng(1).random((3, 4, 3)).astype(np.float32)
    dgstereo.write_pfm(tmp_path / "c.pfm", np.asfortranarray(rgb))
    np.testing.assert_array_equal(dgstereo.read_pfm(tmp_path / "c.pfm"), rgb)
    with pytest.raises(dgstereo.InputError):
        dgstereo.write_pfm(tmp_path / "x.pfm", np.zeros((2, 2, 2), np.float32))
