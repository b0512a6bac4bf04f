"""dgstereo: RAFT-Stereo stereo matching with a monocular depth prior, in Rust.

>>> import dgstereo
>>> model = dgstereo.Model()                    # the bundled default weights
>>> disp = model.predict(left, right, iters=32)  # HxW float32, positive disparity (px)
>>> dgstereo.metrics(disp, gt)["epe"]

Images are ``HxWx3``, ``HxWx4`` (alpha dropped) or ``HxW`` (grey) arrays of any strides, RGB
unless ``channels="bgr"`` (OpenCV's order) says otherwise: ``uint8`` or float in 0..255 (a float
image in 0..1 is refused unless ``scale=`` says how to read it), ``uint16`` in 0..65535 (read as
``dgstereo infer`` reads a 16-bit PNG: ``v * 255 / 65535``). Errors are :class:`dgstereo.Error`;
bad arguments also are ``ValueError`` (:class:`InputError`), files also ``OSError``
(:class:`FileError`).
"""

from __future__ import annotations

import json
import os
import re
import warnings
from typing import Any, Optional, Tuple, Union

import numpy as np

from . import _dgstereo
from .errors import Error, FileError, InputError

__all__ = [
    "Model",
    "metrics",
    "depth",
    "read_pfm",
    "write_pfm",
    "read_image",
    "Error",
    "InputError",
    "FileError",
]

#: Bytes the materialised cost volume may take with ``corr="auto"`` (4 GiB).
DEFAULT_MEMORY_BUDGET: int = _dgstereo.DEFAULT_MEMORY_BUDGET

#: The folder of the data this package carries: ``weights/`` holds the default weights and
#: their model card (in the checkout, a link per file to ``assets/weights``: maturin copies
#: linked files into the wheel, not linked folders).
BUNDLED_ASSETS: str = os.path.join(os.path.dirname(os.path.abspath(__file__)), "assets")

#: Update iterations when neither ``iters`` nor a checkpoint's preset gives them.
DEFAULT_ITERS = 32

#: The threshold (px) of ``lr_check=True``.
DEFAULT_LR_CHECK = 2.0

_NATIVE = (np.dtype(np.uint8), np.dtype(np.float32), np.dtype(np.float64))
#: What images are read in besides: 16-bit samples, scaled as the command line scales them.
_NATIVE_IMAGE = _NATIVE + (np.dtype(np.uint16),)
_CHANNELS = ("rgb", "bgr")
_UNITS = {"": 1, "b": 1, "k": 10**3, "kb": 10**3, "kib": 2**10, "m": 10**6, "mb": 10**6,
          "mib": 2**20, "g": 10**9, "gb": 10**9, "gib": 2**30, "t": 10**12, "tb": 10**12, "tib": 2**40}


def _array(x: Any, what: str, native: Tuple[np.dtype, ...] = _NATIVE) -> np.ndarray:
    """``x`` as an array the native module reads: a dtype of ``native`` in native byte order
    (swapped where it is not; other numeric dtypes become float32); views and strides are kept."""
    a = np.asarray(x)
    if a.dtype.newbyteorder("=") in native:
        return a if a.dtype.isnative else a.astype(a.dtype.newbyteorder("="))
    if a.dtype.kind in "uif":
        return a.astype(np.float32)
    raise InputError(f"`{what}`: expected a numeric array, got dtype {a.dtype}")


def _channels(channels: str) -> str:
    if not isinstance(channels, str) or channels.lower() not in _CHANNELS:
        raise InputError(f'`channels` {channels!r}: expected "rgb" or "bgr" (OpenCV\'s order)')
    return channels.lower()


def _image(x: Any, what: str, scale: Optional[float]) -> np.ndarray:
    """An image for the native module: ``scale`` multiplies the values when given; without it, a
    float image whose values all lie in 0..1 is refused (it would be read as almost black in
    0..255), naming the fixes. ``uint16`` stays as it is (the native module scales it as the
    command line scales a 16-bit file)."""
    a = _array(x, what, _NATIVE_IMAGE)
    if scale is not None:
        return a.astype(np.float32) * np.float32(scale)
    finite = a[np.isfinite(a)] if a.dtype.kind == "f" else a
    if a.dtype.kind == "f" and finite.size:
        top = float(finite.max())
        if 0.0 < top <= 1.0:
            raise InputError(
                f"`{what}` holds values in 0..1 (largest {top:g}) where 0..255 is expected: multiply by 255, "
                "pass uint8, or give `scale=255.0` (or `scale=1.0` if 0..1 is meant)"
            )
    return a


