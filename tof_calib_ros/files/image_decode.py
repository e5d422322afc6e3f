"""sensor_msgs/Image to numpy without cv_bridge, which is not on every install (nor in a venv).

Only the message's fields are read (``encoding``, ``height``, ``width``, ``step``,
``is_bigendian``, ``data``), so rclpy messages and rosbags-deserialised ones decode alike:
rclpy gives ``data`` as ``array.array('B')``, rosbags as a numpy uint8 array.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..core.errors import CalibrationError
from ..core.inputs import depth_in_metres

# encoding -> pixel type (one channel each); only what depth and amplitude streams use
ENCODINGS: dict[str, np.dtype] = {
    "mono8": np.dtype(np.uint8), "8UC1": np.dtype(np.uint8),
    "mono16": np.dtype(np.uint16), "16UC1": np.dtype(np.uint16),
    "32FC1": np.dtype(np.float32),
}
# REP 118: 16UC1 depth is in millimetres (by default), 32FC1 in metres
DEPTH_ENCODINGS = ("16UC1", "32FC1")
# Images beyond this many pixels are refused before they are decoded: ToF sensors have at most
# about 1 Mpx, and judging a 64 Mpx frame took the node 6 GB.
MAX_PIXELS = 4096 * 4096


def check_pixels(width: int, height: int, where: str = "image") -> None:
    """ImageTooLarge when an image of this size is beyond ``MAX_PIXELS``."""
    if width * height > MAX_PIXELS:
        raise ImageTooLarge(f"{where} is {width}x{height} = {width * height / 1e6:.0f} Mpx, more than the "
                         f"{MAX_PIXELS / 1e6:.1f} Mpx accepted (ToF sensors have about 1 Mpx at most)")


class ImageError(CalibrationError):
    """An image message that cannot be decoded; a CalibrationError so one handler catches both."""


class ImageTooLarge(ImageError):
    """An image beyond ``MAX_PIXELS``, refused before it is decoded."""


def _integer(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ImageError(f"image {name} must be an integer, got {value!r}")
    if value < 0:
        raise ImageError(f"image {name} must not be negative, got {value}")
    return int(value)


def _byte_array(data: Any) -> np.ndarray:
    """The message bytes as a flat uint8 array (a view where possible; the caller copies)."""
    if isinstance(data, np.ndarray):
        if data.dtype not in (np.uint8, np.int8):
            raise ImageError(f"image data must be bytes, got a numpy array of {data.dtype}")
        return np.ascontiguousarray(data).reshape(-1).view(np.uint8)
    if isinstance(data, (list, tuple)):
        if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and 0 <= v <= 255
                   for v in data):
            raise ImageError("image data given as a list must hold integers 0..255")
        return np.array(data, dtype=np.uint8)
    try:
        view = memoryview(data)
    except TypeError:
        raise ImageError(f"image data must be bytes-like, got {type(data).__name__}") from None
    if view.itemsize != 1:
        raise ImageError(f"image data must be bytes, got items of {view.itemsize} bytes "
                         f"(format {view.format!r})")
    return np.frombuffer(view.cast("B") if view.c_contiguous else view.tobytes(), dtype=np.uint8)


def _field(msg: Any, name: str) -> Any:
    try:
        return getattr(msg, name)
    except AttributeError:
        raise ImageError(f"not an image message: it has no {name!r} field") from None


def decode_image(msg: Any) -> np.ndarray:
    """The image as a 2-D native-endian array, copied so it outlives the message buffer."""
    encoding = _field(msg, "encoding")
    if not isinstance(encoding, str) or encoding not in ENCODINGS:
        raise ImageError(f"unsupported image encoding {encoding!r}; supported: {', '.join(ENCODINGS)}")
    pixel = ENCODINGS[encoding]
    height, width, step = (_integer(_field(msg, name), name) for name in ("height", "width", "step"))
    if height == 0 or width == 0:
        raise ImageError(f"image is empty ({width}x{height})")
    check_pixels(width, height)
    row_bytes = width * pixel.itemsize
    if step < row_bytes:
        raise ImageError(f"image step {step} is less than width x bytes per pixel = {row_bytes} ({encoding})")
    bigendian = _field(msg, "is_bigendian")
    if not isinstance(bigendian, (bool, int, np.integer)) or bigendian not in (0, 1):
        raise ImageError(f"image is_bigendian must be 0 or 1, got {bigendian!r}")
    data = _byte_array(_field(msg, "data"))
    if data.size != step * height:
        raise ImageError(f"image data has {data.size} bytes but step x height = {step} x {height} "
                         f"= {step * height}")
    rows = np.ascontiguousarray(data.reshape(height, step)[:, :row_bytes])
    stored = pixel.newbyteorder(">" if bigendian else "<")
    return rows.view(stored).astype(pixel)   # astype always copies, and makes it native-endian


def depth_to_metres(image: np.ndarray, encoding: str, scale_16u: float = 0.001) -> np.ndarray:
    """Float64 metres with NaN where invalid (0, negative, NaN, inf), as the calibration expects.

    ``scale_16u`` is metres per count of 16UC1 depth: 0.001 for the usual millimetres.
    """
    if not isinstance(encoding, str) or encoding not in DEPTH_ENCODINGS:
        raise ImageError(f"{encoding!r} is not a depth encoding; depth must be one of {', '.join(DEPTH_ENCODINGS)}")
    image = np.asarray(image)
    if image.ndim != 2:
        raise ImageError(f"depth must be a 2-D image, got shape {image.shape}")
    if image.dtype != ENCODINGS[encoding]:
        raise ImageError(f"{encoding} depth must be a {ENCODINGS[encoding]} array, got {image.dtype}")
    if encoding == "16UC1" and (isinstance(scale_16u, bool) or not isinstance(scale_16u, (int, float, np.number))
                                or not (np.isfinite(scale_16u) and scale_16u > 0)):
        raise ImageError(f"scale_16u must be a positive number of metres per count, got {scale_16u!r}")
    return depth_in_metres(image, scale_16u if encoding == "16UC1" else 1.0)
