"""The least uncertainty any calibration can have on a simulated scene: the Cramér-Rao bound.

A benchmark that finds a method X times better than OpenCV cannot tell from that alone whether X
is all the views allow. The bound can. A scene's observations are its corner pixels (Gaussian,
``corner_sigma``) and the depth of every pixel the board wholly fills (Gaussian, with the
variance ``render`` draws it with: ToF shot noise, so black squares and far or tilted boards are
noisier); the unknowns are the intrinsics, each view's pose and the depth's error terms. The
inverse of their Fisher information bounds the covariance of any unbiased estimate, and the
paper's 3D error drawn from that covariance (``expected_3d_error``) is the least such an
estimate makes on average. From the corners alone it is about what Zhang's method (OpenCV)
reaches at low noise; with the depth, what a depth-aided method could reach at best.

The Jacobians are analytic: a corner moves as its projection does; a depth pixel reads the board
point its ray meets, which stays on that pixel (the implicit function theorem gives how it
slides over the board as the intrinsics and the pose change). Poses are perturbed on the left:
R' = exp([w]x) R, t' = t + dt.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..core import camera as cam
from ..core.board import Board
from ..core.errors import CalibrationError
from . import BACKGROUND, BORDER, REFLECTIVITY, SUPERSAMPLE, Noise, SimCamera, _surfaces

# The depth error terms a bound may leave unknown: a column each (two for the wiggle's amplitude and
# phase; ``period``, the wiggle's period, for a method not told the modulation frequency).
DEPTH_TERMS = ("offset", "black", "wiggle", "period")
POSE = 6
SINGULAR = 1e-12   # relative eigenvalue below which the views do not fix a combination of the unknowns
WHITE = REFLECTIVITY[0]   # ``render``'s white albedo, which its noise and dark offset are relative to


@dataclass(frozen=True)
class Scene:
    """What a simulated calibration observes: ``ids``, the corners each view's corners are (the
    same in every view), with pixel noise ``corner_sigma``; the depth with ``noise``."""

    camera: SimCamera
    board: Board
    poses: list[tuple[np.ndarray, np.ndarray]]
    ids: np.ndarray
    noise: Noise
    corner_sigma: float
    convention: str = "z"


def _skew(a: np.ndarray) -> np.ndarray:
    out = np.zeros(a.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -a[..., 2], a[..., 1], -a[..., 0]
    return out - np.swapaxes(out, -1, -2)


def _corner_rows(scene: Scene, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """d(pixel)/d(intrinsics) and d(pixel)/d(pose) of one view's corners, whitened."""
    a = scene.board.object_points(scene.ids) @ R.T
    p = cam.project(a + t, scene.camera.params, jac=True)
    d_int = np.concatenate([p.d_k, p.d_dist], axis=2)
    d_pose = np.concatenate([p.d_point @ -_skew(a), p.d_point], axis=2)
    return d_int.reshape(-1, cam.N_INTRINSICS) / scene.corner_sigma, d_pose.reshape(-1, POSE) / scene.corner_sigma


