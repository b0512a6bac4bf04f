"""Model.predict against the command line, over every input kind, from several threads."""

import struct
import subprocess
import threading
import zlib

import numpy as np
import pytest

import dgstereo
from conftest import CONES, cli_binary

QUICK = dict(iters=4, min_size=None)


def test_equals_the_command_lines_disparity_on_cones(cones, model, tmp_path):
    exe = cli_binary()
    if exe is None:
        pytest.skip("no dgstereo binary (build it with cargo, or set DGSTEREO_CLI)")
    subprocess.run(
        [exe, "infer", "-l", str(CONES / "left_rgb.png"), "-r", str(CONES / "right_rgb.png"),
         "--iters", "4", "--min-size", "off", "--save", "pfm", "-o", str(tmp_path)],
        check=True, capture_output=True,
    )
    (pfm,) = tmp_path.glob("*_disparity.pfm")
    expected = dgstereo.read_pfm(pfm)
    disp = model.predict(*cones, **QUICK)
    assert disp.shape == (375, 450) and disp.dtype == np.float32
    np.testing.assert_array_equal(disp, expected)
    assert np.nanmedian(disp) > 0


def test_every_input_kind_gives_the_same_disparity(small, model):
    left, right = small
    ref = model.predict(left, right, **QUICK)
    variants = {
        "float32": (left.astype(np.float32), right.astype(np.float32)),
        "float64": (left.astype(np.float64), right.astype(np.float64)),
        "int64": (left.astype(np.int64), right.astype(np.int64)),
        "fortran": (np.asfortranarray(left), np.asfortranarray(right)),
        "view": (np.pad(left, ((2, 2), (5, 5), (0, 0)))[2:-2, 5:-5], np.pad(right, ((2, 2), (5, 5), (0, 0)))[2:-2, 5:-5]),
        "strided": (np.repeat(left, 2, axis=1)[:, ::2], np.repeat(right, 2, axis=1)[:, ::2]),
        "big-endian": (left.astype(">f4"), right.astype(">f4")),
        "list": (left.tolist(), right.tolist()),
    }
    for kind, (l, r) in variants.items():
        np.testing.assert_array_equal(model.predict(l, r, **QUICK), ref, err_msg=kind)
    # RGBA drops its alpha; images in 0..1 are read with `scale`.
    alpha = np.full(left.shape[:2] + (1,), 7, dtype=left.dtype)
    rgba = (np.concatenate([left, alpha], -1), np.concatenate([right, alpha], -1))
    np.testing.assert_array_equal(model.predict(*rgba, **QUICK), ref, err_msg="rgba")
    unit = (left.astype(np.float32) / 255.0, right.astype(np.float32) / 255.0)
    scaled = model.predict(*unit, scale=255.0, **QUICK)
    np.testing.assert_allclose(scaled, ref, atol=1e-3, err_msg="scale=255")
    # Grey images repeat into the three channels.
    grey_l, grey_r = left[..., 1], right[..., 1]
    np.testing.assert_array_equal(
        model.predict(grey_l, grey_r, **QUICK),
        model.predict(np.repeat(grey_l[..., None], 3, -1), np.repeat(grey_r[..., None], 3, -1), **QUICK),
    )


def test_options_and_info(small, model):
    left, right = small
    disp, info = model.predict(left, right, iters=1, max_size=48, lr_check=True, return_info=True)
    assert disp.shape == (48, 64)
    # (height, width), as every array's shape.
    assert info["network_size"] == (36, 48)
    assert info["rejected"].shape == (48, 64) and info["rejected"].dtype == bool
    _, info = model.predict(left, right, iters=1, min_size=None, memory_budget=1, return_info=True)
    assert info["corr"] == "alt"
    _, info = model.predict(left, right, iters=1, min_size=None, memory_budget="4GiB", return_info=True)
    assert info["corr"] == "reg" and info["rejected"] is None
    assert info["precision"] == "f32"


def test_bf16_products_on_the_cpu(small, model):
    left, right = small
    disp, info = dgstereo.Model(precision="bf16").predict(left, right, return_info=True, **QUICK)
    # The processor's bf16 unit, or f32 where it has none.
    assert info["precision"].startswith(("bf16 products (", "f32 (bf16 asked")), info["precision"]
    ref = model.predict(left, right, **QUICK)
    assert np.abs(disp - ref).mean() < 0.05 and np.abs(disp - ref).max() < 1.0


def test_a_model_serves_several_threads(small, model):
    left, right = small
    ref = model.predict(left, right, **QUICK)
    results, errors = [None] * 4, []

    def work(i):
        try:
            results[i] = model.predict(left, right, **QUICK)
        except Exception as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    for r in results:
        np.testing.assert_array_equal(r, ref)


def test_config_and_properties(model):
    config = model.config
    assert isinstance(config, dict) and "encoder" in config and "updater" in config
    assert model.weights.endswith("raft-stereo-default.safetensors")
    assert model.default_iters == 32 and not model.uses_prior
    assert "n_downsample" in model.summary


