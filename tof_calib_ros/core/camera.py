"""The camera models of ROS CameraInfo and OpenCV, plumb_bob and rational_polynomial, with
analytic Jacobians.

Intrinsics are packed as ``[fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6]``: the radial factor
is (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6), plumb_bob where k4..k6 are 0
(a packing of 9 reads as plumb_bob). Wide ToF lenses (the Azure Kinect's) need the denominator:
no plumb_bob holds them to a pixel. Depth is either ``z`` (distance along the optical axis, REP
118) or ``radial`` (distance from the optical centre, what PMD-class sensors measure).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .errors import CalibrationError

DEPTH_CONVENTIONS = ("z", "radial")
N_DISTORTION = 8
N_INTRINSICS = 4 + N_DISTORTION
PLUMB_BOB = 5   # plumb_bob's coefficients, the first of rational_polynomial's
MODEL_TERMS = {"plumb_bob": PLUMB_BOB, "rational_polynomial": N_DISTORTION}   # ROS CameraInfo's names


def check_convention(convention: str) -> str:
    if convention not in DEPTH_CONVENTIONS:
        raise CalibrationError(f"depth convention must be 'z' or 'radial', got {convention!r}")
    return convention


@dataclass
class Projection:
    """Pixels and, when asked for, their derivatives by point (N,2,3), fx..cy (N,2,4), D (N,2,8)."""

    pixels: np.ndarray
    d_point: np.ndarray | None = None
    d_k: np.ndarray | None = None
    d_dist: np.ndarray | None = None


def _lens(params: np.ndarray) -> np.ndarray:
    """The 8 distortion coefficients of packed intrinsics, of 9 (plumb_bob) or 12."""
    D = np.zeros(N_DISTORTION)
    given = np.asarray(params[4:4 + N_DISTORTION], dtype=float)
    D[:given.size] = given
    return D


def distortion_model(D: np.ndarray) -> str:
    """ROS CameraInfo's name for a distortion vector."""
    return "plumb_bob" if np.asarray(D).size <= PLUMB_BOB else "rational_polynomial"


def split_intrinsics(params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """K (3x3) and D: plumb_bob's 5 coefficients, or rational_polynomial's 8 where k4..k6 are not 0."""
    fx, fy, cx, cy = params[:4]
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    D = _lens(params)
    return K, D if np.any(D[PLUMB_BOB:]) else D[:PLUMB_BOB]


def pack_intrinsics(K: np.ndarray, D: np.ndarray) -> np.ndarray:
    D = np.asarray(D, dtype=float).ravel()
    return np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], _lens(np.r_[np.zeros(4), D])]


def _distort(x: np.ndarray, y: np.ndarray, D: np.ndarray, jac: bool):
    k1, k2, p1, p2, k3, k4, k5, k6 = D
    r2 = x * x + y * y
    num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    rational = bool(k4 or k5 or k6)   # plumb_bob, the common lens, spares the division
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6)) if rational else 1.0
    radial = num / den if rational else num
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    if not jac:
        return xd, yd, None, None
    dr = k1 + r2 * (2 * k2 + 3 * k3 * r2)   # d(radial)/d(r2)
    if rational:
        dr = (dr - radial * (k4 + r2 * (2 * k5 + 3 * k6 * r2))) / den
    dxy = np.empty(x.shape + (2, 2))
    dxy[..., 0, 0] = radial + 2 * x * x * dr + 2 * p1 * y + 6 * p2 * x
    dxy[..., 0, 1] = 2 * x * y * dr + 2 * p1 * x + 2 * p2 * y
    dxy[..., 1, 0] = 2 * x * y * dr + 2 * p1 * x + 2 * p2 * y
    dxy[..., 1, 1] = radial + 2 * y * y * dr + 6 * p1 * y + 2 * p2 * x
    # d(radial)/d(k1, k2, k3) are r2, r4, r6 over den; d(radial)/d(k4, k5, k6) those times -radial
    r4 = r2 * r2
    up = (r2 / den, r4 / den, r4 * r2 / den)
    dD = np.empty(x.shape + (2, N_DISTORTION))
    for i, c in enumerate((x, y)):
        for col, u in zip((0, 1, 4), up):
            dD[..., i, col] = c * u
        for col, u in zip((5, 6, 7), up):
            dD[..., i, col] = -c * radial * u
    dD[..., 0, 2], dD[..., 0, 3] = 2 * x * y, r2 + 2 * x * x
    dD[..., 1, 2], dD[..., 1, 3] = r2 + 2 * y * y, 2 * x * y
    return xd, yd, dxy, dD