def depth_pixels(scene: Scene, rvec: np.ndarray, tvec: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pixels the board wholly fills at a pose (x, y), the standard deviation ``render``
    draws their depth with, and how far each reads as a dark square does (0 white, 1 black)."""
    noise = scene.noise
    amp, depth, cov, albedo = _surfaces(scene.camera, scene.board, rvec, tvec, scene.convention, BORDER, BACKGROUND,
                                        True, SUPERSAMPLE, REFLECTIVITY)
    v, u = np.nonzero((cov >= 1.0) & np.isfinite(depth) & (amp > 0))
    sigma = np.sqrt(noise.depth_const ** 2 + noise.depth ** 2 * WHITE / amp[v, u])
    return np.column_stack([u, v]).astype(float), sigma, 1 - albedo[v, u] / WHITE


def _depth_rows(scene: Scene, R: np.ndarray, t: np.ndarray, rvec: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """d(depth)/d(intrinsics), d(depth)/d(pose) and the depth terms' columns of every pixel the
    board wholly fills, whitened by each pixel's noise."""
    noise, params = scene.noise, scene.camera.params
    pix, sigma, dark = depth_pixels(scene, rvec, t)
    ray = cam.rays(pix, params)
    n = R[:, 2]
    P = ray * (n @ t / (ray @ n))[:, None]
    p = cam.project(P, params, jac=True)
    plane = R[:, :2]
    slide = np.linalg.inv(p.d_point @ plane)                                  # d(board coords)/d(pixel)
    direct_pose = np.concatenate([-_skew(P - t), np.broadcast_to(np.eye(3), (len(P), 3, 3))], axis=2)
    d_pixel = np.concatenate([p.d_k, p.d_dist, p.d_point @ direct_pose], axis=2)
    dP = np.concatenate([np.zeros((len(P), 3, cam.N_INTRINSICS)), direct_pose], axis=2) \
        - plane[None] @ slide @ d_pixel
    depth, grad = cam.depth_of(P, scene.convention)
    r = np.linalg.norm(P, axis=1)
    k = 2 * np.pi / noise.wiggle_period
    per = depth / r                                                           # the sim's wiggle is of r, carried into z
    if noise.wiggle_amplitude > 0:
        phase = k * r + noise.wiggle_phase
        grad = grad + noise.wiggle_amplitude * (np.cos(phase)[:, None] * k * per[:, None] * P / r[:, None]
                                                + np.sin(phase)[:, None] * (grad / r[:, None]
                                                                            - (depth / r ** 3)[:, None] * P))
    d = np.einsum("nj,njq->nq", grad, dP)
    period = -noise.wiggle_amplitude * np.cos(k * r + noise.wiggle_phase) * k * r / noise.wiggle_period * per
    terms = np.column_stack([np.ones(len(P)), dark, np.sin(k * r) * per, np.cos(k * r) * per, period])
    w = 1 / sigma[:, None]
    return d[:, :cam.N_INTRINSICS] * w, d[:, cam.N_INTRINSICS:] * w, terms * w


def _columns(depth_terms: list[str]) -> list[int]:
    if not set(depth_terms) <= set(DEPTH_TERMS):
        raise CalibrationError(f"depth terms must be among {DEPTH_TERMS}, got {depth_terms}")
    return [c for name, cols in zip(DEPTH_TERMS, ([0], [1], [2, 3], [4])) if name in depth_terms for c in cols]


def _error_rows(scene: Scene, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How every board corner's 3D error (the paper's Eq. 12, before the norm) moves with the
    intrinsics and with the view's pose, about the truth where it is 0."""
    obj = scene.board.object_points()
    X = obj @ R.T + t
    p = cam.project(X / X[:, 2:], scene.camera.params, jac=True)
    d_xy = -np.linalg.solve(p.d_point[:, :, :2], np.concatenate([p.d_k, p.d_dist], axis=2))
    d_int = np.concatenate([d_xy, np.zeros((len(X), 1, cam.N_INTRINSICS))], axis=1) * X[:, 2, None, None]
    d_pose = np.concatenate([_skew(X - t), np.broadcast_to(-np.eye(3), (len(X), 3, 3))], axis=2)
    return (R.T @ d_int).reshape(-1, cam.N_INTRINSICS), (R.T @ d_pose).reshape(-1, POSE)


class Bound:
    """A scene's information, computed once: the bound for any choice of unknowns from it."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self._corners, self._depth, self._errors = [], [], []
        has_depth = scene.noise.depth > 0 or scene.noise.depth_const > 0
        for rvec, tvec in scene.poses:
            R = cv2.Rodrigues(np.asarray(rvec, dtype=float))[0]
            t = np.asarray(tvec, dtype=float)
            J = np.hstack(_corner_rows(scene, R, t))
            self._corners.append(J.T @ J)                       # [intrinsics, pose]
            if has_depth:
                J = np.hstack(_depth_rows(scene, R, t, rvec))
                self._depth.append(J.T @ J)                     # [intrinsics, pose, depth terms]
            self._errors.append(_error_rows(scene, R, t))

    def information(self, intrinsics: list[int], depth_terms: list[str] | None) -> np.ndarray:
        """The Fisher information of the free ``intrinsics`` (indices into the packed twelve), the
        depth terms and every view's pose, in that order; ``depth_terms`` None: the corners alone."""
        if depth_terms is not None and not self._depth:
            raise CalibrationError("noiseless depth carries unbounded information")
        cols = [] if depth_terms is None else _columns(depth_terms)
        n_int, n_global = len(intrinsics), len(intrinsics) + len(cols)
        info = np.zeros((n_global + POSE * len(self._corners),) * 2)
        pose = cam.N_INTRINSICS + np.arange(POSE)
        for i, corners in enumerate(self._corners):
            at = np.r_[np.arange(n_int), n_global + POSE * i + np.arange(POSE)]
            take = np.r_[intrinsics, pose]
            info[np.ix_(at, at)] += corners[np.ix_(take, take)]
            if depth_terms is not None:
                at = np.r_[at, n_int + np.arange(len(cols))]
                take = np.r_[take, cam.N_INTRINSICS + POSE + np.array(cols, dtype=int)]
                info[np.ix_(at, at)] += self._depth[i][np.ix_(take, take)]
        return info

    def covariance(self, intrinsics: list[int], depth_terms: list[str] | None) -> np.ndarray | None:
        """The bound on the covariance of ``information``'s unknowns; None where the views leave a
        combination of them unfixed (OpenCV refuses such views)."""
        info = self.information(intrinsics, depth_terms)
        s = 1 / np.sqrt(np.maximum(np.diag(info), 1e-300))
        w, V = np.linalg.eigh(info * s[:, None] * s[None, :])
        if w[0] <= SINGULAR * w[-1]:
            return None
        return (V / w) @ V.T * s[:, None] * s[None, :]

    def expected_3d_error(self, intrinsics: list[int], depth_terms: list[str] | None,
                          rng: np.random.Generator, draws: int = 256) -> float:
        """The median of the paper's 3D error (mm) over estimates drawn from the bound: the least
        an efficient calibration with these unknowns makes on this scene (inf where the views do
        not fix them). The error is linear in the estimate's error this close to the truth."""
        C = self.covariance(intrinsics, depth_terms)
        if C is None:
            return float("inf")
        n_global = len(C) - POSE * len(self._errors)
        delta = np.linalg.cholesky(C) @ rng.standard_normal((len(C), draws))
        per_view = []
        for i, (d_int, d_pose) in enumerate(self._errors):
            e = d_int[:, intrinsics] @ delta[:len(intrinsics)] + d_pose @ delta[n_global + POSE * i:][:POSE]
            per_view.append(np.linalg.norm(e.reshape(-1, 3, draws), axis=1).mean(axis=0))
        return float(np.median(np.mean(per_view, axis=0)) * 1e3)


def mean_3d_error(params: np.ndarray, poses: list[tuple[np.ndarray, np.ndarray]],
                  truth: list[tuple[np.ndarray, np.ndarray]], camera: SimCamera, board: Board) -> float:
    """The paper's Eq. 12 over every corner of the board, in millimetres: each true corner's pixel
    back-projected with the estimated intrinsics, scaled to its true depth (z) and mapped to the
    board with the estimated pose."""
    obj = board.object_points()
    errs = []
    for (rvec, tvec), (rvec_true, tvec_true) in zip(poses, truth):
        X, _ = cam.transform(rvec_true, tvec_true, obj)
        est = cam.points_from_depth(cam.rays(cam.project(X, camera.params).pixels, params), X[:, 2], "z")
        R = cv2.Rodrigues(np.asarray(rvec, dtype=float))[0]
        errs.append(np.linalg.norm((est - np.asarray(tvec, dtype=float)) @ R - obj, axis=1).mean())
    return float(np.mean(errs) * 1e3)
