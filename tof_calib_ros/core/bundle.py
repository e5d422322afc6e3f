"""The joint Levenberg-Marquardt over pixel and depth residuals (the paper's Eq. 8).

Parameters: the intrinsics ``[fx, fy, cx, cy, k1, k2, p1, p2, k3]``, the depth bias
``[offset, scale, tilt_x, tilt_y]`` (see depth_bias) and one pose ``[rvec, tvec]`` per view.
Each view's pixel and depth residuals are divided by that view's
standard deviations, so that millimetres and pixels can be added. The Jacobian is analytic
and sparse (a pose touches only its own view's rows); the normal equations are small enough
to solve densely, which also gives the covariance used for the reported uncertainties.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from . import depth_bias
from .camera import N_INTRINSICS, depth_of, project, transform

N_GLOBAL = N_INTRINSICS + depth_bias.N_BIAS


@dataclass
class Observations:
    """One view's data: board points, measured pixels, measured depth (NaN where missing).

    Denoised corner depths all come from one plane: ``depth_floor`` (the plane's own standard
    error) bounds their standard deviation from below, since their scatter about a smooth fit
    understates it, and ``depth_dof`` says how many independent measurements they are worth
    (3 for a plane), so that a systematic depth error over a view is not counted once per corner."""

    object_points: np.ndarray
    pixels: np.ndarray
    depth: np.ndarray
    depth_floor: float = 0.0
    depth_dof: float | None = None


@dataclass
class State:
    intrinsics: np.ndarray
    bias: np.ndarray = field(default_factory=lambda: np.zeros(depth_bias.N_BIAS))
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))

    def copy(self) -> "State":
        return State(self.intrinsics.copy(), self.bias.copy(), self.poses.copy())


@dataclass
class Fit:
    state: State
    pixel_residuals: list[np.ndarray]   # per view, (N, 2) predicted - measured, pixels
    depth_residuals: list[np.ndarray]   # per view, (N,) predicted - measured, metres (NaN if no depth)
    covariance: np.ndarray              # of the free global parameters then the poses
    free_global: np.ndarray             # indices into intrinsics + bias
    cost: float
    iterations: int


def _view_terms(obs: Observations, state: State, pose: np.ndarray, convention: str, jac: bool):
    X, dX = transform(pose[:3], pose[3:], obs.object_points, jac)
    pr = project(X, state.intrinsics, jac)
    d, dd = depth_of(X, convention)
    dpix = pr.pixels - obs.pixels
    ddep = depth_bias.measured(state.bias, d, X) - obs.depth
    if not jac:
        return dpix, ddep, None, None
    n = len(X)
    jp = np.zeros((n, 2, N_GLOBAL + 6))
    jp[:, :, :4] = pr.d_k
    jp[:, :, 4:9] = pr.d_dist
    jp[:, :, N_GLOBAL:] = np.einsum("nij,njk->nik", pr.d_point, dX)
    offset, scale, tx, ty = state.bias
    jd = np.zeros((n, N_GLOBAL + 6))
    jd[:, N_INTRINSICS:N_GLOBAL] = np.column_stack([np.ones(n), d, X[:, 0], X[:, 1]])
    grad = (1 + scale) * dd + np.array([tx, ty, 0.0])
    jd[:, N_GLOBAL:] = np.einsum("nj,njk->nk", grad, dX)
    return dpix, ddep, jp, jd


class Problem:
    """Residuals and Jacobian for a set of views, with some parameters held fixed."""

    def __init__(self, views: list[Observations], convention: str, sigma_px: np.ndarray,
                 sigma_depth: np.ndarray, free_global: np.ndarray, free_poses: bool = True,
                 weights: list[np.ndarray] | None = None):
        self.views = views
        self.convention = convention
        self.sigma_px = sigma_px
        self.sigma_depth = sigma_depth
        self.free_global = np.asarray(free_global, dtype=int)
        self.free_poses = free_poses
        self.weights = weights or [np.ones(len(v.pixels)) for v in views]
        self.priors = [i for i in range(N_INTRINSICS, N_GLOBAL) if i in set(self.free_global.tolist())]

    @property
    def n_params(self) -> int:
        return len(self.free_global) + (6 * len(self.views) if self.free_poses else 0)

    def unpack(self, x: np.ndarray, base: State) -> State:
        s = base.copy()
        flat = np.concatenate([s.intrinsics, s.bias])
        flat[self.free_global] = x[: len(self.free_global)]
        s.intrinsics, s.bias = flat[:N_INTRINSICS], flat[N_INTRINSICS:]
        if self.free_poses:
            s.poses = x[len(self.free_global):].reshape(-1, 6).copy()
        return s

    def pack(self, state: State) -> np.ndarray:
        flat = np.concatenate([state.intrinsics, state.bias])
        parts = [flat[self.free_global]]
        if self.free_poses:
            parts.append(state.poses.ravel())
        return np.concatenate(parts)

    def evaluate(self, state: State, jac: bool):
        """Whitened residual vector and, when asked, its sparse Jacobian in the free parameters."""
        res, rows, cols, vals = [], [], [], []
        g_map = np.full(N_GLOBAL, -1)
        g_map[self.free_global] = np.arange(len(self.free_global))
        row = 0
        for j, obs in enumerate(self.views):
            dpix, ddep, jp, jd = _view_terms(obs, state, state.poses[j], self.convention, jac)
            w = np.sqrt(self.weights[j])
            has_d = np.isfinite(obs.depth)
            rp = (dpix * (w / self.sigma_px[j])[:, None]).ravel()
            rd = (ddep[has_d] * w[has_d] / self.sigma_depth[j])
            res += [rp, rd]
            if jac:
                blocks = [(jp * (w / self.sigma_px[j])[:, None, None]).reshape(-1, N_GLOBAL + 6),
                          jd[has_d] * (w[has_d] / self.sigma_depth[j])[:, None]]
                for blk in blocks:
                    m = blk.shape[0]
                    r_idx = np.arange(row, row + m)
                    gcols = np.flatnonzero(g_map >= 0)
                    rows.append(np.repeat(r_idx, len(gcols)))
                    cols.append(np.tile(g_map[gcols], m))
                    vals.append(blk[:, gcols].ravel())
                    if self.free_poses:
                        base = len(self.free_global) + 6 * j
                        rows.append(np.repeat(r_idx, 6))
                        cols.append(np.tile(np.arange(base, base + 6), m))
                        vals.append(blk[:, N_GLOBAL:].ravel())
                    row += m
            else:
                row += len(rp) + len(rd)
        for i in self.priors:
            k = i - N_INTRINSICS
            res.append(np.array([state.bias[k] / depth_bias.PRIOR_SIGMA[k]]))
            if jac:
                rows.append(np.array([row]))
                cols.append(np.array([g_map[i]]))
                vals.append(np.array([1.0 / depth_bias.PRIOR_SIGMA[k]]))
            row += 1
        r = np.concatenate(res)
        if not jac:
            return r, None
        J = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(row, self.n_params))
        return r, J


def levenberg_marquardt(problem: Problem, state: State, max_iter: int = 100,
                        tol: float = 1e-12) -> tuple[State, np.ndarray, int]:
    """Marquardt-scaled LM; returns the state, the normal matrix at the solution and iterations."""
    x = problem.pack(state)
    r, J = problem.evaluate(state, True)
    cost = r @ r
    lam = 1e-3
    it = 0
    for it in range(1, max_iter + 1):
        A = (J.T @ J).toarray()
        g = J.T @ r
        diag = np.maximum(np.diag(A), 1e-12 * max(np.diag(A).max(), 1e-300))
        improved = False
        while lam < 1e16:
            try:
                step = -scipy.linalg.solve(A + lam * np.diag(diag), g, assume_a="pos")
            except (np.linalg.LinAlgError, ValueError):
                lam *= 10
                continue
            trial = problem.unpack(x + step, state)
            r_new, _ = problem.evaluate(trial, False)
            cost_new = r_new @ r_new
            if np.isfinite(cost_new) and cost_new < cost:
                improved = True
                break
            lam *= 10
        if not improved:
            break
        x = x + step
        state = trial
        r, J = problem.evaluate(state, True)
        small_step = np.linalg.norm(step) <= tol * (np.linalg.norm(x) + tol)
        small_gain = (cost - cost_new) <= tol * cost
        cost = cost_new
        lam = max(lam / 10, 1e-12)
        if small_step or small_gain:
            break
    A = (J.T @ J).toarray()
    return state, A, it


def residuals(views: list[Observations], state: State, convention: str) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Unweighted per-view pixel (N,2) and depth (N,) residuals, predicted minus measured."""
    pix, dep = [], []
    for j, obs in enumerate(views):
        dpix, ddep, _, _ = _view_terms(obs, state, state.poses[j], convention, False)
        pix.append(dpix)
        dep.append(ddep)
    return pix, dep


