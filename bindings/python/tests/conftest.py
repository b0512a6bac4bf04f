"""Shared fixtures: the repository, the bundled Cones pair and the default model."""

import os
import pathlib

import numpy as np
import pytest

import dgstereo

ROOT = pathlib.Path(__file__).resolve().parents[3]
CONES = ROOT / "assets" / "cones"


@pytest.fixture(scope="session")
def root():
    return ROOT


@pytest.fixture(scope="session")
def cones():
    left = dgstereo.read_image(CONES / "left_rgb.png")
    right = dgstereo.read_image(CONES / "right_rgb.png")
    return left, right


@pytest.fixture(scope="session")
def model():
    return dgstereo.Model()


@pytest.fixture(scope="session")
def small():
    """A 64x48 horizontal ramp seen 3 px apart, as uint8."""
    y, x = np.mgrid[0:48, 0:64]
    left = np.stack([x * 4, y * 5, (x * y) % 255], axis=-1).astype(np.uint8)
    right = np.stack([(x + 3) * 4, y * 5, ((x + 3) * y) % 255], axis=-1).astype(np.uint8)
    return left, right


def cli_binary():
    exe = os.environ.get("DGSTEREO_CLI") or str(ROOT / "target" / "debug" / "dgstereo")
    return exe if os.path.exists(exe) else None
