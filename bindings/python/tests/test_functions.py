"""metrics against NumPy, depth, PFM round trips."""

import warnings

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
    # A negative disparity (beyond -doffs) is no point in front of the cameras: inf, as unknown.
    behind = np.array([[-5.0, -10.0, -12.0]], np.float32)
    z = dgstereo.depth(behind, 500.0, 0.1, doffs=10.0)
    assert np.isfinite(z[0, 0]) and np.isinf(z[0, 1:]).all() and (z[0, 1:] > 0).all()


def oakd_calibration(tmp_path):
    """A 640x480 calibration: fx 400, principal point (320, 240), 7.5 cm baseline."""
    path = tmp_path / "calib.json"
    path.write_text('{"fx": 400, "cx": 320, "cy": 240, "baseline_m": 0.075, "width": 640, "height": 480}')
    return path


def test_depth_from_a_calibration_of_another_size(tmp_path):
    calib = oakd_calibration(tmp_path)
    full = dgstereo.depth(np.full((480, 640), 20.0, np.float32), calib=calib)
    np.testing.assert_allclose(full, 400 * 0.075 / 20, rtol=1e-6)
    # A crop of another aspect ratio: an error naming both sizes, not depth x0.156.
    crop = np.full((40, 100), 20.0, np.float32)
    with pytest.raises(dgstereo.InputError, match=r"640x480.*100x40.*crop"):
        dgstereo.depth(crop, calib=calib)
    # Stated, the crop keeps the focal length.
    np.testing.assert_allclose(dgstereo.depth(crop, calib=calib, crop=(300, 200)), 400 * 0.075 / 20, rtol=1e-6)
    # A resize at the same aspect ratio is applied, with a warning.
    half = np.full((240, 320), 10.0, np.float32)
    with pytest.warns(UserWarning, match="640x480.*320x240"):
        z = dgstereo.depth(half, calib=calib)
    np.testing.assert_allclose(z, 200 * 0.075 / 10, rtol=1e-6)
    # Stated, the same resize says nothing; another aspect ratio needs (sx, sy).
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_allclose(dgstereo.depth(half, calib=calib, scale=0.5), z, rtol=1e-6)
        squeezed = np.full((480, 320), 10.0, np.float32)
        np.testing.assert_allclose(dgstereo.depth(squeezed, calib=calib, scale=(0.5, 1.0)), 200 * 0.075 / 10, rtol=1e-6)
    with pytest.raises(dgstereo.InputError, match="320x240.*300x240"):
        dgstereo.depth(np.ones((240, 300), np.float32), calib=calib, scale=0.5)
    with pytest.raises(dgstereo.InputError, match="calib"):
        dgstereo.depth(half, fx=400.0, baseline=0.1, crop=(1, 1))


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