def _robust_sigma(values: np.ndarray, floor: float) -> float:
    v = values[np.isfinite(values)]
    return max(float(np.sqrt(np.mean(v ** 2))) if v.size else floor, floor)


def solve(views: list[Observations], state: State, convention: str, free_global, free_poses: bool = True,
          rounds: int = 3, loss: str | None = None, sigma_floor: tuple[float, float] = (1e-4, 1e-5),
          max_iter: int = 100) -> Fit:
    """LM with per-view variances re-estimated from the residuals between rounds (the paper's
    normalisation); ``loss='huber'`` down-weights outlying corners by iterative reweighting."""
    n = len(views)
    sigma_px = np.ones(n)
    sigma_d = np.full(n, 0.01)
    weights = None
    total_it = 0
    for _ in range(rounds):
        problem = Problem(views, convention, sigma_px, sigma_d, free_global, free_poses, weights)
        state, A, it = levenberg_marquardt(problem, state, max_iter)
        total_it += it
        pix, dep = residuals(views, state, convention)
        # Each view's variance, with its degrees of freedom (6 pose parameters per view).
        new_px, new_d = np.empty(n), np.empty(n)
        for j in range(n):
            m = pix[j].size + np.isfinite(dep[j]).sum()
            dof = max(m - 6, 1) / m
            new_px[j] = _robust_sigma(pix[j].ravel(), sigma_floor[0]) / np.sqrt(dof)
            n_d = np.isfinite(dep[j]).sum()
            worth = np.sqrt(n_d / views[j].depth_dof) if views[j].depth_dof and n_d else 1.0
            new_d[j] = max(_robust_sigma(dep[j], sigma_floor[1]) / np.sqrt(dof), views[j].depth_floor) * worth
        sigma_px, sigma_d = new_px, new_d
        if loss == "huber":
            weights = []
            for j in range(n):
                e = np.hypot(pix[j][:, 0], pix[j][:, 1]) / sigma_px[j]
                weights.append(np.where(e <= 2.0, 1.0, 2.0 / np.maximum(e, 1e-12)))
    problem = Problem(views, convention, sigma_px, sigma_d, free_global, free_poses, weights)
    r, J = problem.evaluate(state, True)
    A = (J.T @ J).toarray()
    dof = max(len(r) - problem.n_params, 1)
    scale = (r @ r) / dof
    cov = scipy.linalg.pinvh(A) * scale
    pix, dep = residuals(views, state, convention)
    return Fit(state, pix, dep, cov, problem.free_global, float(r @ r), total_it)
