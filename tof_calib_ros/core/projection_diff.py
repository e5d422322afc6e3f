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

from .bundle import jackknife_spread
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


def _rotation(va: np.ndarray, vb: np.ndarray) -> np.ndarray:
    """The rotation R that best takes the unit rays ``va`` onto ``vb`` (Wahba's problem), over the
    pairs both models give."""
    ok = np.isfinite(va).all(axis=1) & np.isfinite(vb).all(axis=1)
    return Rotation.align_vectors(vb[ok], va[ok])[0].as_matrix()


class _From(NamedTuple):
    """One calibration's rays through a grid over the image and through the pixels the board was
    seen at: what every comparison with it starts from, computed once."""
    xs: np.ndarray
    ys: np.ndarray
    grid: np.ndarray       # (N, 2) px
    rays: np.ndarray       # (N, 3) unit rays through ``grid``
    seen: np.ndarray       # (M, 2) px
    seen_rays: np.ndarray  # (M, 3)


def _rays_from(a: np.ndarray, image_size: tuple[int, int], seen: np.ndarray, step: int) -> _From:
    w, h = image_size
    xs = np.arange(step / 2 - 0.5, w - 0.5, step)
    ys = np.arange(step / 2 - 0.5, h - 0.5, step)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    seen = np.asarray(seen, dtype=float).reshape(-1, 2)
    return _From(xs, ys, grid, _unit_rays(grid, a), seen, _unit_rays(seen, a))


def _to(src: _From, b: np.ndarray) -> ProjectionDiff:
    """How far ``b`` projects the rays of ``src``, after the rotation that aligns them over its seen pixels."""
    R = _rotation(src.seen_rays, _unit_rays(src.seen, b))
    ok = np.isfinite(src.rays).all(axis=1)
    moved = src.rays[ok] @ R.T
    shift = np.full((len(src.grid), 2), np.nan)
    # a ray behind b's camera, or past where b's lens model folds, has no pixel in b
    seen_by_b = moved[:, 2] > 0
    seen_by_b[seen_by_b] = unfolded(moved[seen_by_b, :2] / moved[seen_by_b, 2:], b)
    idx = np.flatnonzero(ok)[seen_by_b]
    shift[idx] = project(moved[seen_by_b], b).pixels - src.grid[idx]
    return ProjectionDiff(src.xs, src.ys, shift.reshape(len(src.ys), len(src.xs), 2), R)


def projection_difference(a: np.ndarray, b: np.ndarray, image_size: tuple[int, int], seen: np.ndarray,
                          step: int = 8) -> ProjectionDiff:
    """How far (px) ``b`` projects the ray ``a`` gives each pixel of a grid over the image (every
    ``step`` px), after the rotation that aligns them over the pixels ``seen`` (N, 2); packed
    intrinsics ``a``, ``b`` as in core.camera."""
    return _to(_rays_from(a, image_size, seen, step), b)


def projection_spread(center: np.ndarray, refits: np.ndarray, image_size: tuple[int, int], seen: np.ndarray,
                      step: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """How well each pixel's projection is known (px; xs, ys and the (H', W') map): the grouped
    jackknife's spread of where the ``refits`` (intrinsics without each group of views, a row
    each) project the rays ``center`` gives, each aligned as in ``projection_difference``. Where
    no view reached, each refit extrapolates its lens terms its own way: what a parameter's
    standard deviation cannot show."""
    src = _rays_from(center, image_size, seen, step)
    spread = jackknife_spread(np.array([_to(src, r).shift for r in refits]))   # (H', W', 2)
    return src.xs, src.ys, np.hypot(spread[..., 0], spread[..., 1])
