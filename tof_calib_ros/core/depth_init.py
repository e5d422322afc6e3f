"""Initial intrinsics and poses from the depth data (the paper's 'updating K').

Given each corner's denoised depth, a guess of K places the corners in 3D; the right K is the
one for which the board's squares come out at their true size. Unlike Zhang's method this
needs no tilt between views, so it also works where OpenCV refuses or diverges.
"""
from __future__ import annotations

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from .camera import pack_intrinsics, points_from_depth, rays, split_intrinsics
from .errors import CalibrationError

# A consistent set converges in about ten evaluations; without a cap, inconsistent data (corners
# of other views, say) took thousands (20 s) on the way to a calibration the verdict rejects.
MAX_EVALUATIONS = 100


def neighbour_pairs(object_points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairs of a view's corners that are near each other on the board, and their true distance."""
    diff = object_points[:, None, :] - object_points[None, :, :]
    dist = np.linalg.norm(diff, axis=2)
    i, j = np.triu_indices(len(object_points), 1)
    d = dist[i, j]
    near = d <= 1.5 * d.min() + 1e-12
    return i[near], j[near], d[near]


def focal_guess(pixels: list[np.ndarray], depth: list[np.ndarray], object_points: list[np.ndarray],
                image_size: tuple[int, int]) -> np.ndarray:
    """Pinhole intrinsics from similar triangles (f = pixel length x depth / metric length),
    with the principal point at the image centre: a start that needs no tilt and no OpenCV."""
    ratios = []
    for x, d, o in zip(pixels, depth, object_points):
        i, j, L = neighbour_pairs(o)
        dd = 0.5 * (d[i] + d[j])
        ok = np.isfinite(dd)
        ratios.append(np.linalg.norm(x[i] - x[j], axis=1)[ok] * dd[ok] / L[ok])
    ratios = np.concatenate(ratios)
    if not ratios.size:
        raise CalibrationError("no valid depth at any corner of any view (0 or NaN everywhere)")
    f = float(np.median(ratios))
    w, h = image_size
    return pack_intrinsics(np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]]), np.zeros(0))


def square_size_residuals(k: np.ndarray, base: np.ndarray, pixels: np.ndarray, depth: np.ndarray,
                          pairs: tuple[np.ndarray, np.ndarray, np.ndarray], convention: str,
                          estimate_offset: bool) -> np.ndarray:
    """Relative square-size errors over all views at once (corners stacked, pair indices global);
    ``k`` holds the first len(k) (less the offset) of fx, fy, cx, cy, then the offset."""
    intr = base.copy()
    n = len(k) - estimate_offset
    intr[:n] = k[:n]
    offset = k[n] if estimate_offset else 0.0
    i, j, L = pairs
    X = points_from_depth(rays(pixels, intr), depth - offset, convention)
    res = (np.linalg.norm(X[i] - X[j], axis=1) - L) / L
    if estimate_offset:
        res = np.r_[res, offset / 0.1 * 1e-3]  # a weak prior, as in the bundle
    return res[np.isfinite(res)]


def update_intrinsics(intrinsics: np.ndarray, pixels: list[np.ndarray], depth: list[np.ndarray],
                      object_points: list[np.ndarray], convention: str,
                      estimate_offset: bool, hold_principal_point: bool = False
                      ) -> tuple[np.ndarray, float, float]:
    """fx, fy, cx, cy (and a depth offset) that make every square its true size, distortion held;
    the principal point held too where asked: near frontal a square's size barely depends on it.

    Returns the intrinsics, the depth offset, and the RMS relative square-size error."""
    starts = np.cumsum([0] + [len(p) for p in pixels])
    pairs = [neighbour_pairs(o) for o in object_points]
    stacked = (np.concatenate([i + s for (i, _, _), s in zip(pairs, starts)]),
               np.concatenate([j + s for (_, j, _), s in zip(pairs, starts)]),
               np.concatenate([L for (_, _, L) in pairs]))
    n = 2 if hold_principal_point else 4
    k0 = np.r_[intrinsics[:n], 0.0] if estimate_offset else intrinsics[:n].copy()
    sol = least_squares(square_size_residuals, k0, method="lm", x_scale="jac", max_nfev=MAX_EVALUATIONS,
                        args=(intrinsics, np.concatenate(pixels), np.concatenate(depth), stacked, convention,
                              estimate_offset))
    out = intrinsics.copy()
    out[:n] = sol.x[:n]
    offset = float(sol.x[n]) if estimate_offset else 0.0
    return out, offset, float(np.sqrt(np.mean(sol.fun ** 2)))


def square_from_depth(intrinsics: np.ndarray, pixels: list[np.ndarray], depth: list[np.ndarray],
                      object_points: list[np.ndarray], convention: str) -> float:
    """The square size the depth implies with the given intrinsics (the corners' alone, which do
    not depend on it), as a multiple of the size given: the scale that, with a depth offset
    fitted alongside, makes every square its size. What to tell a person whose square size or
    depth unit is wrong."""
    rows = [(p, d, o) for p, d, o in zip(pixels, depth, object_points) if np.isfinite(d).all()]
    if not rows:
        return float("nan")
    r = [rays(p, intrinsics) for p, _, _ in rows]
    pairs = [neighbour_pairs(o) for _, _, o in rows]

    def residuals(k: np.ndarray) -> np.ndarray:
        scale, offset = k
        out = []
        for rr, (_, d, _), (i, j, L) in zip(r, rows, pairs):
            X = points_from_depth(rr, d - offset, convention)
            out.append(np.linalg.norm(X[i] - X[j], axis=1) / L - scale)
        return np.concatenate(out)

    sol = least_squares(residuals, np.array([1.0, 0.0]), method="lm", max_nfev=MAX_EVALUATIONS)
    return float(sol.x[0])


def pose_from_points(object_points: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Rigid board-to-camera pose (rvec, tvec) from corresponding 3D points (Kabsch)."""
    ok = np.all(np.isfinite(points), axis=1)
    a, b = object_points[ok], points[ok]
    ca, cb = a.mean(0), b.mean(0)
    R = Rotation.align_vectors(b - cb, a - ca)[0]
    return np.r_[R.as_rotvec(), cb - R.apply(ca)]


def pose_from_pixels(object_points: np.ndarray, pixels: np.ndarray, intrinsics: np.ndarray) -> np.ndarray:
    """Pose (rvec, tvec) of a view with no usable depth, from its corners alone."""
    K, D = split_intrinsics(intrinsics)
    try:   # OpenCV wants contiguous arrays
        ok, rvec, tvec = cv2.solvePnP(np.ascontiguousarray(object_points, dtype=float),
                                      np.ascontiguousarray(pixels, dtype=float), K, D)
    except cv2.error:
        ok = False
    if not ok:
        raise CalibrationError("a view's pose could not be found from its corners")
    return np.r_[rvec.ravel(), tvec.ravel()]