def _bytes(budget: Union[int, str]) -> int:
    if isinstance(budget, (int, np.integer)) and not isinstance(budget, bool):
        if budget < 0:
            raise InputError(f"`memory_budget` {budget}: must not be negative")
        return int(budget)
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?)\s*([A-Za-z]*)\s*", str(budget))
    if not m or m.group(2).lower() not in _UNITS:
        raise InputError(f"`memory_budget` {budget!r}: not a size like 4GiB or a number of bytes")
    return int(float(m.group(1)) * _UNITS[m.group(2).lower()])


class Model:
    """A stereo model loaded once, predicting the disparity of rectified pairs.

    Args:
        weights: a dgstereo ``.safetensors`` file, an official RAFT-Stereo or DEFOM-Stereo
            ``.pth`` checkpoint (its architecture read from its tensors), or an official
            checkpoint's name (``"raftstereo-middlebury"``, ``"defomstereo-vits-sceneflow"``;
            ``dgstereo weights list``), fetched into the
            cache on first use unless ``DGSTEREO_OFFLINE=1``; ``None`` for the default weights
            this package carries (``dgstereo/assets/weights``).
        experiment: an experiment ``.toml`` whose model (and prior) configuration the weights
            were trained with; ``run`` picks one run of a sweep.
        prior: the depth prior, replacing the experiment's: ``"none"``, ``"file:DIR"`` or
            ``"depth-anything-v2:WEIGHTS"`` (a file or a name such as
            ``depth-anything-v2-small``). A model with a prior and none configured takes
            the prior maps with each :meth:`predict` call (``prior=(left, right)``).
        device: ``"cpu"`` or ``"gpu"`` (a build with the GPU backend).
        precision: ``"f32"``; on the CPU ``"bf16"``: f32 activations with the
            convolutions' products in bf16 (f32 sums) on the processor's AMX tiles or
            AVX512-BF16 (f32 where it has neither); on the GPU ``"f16"`` or ``"bf16"`` for
            the whole pass.
        slow_fast_gru: replaces the configuration's slow-fast GRU schedule.

    A model may be shared by threads: :meth:`predict` releases the GIL for the whole
    prediction, so calls run at once (sharing the CPU's thread pool) without a lock.
    """

    def __init__(
        self,
        weights: Optional[Union[str, os.PathLike]] = None,
        *,
        experiment: Optional[Union[str, os.PathLike]] = None,
        run: Optional[str] = None,
        prior: Optional[str] = None,
        device: str = "cpu",
        precision: str = "f32",
        slow_fast_gru: Optional[bool] = None,
    ) -> None:
        path = lambda p: None if p is None else os.fspath(p)  # noqa: E731
        self._engine = _dgstereo.Engine(
            path(weights), path(experiment), run, prior, device, precision, slow_fast_gru,
            BUNDLED_ASSETS,
        )
        self._config = json.loads(self._engine.config_json)

    @property
    def config(self) -> dict:
        """The model configuration (the serde form of the library's ``ModelConfig``)."""
        return json.loads(json.dumps(self._config))

    @property
    def weights(self) -> str:
        """The weights file."""
        return os.fspath(self._engine.weights)

    @property
    def summary(self) -> str:
        """The configuration on one line, with where it came from."""
        return self._engine.summary

    @property
    def notes(self) -> list:
        """What loading chose on the caller's behalf (a fallback, an ignored prior)."""
        return self._engine.notes

    @property
    def default_iters(self) -> int:
        """Iterations :meth:`predict` runs by default: an official checkpoint's preset, else 32."""
        return self._engine.preset_iters or DEFAULT_ITERS

    @property
    def uses_prior(self) -> bool:
        """Whether the model uses a depth prior."""
        return self._engine.uses_prior

    def __repr__(self) -> str:
        return f"dgstereo.Model({self.weights!r}, {self.summary})"

    def export_onnx(
        self, path: Union[str, "os.PathLike[str]"], size: Tuple[int, int], iters: Optional[int] = None
    ) -> dict:
        """Writes the model as an ONNX file (opset 19) for pairs of ``size = (height, width)``,
        ``iters`` update iterations unrolled (default :attr:`default_iters`), as ``dgstereo
        export onnx`` does. Inputs ``left``, ``right`` (``1x3xHxW`` float32, RGB 0..255) and, for
        a model with a depth prior, ``left_prior``, ``right_prior`` (``1x1xHxW``); output
        ``disparity`` (``1x1xHxW``, positive, what :meth:`predict` gives with ``min_size=None``).

        Returns:
            ``{"opset", "nodes", "inputs", "outputs"}``, each boundary a ``(name, shape)`` pair.
        """
        height, width = size
        if iters is None:
            iters = self.default_iters
        opset, nodes, inputs, outputs = self._engine.export_onnx(os.fspath(path), height, width, iters)
        return {"opset": opset, "nodes": nodes, "inputs": inputs, "outputs": outputs}

    def predict(
        self,
        left: Any,
        right: Any,
        *,
        iters: Optional[int] = None,
        prior: Optional[Tuple[Any, Any]] = None,
        max_size: Optional[int] = None,
        min_size: Union[str, int, None] = "auto",
        memory_budget: Union[int, str] = DEFAULT_MEMORY_BUDGET,
        corr: str = "auto",
        lr_check: Union[bool, float] = False,
        name: str = "pair",
        return_info: bool = False,
        scale: Optional[float] = None,
        channels: str = "rgb",
    ):
        """The disparity of a rectified pair: ``HxW`` float32, in pixels, positive
        (``x_right = x_left - d``), at the left image's size. The same as ``dgstereo infer``
        with the same options.

        Args:
            left, right: ``HxWx3``, ``HxWx4`` (alpha dropped) or ``HxW`` arrays of one size:
                ``uint8`` or float in 0..255 (a float image in 0..1 is refused unless ``scale``
                says how to read it), or ``uint16`` in 0..65535 (``cv2.IMREAD_UNCHANGED`` of a
                16-bit file), read as ``dgstereo infer`` reads a 16-bit PNG (``v * 255 / 65535``).
                Other integer dtypes are taken as 0..255.
            iters: update iterations (default :attr:`default_iters`).
            prior: ``(left, right)`` ``HxW`` relative inverse depth maps (larger = nearer) of a
                model with a depth prior, computed elsewhere (any size; resized bilinearly).
            max_size: downscale pairs whose longer side exceeds this.
            min_size: ``"auto"`` (900 for 1/8-resolution models), ``None``/``"off"``, or pixels.
            memory_budget: bytes (or ``"4GiB"``) for the materialised cost volume.
            corr: ``"auto"``, ``"reg"`` (materialised) or ``"alt"`` (on the fly).
            lr_check: left-right check (``True``: 2 px, or a threshold in pixels).
            name: the pair's name, by which a ``file:`` prior finds its maps.
            return_info: also return a dict: ``network_size`` (``(height, width)`` the network
                saw, as NumPy orders shapes), ``corr``, ``rejected`` (mask of the pixels the
                check replaced), ``prior_seconds``, ``precision`` (``"f32"``, or on the CPU
                ``"bf16 products (avx512-bf16)"`` / ``"bf16 products (amx-bf16)"``).
            scale: multiply the images' values by this first, whatever their dtype (``255.0``
                for images in 0..1; ``1.0`` to pass them as they are).
            channels: the order of the images' colour channels: ``"rgb"`` (the default, what
                :func:`read_image`, PIL and imageio give) or ``"bgr"`` (OpenCV's
                ``cv2.imread``).

        Pairs with a side under 32 pixels (as given, or after ``max_size``) are refused.
        """
        if iters is None:
            iters = self.default_iters
        if isinstance(iters, bool) or not isinstance(iters, (int, np.integer)) or iters < 1:
            raise InputError(f"`iters` {iters!r}: must be an integer of at least 1")
        if min_size is None:
            min_size = "off"
        if lr_check is True:
            threshold: Optional[float] = DEFAULT_LR_CHECK
        elif lr_check is False or lr_check is None:
            threshold = None
        else:
            threshold = float(lr_check)
        if max_size is not None and (isinstance(max_size, bool) or int(max_size) < 0):
            raise InputError(f"`max_size` {max_size!r}: must be a number of pixels")
        channels = _channels(channels)
        if prior is not None:
            if not (isinstance(prior, (tuple, list)) and len(prior) == 2):
                raise InputError("`prior`: expected a pair (left, right) of HxW arrays")
            prior = (_array(prior[0], "prior[0]"), _array(prior[1], "prior[1]"))
        disp, info = self._engine.predict(
            _image(left, "left", scale),
            _image(right, "right", scale),
            int(iters),
            None if max_size is None else int(max_size),
            str(min_size),
            _bytes(memory_budget),
            corr,
            threshold,
            prior,
            name,
            channels,
        )
        return (disp, info) if return_info else disp