def project(points: np.ndarray, params: np.ndarray, jac: bool = False) -> Projection:
    """Project camera-frame points (N,3) to distorted pixels (N,2)."""
    X = np.asarray(points, dtype=float)
    fx, fy, cx, cy = params[:4]
    iz = 1.0 / X[:, 2]
    x = X[:, 0] * iz
    y = X[:, 1] * iz
    xd, yd, dxy, dD = _distort(x, y, _lens(params), jac)
    pix = np.stack([fx * xd + cx, fy * yd + cy], axis=1)
    if not jac:
        return Projection(pix)
    f = np.array([fx, fy])
    dn = np.zeros((X.shape[0], 2, 3))  # d(x, y)/d(X, Y, Z)
    dn[:, 0, 0] = iz
    dn[:, 1, 1] = iz
    dn[:, 0, 2] = -x * iz
    dn[:, 1, 2] = -y * iz
    d_point = f[None, :, None] * np.einsum("nij,njk->nik", dxy, dn)
    d_k = np.zeros((X.shape[0], 2, 4))
    d_k[:, 0, 0] = xd
    d_k[:, 1, 1] = yd
    d_k[:, 0, 2] = 1.0
    d_k[:, 1, 3] = 1.0
    return Projection(pix, d_point, d_k, f[None, :, None] * dD)


def undistort_normalized(pixels: np.ndarray, params: np.ndarray, tol_px: float = 1e-9,
                         max_iter: int = 50) -> np.ndarray:
    """Normalised image coordinates (N,2) of distorted pixels, by Newton's method to ``tol_px``."""
    pix = np.asarray(pixels, dtype=float).reshape(-1, 2)
    fx, fy, cx, cy = params[:4]
    D = _lens(params)
    target = np.stack([(pix[:, 0] - cx) / fx, (pix[:, 1] - cy) / fy], axis=1)
    xy = target.copy()
    if not np.any(D):
        return xy
    scale = np.array([fx, fy])
    # Each point is its own Newton problem: only those not yet converged are iterated (where the
    # model folds, near the corners of wide images, a few never converge and would otherwise keep
    # the whole image iterating to max_iter: 0.4 s for a 512x424 image).
    active = np.arange(len(xy))
    with np.errstate(over="ignore", invalid="ignore"):   # past a fold Newton runs off: no ray is there
        for _ in range(max_iter):
            xd, yd, dxy, _ = _distort(xy[active, 0], xy[active, 1], D, True)
            err = np.stack([xd, yd], axis=1) - target[active]
            moving = ~np.all(np.abs(err * scale) < tol_px, axis=1)
            if not moving.any():
                break
            active, err, dxy = active[moving], err[moving], dxy[moving]
            a, b, c, d = dxy[:, 0, 0], dxy[:, 0, 1], dxy[:, 1, 0], dxy[:, 1, 1]
            det = (a * d - b * c)[:, None]
            xy[active] -= np.stack([d * err[:, 0] - b * err[:, 1], a * err[:, 1] - c * err[:, 0]], axis=1) / det
    return xy


