"""The ToF depth error model estimated alongside the intrinsics (beyond the paper).

    measured = (1 + scale) * depth + offset + tilt_x * X + tilt_y * Y
               + (radial + wiggle_sin * sin(2 pi r / period) + wiggle_cos * cos(2 pi r / period)) * depth / r

``offset`` is the systematic range offset of real ToF cameras (about 25 mm on a Kinect v2);
``scale`` a modulation-frequency error; ``tilt`` a depth axis not quite along the optical
axis, which is what a driver's z-depth computed with its own factory principal point looks
like to first order. The wiggling term is the periodic error of a continuous-wave ToF camera
(Lindner and Kolb): a function of the light's path, the radial distance ``r``, whose period
the modulation sets (c / (8 f) for four-phase sampling: 1.87 m at 20 MHz), so the period is
the one of the frequency given, or one the data chose; ``depth / r`` carries it into a
z-depth. ``radial`` is an offset in the light's path rather than in the depth: in z-depth it
reads less towards the image's edges, which bows every board's depth alike, and which near
frontal views otherwise take for a wiggle (in a radial convention it is the offset, so it is
not offered there). Left out of the model, each of them biases the intrinsics.
"""
from __future__ import annotations

import numpy as np

from .errors import CalibrationError

NAMES = ("depth_offset", "depth_scale", "depth_tilt_x", "depth_tilt_y", "depth_wiggle_sin", "depth_wiggle_cos",
         "depth_radial")
N_BIAS = len(NAMES)
TERMS = {"offset": [0], "scale": [1], "tilt": [2, 3], "wiggle": [4, 5], "radial": [6]}
# calibration files written before these terms lack them
TERMS_ADDED_LATER = tuple(NAMES[i] for i in TERMS["wiggle"] + TERMS["radial"])
# Weak priors (offset, wiggle and radial in metres, the rest unitless) keep terms the views cannot separate finite.
PRIOR_SIGMA = np.array([0.1, 0.05, 0.05, 0.05, 0.05, 0.05, 0.1])
SPEED_OF_LIGHT = 299_792_458.0
# Steps of the fixed-point inversion of the wiggle: each shrinks the error by the wiggle's
# slope, 2 pi amplitude / period (0.05 for 15 mm at 1.87 m).
INVERSE_STEPS = 4


def parse(spec: str) -> list[int]:
    """Indices of the estimated terms from 'none' or terms joined by '+', e.g. 'offset+tilt'."""
    if spec == "none":
        return []
    names = spec.split("+") if isinstance(spec, str) else []
    if not names or any(n not in TERMS for n in names) or len(set(names)) != len(names):
        raise CalibrationError(f"depth_bias must be 'none' or terms from {sorted(TERMS)} joined by '+', "
                               f"got {spec!r}")
    return sorted(i for n in names for i in TERMS[n])


def wiggle_period(modulation_hz: float) -> float:
    """The wiggling error's period in distance (m) of a four-phase ToF camera at this modulation."""
    return SPEED_OF_LIGHT / (8.0 * modulation_hz)


def modulation_hz(period: float) -> float:
    """The modulation frequency whose wiggle has this period (m): the inverse of ``wiggle_period``."""
    return SPEED_OF_LIGHT / (8.0 * period)


def wiggle_basis(period: float | None, depth: np.ndarray, radial: np.ndarray) -> np.ndarray:
    """(N, 2) the wiggle's sine and cosine terms in the depth's convention (zeros without a period)."""
    if period is None:
        return np.zeros((len(depth), 2))
    phase = 2 * np.pi * radial / period
    return np.column_stack([np.sin(phase), np.cos(phase)]) * (depth / radial)[:, None]


def measured(bias: np.ndarray, depth: np.ndarray, points: np.ndarray, period: float | None = None) -> np.ndarray:
    """The depth the camera reports for camera-frame points whose true depth is ``depth``."""
    offset, scale, tx, ty, ws, wc, radial = bias
    linear = (1 + scale) * depth + offset + tx * points[:, 0] + ty * points[:, 1]
    if radial:
        linear = linear + radial * depth / np.linalg.norm(points, axis=1)
    if period is None or (ws == 0 and wc == 0):
        return linear
    return linear + wiggle_basis(period, depth, np.linalg.norm(points, axis=1)) @ np.array([ws, wc])


def true_depth(bias: np.ndarray, reported: np.ndarray, directions: np.ndarray,
               period: float | None = None) -> np.ndarray:
    """Inverse of ``measured`` along rays scaled so that the point is depth x direction."""
    offset, scale, tx, ty, ws, wc, radial = bias
    gain = 1 + scale + tx * directions[:, 0] + ty * directions[:, 1]
    ray = np.linalg.norm(directions, axis=1)
    offset = offset + radial / ray   # depth / r is the same all along a ray
    depth = (reported - offset) / gain
    if period is None or (ws == 0 and wc == 0):
        return depth
    for _ in range(INVERSE_STEPS):
        depth = (reported - offset - wiggle_basis(period, depth, depth * ray) @ np.array([ws, wc])) / gain
    return depth