def metrics(pred: Any, gt: Any, mask: Any = None, *, max_disp: Optional[float] = None) -> dict:
    """The disparity metrics of the eval crate over the valid pixels (ground truth finite and
    > 0, ``mask`` set, below ``max_disp``): ``epe`` (px), ``bad-0.5`` ... ``bad-4`` and
    ``d1-all`` (percentages), ``valid_pixels``. A non-finite prediction counts as 0; with no
    valid pixel the metrics are NaN."""
    m = None if mask is None else np.asarray(mask).astype(bool, copy=False)
    return _dgstereo.metrics(_array(pred, "pred"), _array(gt, "gt"), m, max_disp)


def depth(
    disparity: Any,
    fx: Optional[float] = None,
    baseline: Optional[float] = None,
    *,
    doffs: float = 0.0,
    calib: Optional[Union[str, os.PathLike]] = None,
    crop: Optional[Tuple[float, float]] = None,
    scale: Union[float, Tuple[float, float], None] = None,
) -> np.ndarray:
    """Depth in metres, ``fx * baseline / (d + doffs)`` (``fx`` in pixels, ``baseline`` in
    metres), or from a calibration file ``calib`` (Middlebury ``calib.txt``, JSON or ``K.txt``).

    ``inf`` where there is no point in front of the cameras: the disparity is unknown (NaN,
    ``inf``) or ``d + doffs <= 0`` (a negative disparity); ``inf`` is also the invalid value of a
    PFM map.

    A calibration applies to the image size it was made for. A map of another size at the same
    aspect ratio (a resized pair) gets the calibration scaled to it, with a ``UserWarning``
    saying so; any other size is an :class:`InputError` naming both sizes, unless ``crop`` and
    ``scale`` say how the pair was made from the calibrated images:

    Args:
        crop: ``(x, y)``, the top-left corner of the crop in pixels of the calibrated image: the
            principal point moves by ``(-x, -y)``.
        scale: the (cropped) images were then resized by this factor, or by ``(sx, sy)``:
            ``fx``, ``cx`` and ``doffs`` scale by ``sx``, ``fy`` and ``cy`` by ``sy``.
    """
    if crop is not None:
        if not (isinstance(crop, (tuple, list)) and len(crop) == 2):
            raise InputError(f"`crop` {crop!r}: expected the corner (x, y) in pixels of the calibrated image")
        crop = (float(crop[0]), float(crop[1]))
    if scale is not None:
        if isinstance(scale, (tuple, list)):
            if len(scale) != 2:
                raise InputError(f"`scale` {scale!r}: expected a factor or (sx, sy)")
            scale = (float(scale[0]), float(scale[1]))
        else:
            scale = (float(scale), float(scale))
    result, notice = _dgstereo.depth(
        _array(disparity, "disparity"), fx, baseline, float(doffs), None if calib is None else os.fspath(calib),
        crop, scale,
    )
    if notice is not None:
        warnings.warn(notice, UserWarning, stacklevel=2)
    return result


def read_pfm(path: Union[str, os.PathLike]) -> np.ndarray:
    """A PFM file as ``HxW`` (``Pf``) or ``HxWx3`` (``PF``) float32, top row first."""
    return _dgstereo.read_pfm(os.fspath(path))


def write_pfm(path: Union[str, os.PathLike], array: Any) -> None:
    """Writes an ``HxW`` or ``HxWx3`` array as a little-endian PFM (as ``dgstereo infer``)."""
    a = np.asarray(array)
    if a.dtype.kind not in "uif":
        raise InputError(f"`array`: expected a numeric array, got dtype {a.dtype}")
    _dgstereo.write_pfm(os.fspath(path), a.astype(np.float32, copy=False))


def read_image(path: Union[str, os.PathLike]) -> np.ndarray:
    """A PNG, JPEG, BMP or TIFF picture as ``HxWx3`` float32 in 0..255 (as ``dgstereo infer``
    reads it)."""
    return _dgstereo.read_image(os.fspath(path))