def fold_distance(params: np.ndarray, image_size: tuple[int, int], directions: int = 90,
                  steps: int = 2000, reach: float = 4.0) -> float | None:
    """How far from the principal point (px) the lens model folds back on itself inside the image,
    None where it is one-to-one over the whole image. Beyond a fold the model is not the lens's:
    fitted to views that leave the image's corners out, high-order terms (k3) can bend back
    before them, and a pixel there then has no ray or two (on 7 real Kinect v2 views, a k3 of
    -2 that fit them to 0.08 px put the views left out 25 px off). Searched along rays from the
    axis, out to ``reach`` (normalised units) or until the model leaves the image: a fold in the
    image's very corners, between two of the rays, can be missed."""
    fx, fy, cx, cy = params[:4]
    angle = np.linspace(0.0, 2 * np.pi, directions, endpoint=False)[:, None]
    r = np.linspace(0.0, reach, steps + 1)[None, 1:]
    xd, yd, dxy, _ = _distort(r * np.cos(angle), r * np.sin(angle), _lens(params), True)
    u, v = fx * xd + cx, fy * yd + cy
    w, h = image_size
    inside = (u >= -0.5) & (u <= w - 0.5) & (v >= -0.5) & (v <= h - 0.5)
    before_leaving = np.cumsum(~inside, axis=1) == 0
    folded = (dxy[..., 0, 0] * dxy[..., 1, 1] - dxy[..., 0, 1] * dxy[..., 1, 0] <= 0) & before_leaving
    rows = np.flatnonzero(folded.any(axis=1))
    if not rows.size:
        return None
    first = folded[rows].argmax(axis=1)   # where each ray folds; past it, the model turns back over the image
    return float(np.min(np.hypot(u[rows, first] - cx, v[rows, first] - cy)))


def unfolded(xy: np.ndarray, params: np.ndarray, steps: int = 64) -> np.ndarray:
    """Whether the lens model is one-to-one from the axis out to each normalised point (N,2): past
    a fold, a ray projects onto pixels whose own rays are others, and the model says nothing true."""
    t = np.linspace(0.0, 1.0, steps + 1)[1:, None]
    _, _, dxy, _ = _distort(t * xy[:, 0], t * xy[:, 1], _lens(params), True)
    return np.all(dxy[..., 0, 0] * dxy[..., 1, 1] - dxy[..., 0, 1] * dxy[..., 1, 0] > 0, axis=0)


def rays(pixels: np.ndarray, params: np.ndarray) -> np.ndarray:
    """Viewing rays (N,3) with z = 1 through distorted pixels."""
    xy = undistort_normalized(pixels, params)
    return np.column_stack([xy, np.ones(len(xy))])


def depth_of(points: np.ndarray, convention: str) -> tuple[np.ndarray, np.ndarray]:
    """Depth of camera-frame points in the given convention, and its gradient (N,3)."""
    X = np.asarray(points, dtype=float)
    if convention == "z":
        grad = np.zeros_like(X)
        grad[:, 2] = 1.0
        return X[:, 2].copy(), grad
    norm = np.linalg.norm(X, axis=1)
    return norm, X / norm[:, None]


def points_from_depth(rays_z1: np.ndarray, depth: np.ndarray, convention: str) -> np.ndarray:
    """3D points along rays (z = 1) at the given depth."""
    scale = depth if convention == "z" else depth / np.linalg.norm(rays_z1, axis=1)
    return rays_z1 * scale[:, None]


def transform(rvec: np.ndarray, tvec: np.ndarray, points: np.ndarray,
              jac: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Board points to the camera frame, and d(point)/d(rvec, tvec) (N,3,6) when asked."""
    poses = np.r_[np.ravel(rvec), np.ravel(tvec)][None]
    return transform_views(poses, points, np.zeros(len(points), dtype=int), jac)


def transform_views(poses: np.ndarray, points: np.ndarray, view: np.ndarray,
                    jac: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Board points to the camera frame, point ``n`` by pose ``view[n]`` of ``poses`` (V,6)."""
    rot = [cv2.Rodrigues(np.asarray(p[:3], dtype=float).reshape(3, 1)) for p in poses]
    R = np.array([r for r, _ in rot])[view]
    X = np.einsum("nij,nj->ni", R, points) + poses[view, 3:]
    if not jac:
        return X, None
    # cv2 gives dR (3x9): row k is d(R.ravel())/d(rvec_k).
    dR = np.array([d.reshape(3, 3, 3) for _, d in rot])[view]
    J = np.zeros((len(points), 3, 6))
    J[:, :, :3] = np.einsum("nkij,nj->nik", dR, points)
    J[:, 0, 3] = J[:, 1, 4] = J[:, 2, 5] = 1.0
    return X, J