def test_given_prior_maps(root, small):
    paper = dgstereo.Model(root / "assets" / "weights" / "paper-default.safetensors")
    assert paper.uses_prior
    left, right = small
    y, x = np.mgrid[0:48, 0:64]
    prior = (1.0 + x / 64.0, 1.0 + (x + 3) / 64.0)
    disp = paper.predict(left, right, prior=prior, iters=1, min_size=None)
    assert disp.shape == (48, 64) and np.isfinite(disp).all()
    # Maps of another size are resized; the left-right check mirrors them.
    half = tuple(p[::2, ::2] for p in prior)
    assert paper.predict(left, right, prior=half, iters=1, min_size=None, lr_check=True).shape == (48, 64)
    with pytest.raises(dgstereo.InputError, match="prior"):
        paper.predict(left, right, iters=1)
    with pytest.raises(dgstereo.InputError, match="non-finite"):
        paper.predict(left, right, prior=(np.full((48, 64), np.nan), prior[1]), iters=1)


def write_png16(path, rgb):
    """A 16-bit RGB PNG (big-endian samples, as the format stores them)."""
    h, w, _ = rgb.shape
    rows = rgb.astype(">u2")
    raw = b"".join(b"\x00" + rows[y].tobytes() for y in range(h))

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def test_uint16_images_are_read_as_the_command_line_reads_16_bit_files(cones, model, tmp_path):
    # Cones at 16 bits with every bit used (not only multiples of 257), as a 16-bit camera gives.
    rng = np.random.default_rng(16)
    pair = []
    for view, name in zip(cones, ("left", "right")):
        wide = np.minimum(view.astype(np.uint32) * 257 + rng.integers(0, 257, view.shape), 65535).astype(np.uint16)
        write_png16(tmp_path / f"{name}.png", wide)
        pair.append(wide)
    disp = model.predict(*pair, **QUICK)
    # The file read as `dgstereo infer` reads it (the same reader) gives the same disparity.
    from_files = [dgstereo.read_image(tmp_path / f"{n}.png") for n in ("left", "right")]
    assert from_files[0].max() > 200, "the 16-bit file is read in 0..255"
    np.testing.assert_array_equal(disp, model.predict(*from_files, **QUICK))
    # A big-endian array holds the same pixels.
    np.testing.assert_array_equal(disp, model.predict(*(p.astype(">u2") for p in pair), **QUICK))
    exe = cli_binary()
    if exe is None:
        pytest.skip("no dgstereo binary for the command line's side (build it with cargo, or set DGSTEREO_CLI)")
    subprocess.run(
        [exe, "infer", "-l", str(tmp_path / "left.png"), "-r", str(tmp_path / "right.png"),
         "--iters", "4", "--min-size", "off", "--save", "pfm", "-o", str(tmp_path / "out")],
        check=True, capture_output=True,
    )
    (pfm,) = (tmp_path / "out").glob("*_disparity.pfm")
    np.testing.assert_array_equal(disp, dgstereo.read_pfm(pfm))


def test_channel_order_is_an_argument(small, model):
    left, right = small
    ref = model.predict(left, right, **QUICK)
    bgr = (left[..., ::-1], right[..., ::-1])
    np.testing.assert_array_equal(model.predict(*bgr, channels="bgr", **QUICK), ref)
    np.testing.assert_array_equal(model.predict(*bgr, channels="BGR", **QUICK), ref)
    # BGRA (OpenCV's IMREAD_UNCHANGED of a PNG with alpha) drops its alpha too.
    alpha = np.full(left.shape[:2] + (1,), 9, dtype=left.dtype)
    bgra = (np.concatenate([bgr[0], alpha], -1), np.concatenate([bgr[1], alpha], -1))
    np.testing.assert_array_equal(model.predict(*bgra, channels="bgr", **QUICK), ref)
    # Read as RGB, the same arrays are other images: the order matters to the model.
    assert not np.array_equal(model.predict(*bgr, **QUICK), ref)
    # Grey images have no order.
    grey = (left[..., 1], right[..., 1])
    np.testing.assert_array_equal(model.predict(*grey, channels="bgr", **QUICK), model.predict(*grey, **QUICK))
    with pytest.raises(dgstereo.InputError, match="channels"):
        model.predict(left, right, channels="yuv", **QUICK)


def test_pairs_under_the_networks_minimum_are_refused(model):
    tiny = np.zeros((1, 1, 3), np.uint8)
    with pytest.raises(dgstereo.InputError, match="1x1"):
        model.predict(tiny, tiny, iters=1)
    strip = np.zeros((20, 200, 3), np.uint8)
    with pytest.raises(dgstereo.InputError, match="200x20"):
        model.predict(strip, strip, iters=1)
    wide = np.zeros((40, 1000, 3), np.uint8)
    with pytest.raises(dgstereo.InputError, match="max_size"):
        model.predict(wide, wide, iters=1, max_size=100)
