"""Each error is a dgstereo.Error of the right kind, carrying the library's message."""

import numpy as np
import pytest

import dgstereo


def test_error_classes():
    assert issubclass(dgstereo.InputError, dgstereo.Error) and issubclass(dgstereo.InputError, ValueError)
    assert issubclass(dgstereo.FileError, dgstereo.Error) and issubclass(dgstereo.FileError, OSError)


@pytest.mark.parametrize(
    "left, right, message",
    [
        (np.zeros((48, 64, 3)), np.zeros((48, 60, 3)), "one size"),
        (np.zeros((48, 64, 5)), np.zeros((48, 64, 5)), "3 colour channels"),
        (np.full((48, 64, 3), 0.5), np.full((48, 64, 3), 0.5), r"0\.\.1 .*multiply by 255"),
        (np.zeros((2, 48, 64, 3)), np.zeros((2, 48, 64, 3)), "HxWx3 or HxW"),
        (np.zeros((0, 64, 3)), np.zeros((0, 64, 3)), "empty"),
        (np.full((48, 64, 3), np.nan), np.zeros((48, 64, 3)), "non-finite"),
        (np.zeros((48, 64, 3), dtype=bool), np.zeros((48, 64, 3), dtype=bool), "numeric"),
        (np.zeros((48, 64, 3), dtype=object), np.zeros((48, 64, 3)), "numeric"),
    ],
)
def test_bad_arrays(model, left, right, message):
    with pytest.raises(dgstereo.InputError, match=message):
        model.predict(left, right, iters=1)


@pytest.mark.parametrize(
    "options, message",
    [
        (dict(iters=0), "iters"),
        (dict(max_size=16), "max_size"),
        (dict(min_size=8), "min_size"),
        (dict(min_size="sometimes"), "min_size"),
        (dict(min_size=300, max_size=200), "larger than"),
        (dict(lr_check=-1.0), "lr_check"),
        (dict(corr="magic"), "corr"),
        (dict(memory_budget="lots"), "memory_budget"),
        (dict(prior=(np.zeros((4, 4)), np.zeros((4, 4)))), "no depth prior"),
    ],
)
def test_bad_options(model, small, options, message):
    with pytest.raises(dgstereo.InputError, match=message):
        model.predict(*small, **{"iters": 1, **options})


def test_files(tmp_path):
    with pytest.raises(dgstereo.FileError, match="missing.safetensors"):
        dgstereo.Model(tmp_path / "missing.safetensors")
    with pytest.raises(dgstereo.FileError, match="missing.pfm"):
        dgstereo.read_pfm(tmp_path / "missing.pfm")
    bad = tmp_path / "bad.pfm"
    bad.write_bytes(b"P6 nonsense")
    with pytest.raises(dgstereo.FileError, match="PFM"):
        dgstereo.read_pfm(bad)
    with pytest.raises(dgstereo.FileError):
        dgstereo.write_pfm(tmp_path / "no" / "such" / "dir.pfm", np.zeros((2, 2), np.float32))
    with pytest.raises(dgstereo.FileError, match="missing.png"):
        dgstereo.read_image(tmp_path / "missing.png")
    with pytest.raises(dgstereo.Error, match="missing.toml"):
        dgstereo.Model(experiment=tmp_path / "missing.toml")


def test_bad_model_arguments():
    with pytest.raises(dgstereo.InputError, match="device"):
        dgstereo.Model(device="abacus")
    with pytest.raises(dgstereo.InputError, match="prior"):
        dgstereo.Model(prior="magic")
    with pytest.raises(dgstereo.InputError, match="experiment"):
        dgstereo.Model(run="a")
