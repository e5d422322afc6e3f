"""Where two calibrations of one camera project apart over the image, as mrcal's projection_diff
shows it: each pixel's ray through one, projected through the other.

A camera's frame is defined only up to a rotation (the board poses take it up, and so does any
extrinsic calibration after), and a small one reads as a shift of the principal point. So the
rays are first aligned by the rotation that best maps one calibration's onto the other's where
the board was seen; what is left is what a user of either would see differ. A parameter table
cannot say where: a lens term fitted to views that missed part of the image may agree where
they looked and part far elsewhere.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

from .camera import project, rays, unfolded

# A pixel whose ray does not project back to it within this (px) is one where Newton's method
# found no ray (past a fold); the map leaves it blank.
ROUND_TRIP_PX = 0.01


class ProjectionDiff(NamedTuple):
    xs: np.ndarray         # (W',) pixel columns of the grid
    ys: np.ndarray         # (H',) pixel rows
    shift: np.ndarray      # (H', W', 2) px, b's pixel less a's; NaN where either model has no ray
    rotation: np.ndarray   # (3, 3) the camera frame's rotation from ``a``'s to ``b``'s

    @property
    def diff(self) -> np.ndarray:
        """(H', W') px, how far apart."""
        return np.hypot(self.shift[..., 0], self.shift[..., 1])

    @property
    def angle_deg(self) -> float:
        return float(np.degrees(Rotation.from_matrix(self.rotation).magnitude()))


def _unit_rays(pixels: np.ndarray, params: np.ndarray) -> np.ndarray:
    """Unit rays through ``pixels``, NaN where the lens model folds before them (no ray of their own)."""
    v = rays(pixels, params)
    v[~unfolded(v[:, :2], params) | (np.hypot(*(project(v, params).pixels - pixels).T) > ROUND_TRIP_PX)] = np.nan
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def implied_rotation(a: np.ndarray, b: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """The rotation R that best takes ``a``'s rays through the pixels ``seen`` onto ``b``'s
    (Wahba's problem, solved by the SVD): packed intrinsics ``a``, ``b`` as in core.camera."""
    va, vb = _unit_rays(seen, a), _unit_rays(seen, b)
    ok = np.isfinite(va).all(axis=1) & np.isfinite(vb).all(axis=1)
    U, _, Vt = np.linalg.svd(va[ok].T @ vb[ok])
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    return Vt.T @ np.diag([1.0, 1.0, d]) @ U.T


def projection_difference(a: np.ndarray, b: np.ndarray, image_size: tuple[int, int], seen: np.ndarray,
                          step: int = 8) -> ProjectionDiff:
    """How far (px) ``b`` projects the ray ``a`` gives each pixel of a grid over the image (every
    ``step`` px), after the rotation that aligns them over the pixels ``seen`` (N, 2)."""
    w, h = image_size
    xs = np.arange(step / 2 - 0.5, w - 0.5, step)
    ys = np.arange(step / 2 - 0.5, h - 0.5, step)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    R = implied_rotation(a, b, np.asarray(seen, dtype=float).reshape(-1, 2))
    va = _unit_rays(grid, a)
    ok = np.isfinite(va).all(axis=1)
    moved = va[ok] @ R.T
    shift = np.full((len(grid), 2), np.nan)
    # a ray behind b's camera, or past where b's lens model folds, has no pixel in b
    seen_by_b = moved[:, 2] > 0
    seen_by_b[seen_by_b] = unfolded(moved[seen_by_b, :2] / moved[seen_by_b, 2:], b)
    idx = np.flatnonzero(ok)[seen_by_b]
    shift[idx] = project(moved[seen_by_b], b).pixels - grid[idx]
    return ProjectionDiff(xs, ys, shift.reshape(len(ys), len(xs), 2), R)


def projection_spread(center: np.ndarray, refits: np.ndarray, image_size: tuple[int, int], seen: np.ndarray,
                      step: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """How well each pixel's projection is known (px; xs, ys and the (H', W') map): the grouped
    jackknife's spread of where the ``refits`` (intrinsics without each group of views, a row
    each) project the rays ``center`` gives, each aligned as in ``projection_difference``. Where
    no view reached, each refit extrapolates its lens terms its own way: what a parameter's
    standard deviation cannot show."""
    pds = [projection_difference(center, r, image_size, seen, step) for r in refits]
    shifts = np.array([p.shift for p in pds])
    m = len(shifts)
    spread = np.sqrt((m - 1) / m * np.sum((shifts - shifts.mean(axis=0)) ** 2, axis=(0, 3)))
    return pds[0].xs, pds[0].ys, spread
