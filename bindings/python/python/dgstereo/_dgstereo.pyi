"""Type stubs of the native module (the Rust half); use the `dgstereo` package's wrappers."""

import os
from typing import Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

_Path = Union[str, os.PathLike]

DEFAULT_MEMORY_BUDGET: int

class Engine:
    def __init__(
        self,
        weights: Optional[_Path] = None,
        experiment: Optional[_Path] = None,
        run: Optional[str] = None,
        prior: Optional[str] = None,
        device: str = "cpu",
        precision: str = "f32",
        slow_fast_gru: Optional[bool] = None,
        bundled_assets: Optional[_Path] = None,
    ) -> None: ...
    @property
    def weights(self) -> str: ...
    @property
    def config_json(self) -> str: ...
    @property
    def summary(self) -> str: ...
    @property
    def preset_iters(self) -> Optional[int]: ...
    @property
    def notes(self) -> list[str]: ...
    @property
    def uses_prior(self) -> bool: ...
    @property
    def takes_given_priors(self) -> bool: ...
    def predict(
        self,
        left: npt.NDArray,
        right: npt.NDArray,
        iters: int,
        max_size: Optional[int] = None,
        min_size: str = "auto",
        memory_budget: int = ...,
        corr: str = "auto",
        lr_check: Optional[float] = None,
        prior: Optional[Tuple[npt.NDArray, npt.NDArray]] = None,
        name: str = "pair",
        channels: str = "rgb",
    ) -> Tuple[npt.NDArray[np.float32], dict]:
        """``left``, ``right``: uint8 or float in 0..255, or uint16 in 0..65535 (scaled by
        255/65535 as a 16-bit PNG is read), channels in ``channels`` order (``"rgb"`` or
        ``"bgr"``); the dict's ``network_size`` is ``(height, width)``."""
        ...
    def export_onnx(
        self, path: str, height: int, width: int, iters: int
    ) -> Tuple[int, int, list[Tuple[str, list[int]]], list[Tuple[str, list[int]]]]: ...

def metrics(
    pred: npt.NDArray, gt: npt.NDArray, mask: Optional[npt.NDArray[np.bool_]] = None, max_disp: Optional[float] = None
) -> dict[str, float]: ...
def depth(
    disparity: npt.NDArray,
    fx: Optional[float] = None,
    baseline: Optional[float] = None,
    doffs: float = 0.0,
    calib: Optional[_Path] = None,
    crop: Optional[Tuple[float, float]] = None,
    scale: Optional[Tuple[float, float]] = None,
) -> Tuple[npt.NDArray[np.float32], Optional[str]]:
    """The depth map (``inf`` where ``d + doffs <= 0`` or ``d`` is unknown) and the notice of a
    calibration rescaled to the map's size (same aspect ratio), else ``None``."""
    ...
def read_pfm(path: _Path) -> npt.NDArray[np.float32]: ...
def write_pfm(path: _Path, array: npt.NDArray[np.float32]) -> None: ...
def read_image(path: _Path) -> npt.NDArray[np.float32]: ...
