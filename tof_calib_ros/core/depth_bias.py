"""The ToF depth error model estimated alongside the intrinsics (beyond the paper).

    measured = (1 + scale) * depth + offset + tilt_x * X + tilt_y * Y

``offset`` is the systematic range offset of real ToF cameras (about 25 mm on a Kinect v2);
``scale`` a modulation-frequency error; ``tilt`` a depth axis not quite along the optical
axis, which is what a driver's z-depth computed with its own factory principal point looks
like to first order. Left out of the model, each of them biases the intrinsics.
"""
from __future__ import annotations

import numpy as np

from .errors import CalibrationError

NAMES = ("depth_offset", "depth_scale", "depth_tilt_x", "depth_tilt_y")
N_BIAS = len(NAMES)
TERMS = {"offset": [0], "scale": [1], "tilt": [2, 3]}
# Weak priors (offset in metres, the rest unitless) keep terms the views cannot separate finite.
PRIOR_SIGMA = np.array([0.1, 0.05, 0.05, 0.05])


def parse(spec: str) -> list[int]:
    """Indices of the estimated terms from 'none' or terms joined by '+', e.g. 'offset+tilt'."""
    if spec == "none":
        return []
    names = spec.split("+") if isinstance(spec, str) else []
    if not names or any(n not in TERMS for n in names) or len(set(names)) != len(names):
        raise CalibrationError(f"depth_bias must be 'none' or terms from {sorted(TERMS)} joined by '+', "
                               f"got {spec!r}")
    return sorted(i for n in names for i in TERMS[n])


def measured(bias: np.ndarray, depth: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The depth the camera reports for camera-frame points whose true depth is ``depth``."""
    offset, scale, tx, ty = bias
    return (1 + scale) * depth + offset + tx * points[:, 0] + ty * points[:, 1]


def true_depth(bias: np.ndarray, reported: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Inverse of ``measured`` along rays scaled so that the point is depth x direction."""
    offset, scale, tx, ty = bias
    return (reported - offset) / (1 + scale + tx * directions[:, 0] + ty * directions[:, 1])
