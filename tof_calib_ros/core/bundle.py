"""The joint Levenberg-Marquardt over pixel and depth residuals (the paper's Eq. 8).

Parameters: the intrinsics ``[fx, fy, cx, cy, k1, k2, p1, p2, k3]``, the depth bias
``[offset, scale, tilt_x, tilt_y, wiggle_sin, wiggle_cos, radial]`` (see depth_bias) and one pose
``[rvec, tvec]`` per view.
Each view's pixel and depth residuals are divided by that view's standard deviations, so
that millimetres and pixels can be added. The Jacobian is analytic and block-sparse: a pose
touches only its own view's rows. So the normal equations are solved as in bundle
adjustment, by the Schur complement on the few global parameters, which also gives their
covariance for the reported uncertainties.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import chi2

from . import depth_bias
from .camera import N_INTRINSICS, depth_of, pack_intrinsics, project, split_intrinsics, transform_views
from .result import INTRINSIC_NAMES, Focal

N_GLOBAL = N_INTRINSICS + depth_bias.N_BIAS
WIGGLE = [N_INTRINSICS + k for k in depth_bias.TERMS["wiggle"]]
RADIAL = N_INTRINSICS + depth_bias.TERMS["radial"][0]
RAYLEIGH_MEDIAN = np.sqrt(2 * np.log(2))  # median length of a 2-D Gaussian residual, in sigmas
UNCONSTRAINED = 1e-12  # relative eigenvalue below which the views do not constrain a combination
# The least noise the uncertainties assume (pixels, metres): what a corner detector and a
# plane fit achieve at best. Exact (synthetic) data would otherwise claim exact parameters
# however weakly the views constrain them.
MIN_NOISE = (0.01, 1e-4)
LOSS_SCALE = 2.0  # residuals within this many sigmas count in full
JACKKNIFE_P = 0.05  # the false-alarm rate at which a jackknife spread beyond the covariance raises it


def loss_weights(loss: str, e: np.ndarray) -> np.ndarray:
    """Iteratively-reweighted least squares weights for residual lengths ``e`` in sigmas:
    'huber' bounds an outlier's pull, 'cauchy' all but removes a gross one."""
    if loss == "huber":
        return np.where(e <= LOSS_SCALE, 1.0, LOSS_SCALE / np.maximum(e, 1e-12))
    return 1.0 / (1.0 + (e / LOSS_SCALE) ** 2)


@dataclass
class WiggleShape:
    """A view's depth on the wiggle. ``curve`` (N, 2): how far each wiggle basis term at a corner
    lies off the plane fitted to it over the view's samples. The plane keeps only the wiggle's
    planar part, so a corner depth read off it is predicted with that part: the basis less this.
    ``information`` (2, 2) and ``moment`` (2,): what the samples' depth off the plane says of the
    wiggle's two terms (planarize.off_plane). Near frontal, a view's distance barely changes
    and the planar part trades with the focal length; the curvature across the board does not."""

    curve: np.ndarray
    information: np.ndarray
    moment: np.ndarray


@dataclass
class RadialShape:
    """A view's depth on a radial offset, as WiggleShape on the wiggle. The plane was fitted to
    the depth with a radial offset ``at`` taken out, so it keeps only the planar part of the rest:
    ``curve`` (N,) is how far the offset's term at each corner lies off it, a unit of offset
    beyond ``at`` moving a corner depth read off the plane by the term less this.
    ``information`` and ``moment``: what the samples' depth off the plane says of the offset
    (planarize.off_plane), the moment given as the depth before ``at`` was taken out would give
    it, so that the offset's estimate is moment / information."""

    information: float
    moment: float
    curve: np.ndarray
    at: float = 0.0


@dataclass
class Observations:
    """One view's data: board points, measured pixels, measured depth (NaN where missing).

    Denoised corner depths all come from one plane: ``depth_floor`` (the plane's own standard
    error) bounds their standard deviation from below, since their scatter about a smooth fit
    understates it, and ``depth_dof`` says how many independent measurements they are worth
    (3 for a plane), so that a systematic depth error over a view is not counted once per corner.
    ``wiggle``: where the depth model has a wiggle, what the view's depth says of it (WiggleShape).
    ``depth_inflation``: how many times its noise the depth's error is taken to be, where the
    depth pulls the corners off their fit by an error the model does not explain.
    ``radial``: what the view's depth says of a radial offset (RadialShape; z-depth only)."""

    object_points: np.ndarray
    pixels: np.ndarray
    depth: np.ndarray
    depth_floor: float = 0.0
    depth_dof: float | None = None
    wiggle: WiggleShape | None = None
    depth_inflation: float = 1.0
    radial: RadialShape | None = None


@dataclass
class State:
    intrinsics: np.ndarray
    bias: np.ndarray = field(default_factory=lambda: np.zeros(depth_bias.N_BIAS))
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))

    def __post_init__(self) -> None:
        if len(self.intrinsics) != N_INTRINSICS:   # a plumb_bob packing of 9
            self.intrinsics = pack_intrinsics(*split_intrinsics(self.intrinsics))

    def copy(self) -> State:
        return State(self.intrinsics.copy(), self.bias.copy(), self.poses.copy())

    @property
    def globals_(self) -> np.ndarray:
        """The intrinsics then the depth terms: what ``Fit.free_global`` indexes."""
        return np.r_[self.intrinsics, self.bias]


@dataclass
class Fit:
    state: State
    pixel_residuals: list[np.ndarray]   # per view, (N, 2) predicted - measured, pixels
    depth_residuals: list[np.ndarray]   # per view, (N,) predicted - measured, metres (NaN if no depth)
    covariance: np.ndarray              # of the free global parameters, in the order of free_global
    free_global: np.ndarray             # indices into intrinsics + bias
    iterations: int
    sigma_px: np.ndarray                # per view, the pixel and depth noise the fit assumed
    sigma_depth: np.ndarray
    weights: list[np.ndarray] | None    # per corner, the robust loss's weights
    wiggle_period: float | None = None  # m, the depth model's wiggling period, where it has one
    converged: bool = True              # False where the last round's LM stopped at its iteration cap

    def std(self) -> dict[str, float]:
        """Every intrinsic and depth term's standard deviation by name: 0 where it was held fixed."""
        names = list(INTRINSIC_NAMES) + list(depth_bias.NAMES)
        std = {n: 0.0 for n in names}
        for k, i in enumerate(self.free_global):
            std[names[i]] = float(np.sqrt(max(self.covariance[k, k], 0.0)))
        return std

    def focal(self) -> Focal:
        """fx, fy and their standard deviations."""
        std = self.std()
        return float(self.state.intrinsics[0]), float(self.state.intrinsics[1]), std["fx"], std["fy"]


@dataclass
class BlockJacobian:
    """Rows of the whitened Jacobian: global columns (R, G) and the own view's pose columns (R, 6)."""

    globals_: np.ndarray
    pose: np.ndarray
    view: np.ndarray      # (R,) the view each row belongs to

    def dense(self, n_views: int) -> np.ndarray:
        """The full matrix (for tests and inspection; the solver never forms it)."""
        J = np.zeros((len(self.view), self.globals_.shape[1] + 6 * n_views))
        J[:, :self.globals_.shape[1]] = self.globals_
        cols = self.globals_.shape[1] + 6 * self.view[:, None] + np.arange(6)
        J[np.arange(len(self.view))[:, None], cols] = self.pose
        return J


class Problem:
    """Residuals and Jacobian for a set of views, with some parameters held fixed."""

    def __init__(self, views: list[Observations], convention: str, sigma_px: np.ndarray,
                 sigma_depth: np.ndarray, free_global,
                 weights: list[np.ndarray] | None = None, wiggle_period: float | None = None):
        self.n_views = len(views)
        self.convention = convention
        self.wiggle_period = wiggle_period
        self.free_global = np.asarray(free_global, dtype=int)
        self.points = np.concatenate([v.object_points for v in views])
        self.pixels = np.concatenate([v.pixels for v in views])
        self.depth = np.concatenate([v.depth for v in views])
        self.wiggle_curve = np.concatenate([np.zeros((len(v.pixels), 2)) if v.wiggle is None
                                            else v.wiggle.curve for v in views])
        self.radial_curve = np.concatenate([np.zeros(len(v.pixels)) if v.radial is None else v.radial.curve
                                            for v in views])
        self.radial_at = np.concatenate([np.full(len(v.pixels), 0.0 if v.radial is None else v.radial.at)
                                         for v in views])
        self.wiggle_rows = _wiggle_rows(views) if set(WIGGLE) <= set(self.free_global.tolist()) else None
        self.radial_row = _radial_row(views) if RADIAL in self.free_global.tolist() else None
        self.view = np.concatenate([np.full(len(v.pixels), j) for j, v in enumerate(views)])
        w = np.sqrt(np.concatenate(weights)) if weights else np.ones(len(self.view))
        self.has_depth = np.isfinite(self.depth)
        self.pixel_scale = w / np.asarray(sigma_px)[self.view]
        self.depth_scale = (w / np.asarray(sigma_depth)[self.view])[self.has_depth]
        self.priors = [i for i in self.free_global.tolist() if i >= N_INTRINSICS]

    @property
    def n_params(self) -> int:
        return len(self.free_global) + 6 * self.n_views

    def unpack(self, x: np.ndarray, base: State) -> State:
        s = base.copy()
        flat = s.globals_
        flat[self.free_global] = x[: len(self.free_global)]
        s.intrinsics, s.bias = flat[:N_INTRINSICS], flat[N_INTRINSICS:]
        s.poses = x[len(self.free_global):].reshape(-1, 6).copy()
        return s

    def pack(self, state: State) -> np.ndarray:
        flat = state.globals_
        return np.concatenate([flat[self.free_global], state.poses.ravel()])

    def raw(self, state: State, jac: bool = False):
        """Unweighted residuals, predicted minus measured: pixels (N,2) and depth (N,), and
        when asked their Jacobians in all global and pose parameters, (N,2,G+6) and (N,G+6)."""
        X, dX = transform_views(state.poses, self.points, self.view, jac)
        pr = project(X, state.intrinsics, jac)
        d, dd = depth_of(X, self.convention)
        dpix = pr.pixels - self.pixels
        ddep = depth_bias.measured(state.bias, d, X, self.wiggle_period) - self.depth \
            - self.wiggle_curve @ state.bias[depth_bias.TERMS["wiggle"]] \
            - self.radial_curve * (state.bias[RADIAL - N_INTRINSICS] - self.radial_at)
        if not jac:
            return dpix, ddep, None, None
        n = len(X)
        jp = np.zeros((n, 2, N_GLOBAL + 6))
        jp[:, :, :4] = pr.d_k
        jp[:, :, 4:N_INTRINSICS] = pr.d_dist
        jp[:, :, N_GLOBAL:] = np.einsum("nij,njk->nik", pr.d_point, dX)
        _, scale, tx, ty, ws, wc, radial = state.bias
        jd = np.zeros((n, N_GLOBAL + 6))
        r = np.linalg.norm(X, axis=1)
        jd[:, N_INTRINSICS:N_GLOBAL] = np.column_stack(
            [np.ones(n), d, X[:, 0], X[:, 1], depth_bias.wiggle_basis(self.wiggle_period, d, r) - self.wiggle_curve,
             d / r - self.radial_curve])
        grad = (1 + scale) * dd + np.array([tx, ty, 0.0])
        # the radial term and the wiggle, f(r) d / r, move with the point too
        f, df = np.full(n, radial), np.zeros(n)
        if self.wiggle_period is not None:
            k = 2 * np.pi / self.wiggle_period
            f = f + ws * np.sin(k * r) + wc * np.cos(k * r)
            df = k * (ws * np.cos(k * r) - wc * np.sin(k * r))
        if self.wiggle_period is not None or radial:
            grad = grad + ((df * d / r ** 2 - f * d / r ** 3)[:, None] * X + (f / r)[:, None] * dd)
        jd[:, N_GLOBAL:] = np.einsum("nj,njk->nk", grad, dX)
        return dpix, ddep, jp, jd

    def evaluate(self, state: State, jac: bool) -> tuple[np.ndarray, BlockJacobian | None]:
        """Whitened residual vector and, when asked, its Jacobian in the free parameters. Beside
        the views' rows, rows on the global parameters alone: the depth terms' weak priors and
        what the views' depth off their planes says of the wiggle and of a radial offset."""
        dpix, ddep, jp, jd = self.raw(state, jac)
        prior = np.array([state.bias[i - N_INTRINSICS] / depth_bias.PRIOR_SIGMA[i - N_INTRINSICS]
                          for i in self.priors])
        M, c = self.wiggle_rows if self.wiggle_rows is not None else (np.zeros((0, 2)), np.zeros(0))
        a, m = self.radial_row if self.radial_row is not None else (np.zeros(0), np.zeros(0))
        r = np.concatenate([(dpix * self.pixel_scale[:, None]).ravel(),
                            ddep[self.has_depth] * self.depth_scale, prior,
                            M @ state.bias[depth_bias.TERMS["wiggle"]] - c, a * state.bias[RADIAL - N_INTRINSICS] - m])
        if not jac:
            return r, None
        rows = np.concatenate([(jp * self.pixel_scale[:, None, None]).reshape(-1, N_GLOBAL + 6),
                               jd[self.has_depth] * self.depth_scale[:, None]])
        free = list(self.free_global)
        alone = np.zeros((len(self.priors) + len(M) + len(a), len(free)))
        for k, i in enumerate(self.priors):
            alone[k, free.index(i)] = 1.0 / depth_bias.PRIOR_SIGMA[i - N_INTRINSICS]
        if len(M):
            alone[len(self.priors):len(self.priors) + len(M), [free.index(i) for i in WIGGLE]] = M
        if len(a):
            alone[-1, free.index(RADIAL)] = a[0]
        view = np.concatenate([np.repeat(self.view, 2), self.view[self.has_depth], np.zeros(len(alone), dtype=int)])
        g = np.vstack([rows[:, self.free_global], alone])
        pose = np.vstack([rows[:, N_GLOBAL:], np.zeros((len(alone), 6))])
        return r, BlockJacobian(g, pose, view)


def _wiggle_rows(views: list[Observations]) -> tuple[np.ndarray, np.ndarray] | None:
    """(M, c) with |M w - c|^2 the cost, up to a constant, of the wiggle's terms ``w`` against the
    views' depth off their planes (at each view's depth inflation, as its corner depths)."""
    shapes = [(v.wiggle, v.depth_inflation) for v in views if v.wiggle is not None]
    if not shapes:
        return None
    info = sum(s.information / k ** 2 for s, k in shapes)
    moment = sum(s.moment / k ** 2 for s, k in shapes)
    e, V = np.linalg.eigh(info)
    e = np.maximum(e, UNCONSTRAINED * max(e.max(), 1e-300))
    return np.sqrt(e)[:, None] * V.T, (V.T @ moment) / np.sqrt(e)


def _radial_row(views: list[Observations]) -> tuple[np.ndarray, np.ndarray] | None:
    """(a, m) with (a b - m)^2 the cost, up to a constant, of a radial offset ``b`` against the
    views' depth off their planes (at each view's depth inflation, as its corner depths)."""
    shapes = [(v.radial, v.depth_inflation) for v in views if v.radial is not None]
    if not shapes:
        return None
    info = max(sum(s.information / k ** 2 for s, k in shapes), 1e-300)
    moment = sum(s.moment / k ** 2 for s, k in shapes)
    return np.array([np.sqrt(info)]), np.array([moment / np.sqrt(info)])


@dataclass
class _Normal:
    """The normal equations in blocks: U (G,G), W (V,G,6), V (V,6,6), and the gradient."""

    U: np.ndarray
    W: np.ndarray
    V: np.ndarray
    g_glob: np.ndarray
    g_pose: np.ndarray


def _normal(J: BlockJacobian, r: np.ndarray, n_views: int) -> _Normal:
    # a product per view: four times faster than summing per-row outer products
    order = np.argsort(J.view, kind="stable")
    bounds = np.searchsorted(J.view[order], np.arange(n_views + 1))  # every view has rows
    g, p, rr = J.globals_[order], J.pose[order], r[order]
    W, V, gp = np.empty((n_views, g.shape[1], 6)), np.empty((n_views, 6, 6)), np.empty((n_views, 6))
    for j, rows in enumerate(map(slice, bounds[:-1], bounds[1:])):
        W[j], V[j], gp[j] = g[rows].T @ p[rows], p[rows].T @ p[rows], p[rows].T @ rr[rows]
    return _Normal(J.globals_.T @ J.globals_, W, V, J.globals_.T @ r, gp)


def _solve_normal(N: _Normal, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """Steps (global, pose) of the damped system, by the Schur complement on the globals."""
    U = N.U + lam * np.diag(np.maximum(np.diag(N.U), 1e-300))
    dV = np.maximum(np.einsum("vii->vi", N.V), 1e-300)
    Vinv = np.linalg.inv(N.V + lam * dV[:, :, None] * np.eye(6))
    WVinv = np.einsum("vgi,vij->vgj", N.W, Vinv)
    S = U - np.einsum("vgj,vhj->gh", WVinv, N.W)
    rhs = -N.g_glob + np.einsum("vgj,vj->g", WVinv, N.g_pose)
    dg = np.linalg.solve(S, rhs) if len(rhs) else rhs
    dp = -np.einsum("vij,vj->vi", Vinv, N.g_pose + np.einsum("vgi,g->vi", N.W, dg))
    return dg, dp


def global_covariance(N: _Normal) -> np.ndarray:
    """Inverse of the Schur complement: the globals' covariance with the poses marginalised.

    A combination of parameters the views do not constrain at all (e.g. the principal point
    and the lens' decentering under fronto-parallel views) gives each parameter in it an
    infinite variance; a pseudo-inverse would give it none, and a verdict built on that would
    trust a parameter the data never saw. Eigenvalues are taken of the matrix scaled to unit
    diagonal, so pixels, metres and distortion terms compare."""
    S = N.U - np.einsum("vgi,vij,vhj->gh", N.W, np.linalg.pinv(N.V), N.W)
    d = np.sqrt(np.maximum(np.diag(S), 0.0))
    scale = np.divide(1.0, d, out=np.zeros_like(d), where=d > 0)
    w, vecs = np.linalg.eigh(S * np.outer(scale, scale))
    keep = w > UNCONSTRAINED * max(w.max(initial=0.0), 1e-300)
    cov = (vecs[:, keep] / w[keep]) @ vecs[:, keep].T * np.outer(scale, scale)
    unknown = (d == 0) | np.any(np.abs(vecs[:, ~keep]) > 0.01, axis=1)
    cov[unknown, unknown] = np.inf   # only the variances: the correlations of those are meaningless
    return cov


def levenberg_marquardt(problem: Problem, state: State, max_iter: int = 100,
                        tol: float = 1e-12) -> tuple[State, int]:
    """Marquardt-scaled LM on the block normal equations."""
    r, J = problem.evaluate(state, True)
    cost = r @ r
    lam = 1e-3
    it = 0
    for it in range(1, max_iter + 1):
        N = _normal(J, r, problem.n_views)
        x = problem.pack(state)
        improved = False
        while lam < 1e16:
            try:
                dg, dp = _solve_normal(N, lam)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            step = np.concatenate([dg, dp.ravel()])
            trial = problem.unpack(x + step, state)
            r_new, _ = problem.evaluate(trial, False)
            cost_new = r_new @ r_new
            if np.isfinite(cost_new) and cost_new < cost:
                improved = True
                break
            lam *= 10
        if not improved:
            break
        state = trial
        r, J = problem.evaluate(state, True)
        small_step = np.linalg.norm(step) <= tol * (np.linalg.norm(x) + tol)
        small_gain = (cost - cost_new) <= tol * cost
        cost = cost_new
        lam = max(lam / 10, 1e-12)
        if small_step or small_gain:
            break
    return state, it


def _split(values: np.ndarray, view: np.ndarray, n_views: int) -> list[np.ndarray]:
    return [values[view == j] for j in range(n_views)]


def _robust_sigma(values: np.ndarray, floor: float) -> float:
    v = values[np.isfinite(values)]
    return max(float(np.sqrt(np.mean(v ** 2))) if v.size else floor, floor)


def solve(views: list[Observations], state: State, convention: str, free_global, rounds: int = 3,
          loss: str | None = None, sigma_floor: tuple[float, float] = (1e-4, 1e-5),
          max_iter: int = 100, wiggle_period: float | None = None, pooled_pixels: bool = False,
          noise: tuple[np.ndarray, np.ndarray] | None = None) -> Fit:
    """LM with per-view variances re-estimated from the residuals between rounds (the paper's
    normalisation); ``loss`` ('huber' or 'cauchy') down-weights outlying corners.
    ``wiggle_period``: the depth's wiggling period (m), where the depth model has one.
    ``pooled_pixels``: one pixel variance for every view (OpenCV's weighting).
    ``noise``: each view's pixel and depth sigmas to start from (1 px and 10 mm otherwise)."""
    n = len(views)
    sigma_px, sigma_d = (np.ones(n), np.full(n, 0.01)) if noise is None else (noise[0].copy(), noise[1].copy())
    weights = None
    total_it = 0
    for _ in range(rounds):
        problem = Problem(views, convention, sigma_px, sigma_d, free_global, weights, wiggle_period)
        state, it = levenberg_marquardt(problem, state, max_iter)
        total_it += it
        converged = it < max_iter or max_iter == 0   # none asked: the state given is the fit (OpenCV's)
        dpix, ddep, _, _ = problem.raw(state)
        pix, dep = _split(dpix, problem.view, n), _split(ddep, problem.view, n)
        # Each view's variance, with its degrees of freedom (6 pose parameters per view).
        new_px, new_d = np.empty(n), np.empty(n)
        for j in range(n):
            n_d = np.isfinite(dep[j]).sum()
            m = pix[j].size + n_d
            dof = max(m - 6, 1) / m
            if loss:  # the outliers must not set the scale they are judged by
                new_px[j] = max(np.median(np.hypot(pix[j][:, 0], pix[j][:, 1])) / RAYLEIGH_MEDIAN, sigma_floor[0])
            else:
                new_px[j] = _robust_sigma(pix[j].ravel(), sigma_floor[0]) / np.sqrt(dof)
            worth = np.sqrt(n_d / views[j].depth_dof) if views[j].depth_dof and n_d else 1.0
            new_d[j] = max(_robust_sigma(dep[j], sigma_floor[1]) / np.sqrt(dof), views[j].depth_floor) * worth \
                * views[j].depth_inflation
        if pooled_pixels:
            counts = np.array([p.size for p in pix], dtype=float)
            new_px = np.full(n, np.sqrt(np.sum(counts * new_px ** 2) / np.sum(counts)))
        sigma_px, sigma_d = new_px, new_d
        if loss:
            weights = [loss_weights(loss, np.hypot(pix[j][:, 0], pix[j][:, 1]) / sigma_px[j]) for j in range(n)]
    problem_sigmas = np.maximum(sigma_px, MIN_NOISE[0]), np.maximum(sigma_d, MIN_NOISE[1])
    problem = Problem(views, convention, *problem_sigmas, free_global, weights, wiggle_period)
    cov = _covariance(problem, state, n)
    dpix, ddep, _, _ = problem.raw(state)
    return Fit(state, _split(dpix, problem.view, n), _split(ddep, problem.view, n), cov,
               problem.free_global, total_it, problem_sigmas[0], problem_sigmas[1], weights,
               wiggle_period, converged)


def _covariance(problem: Problem, state: State, n_views: int) -> np.ndarray:
    """The free global parameters' covariance at ``state``."""
    r, J = problem.evaluate(state, True)
    dof = max(len(r) - problem.n_params, 1)
    # Scaled by the residuals when they exceed the assumed noise, never below it.
    return global_covariance(_normal(J, r, n_views)) * max((r @ r) / dof, 1.0)


def jackknife_folds(n: int, folds: int, consecutive: bool = False) -> list[np.ndarray]:
    """The views each of ``min(folds, n)`` refits keeps: fold k leaves out every m-th view from the
    k-th, or, ``consecutive``, the k-th of m runs of views in their order (views taken one after
    another share a region of the image and a distance, which every-m-th folds never leave out)."""
    m = min(folds, n)
    if consecutive:
        return [np.setdiff1d(np.arange(n), run) for run in np.array_split(np.arange(n), m)]
    return [np.setdiff1d(np.arange(n), np.arange(k, n, m)) for k in range(m)]


def jackknife_spread(estimates: np.ndarray) -> np.ndarray:
    """The grouped jackknife's standard deviation of the whole set's estimate, from the refits'
    estimates (one row each)."""
    m = len(estimates)
    return np.sqrt((m - 1) / m * np.sum((estimates - estimates.mean(0)) ** 2, axis=0))


def fold_estimates(views: list[Observations], fit: Fit, convention: str, folds: int, estimated,
                   loss: str | None = None, consecutive: bool = False) -> np.ndarray | None:
    """Every global parameter (intrinsics, then bias; a row each) refitted from the fit's state
    without each of ``folds`` groups of the views, ``estimated`` free: how far an error of each
    view's own moves them; a refit that ends worse than it started, by more than its terms'
    price, is refitted from the fit's own noise. None with fewer than 3 folds."""
    kept = jackknife_folds(len(views), folds, consecutive)
    if len(kept) < 3:
        return None
    estimates = []
    for keep in kept:
        state = State(fit.state.intrinsics.copy(), fit.state.bias.copy(), fit.state.poses[keep].copy())
        kept_views = [views[i] for i in keep]
        sub = solve(kept_views, state, convention, estimated, loss=loss, wiggle_period=fit.wiggle_period)
        start = deviance(kept_views, replace(fit, sigma_px=fit.sigma_px[keep], sigma_depth=fit.sigma_depth[keep]))
        if deviance(kept_views, sub) > start + len(estimated) * np.log(n_observations(kept_views)):
            # ended worse than it started, by more than its terms' price: the first round's noise
            # (1 px, 10 mm) let a near-degenerate lens run off (a rational lens's fx to 581-1437 px
            # for 248 on an AMD EPYC machine, not on an Intel Xeon); from the fit's own noise it stays
            again = solve(kept_views, state, convention, estimated, loss=loss, wiggle_period=fit.wiggle_period,
                          noise=(fit.sigma_px[keep], fit.sigma_depth[keep]))
            sub = min(sub, again, key=lambda f: deviance(kept_views, f))
        estimates.append(sub.state.globals_)
    return np.array(estimates)


def jackknifed(fit: Fit, estimates: np.ndarray | None, estimated) -> Fit:
    """The fit at the same estimate, each ``estimated`` global parameter's uncertainty raised to
    its grouped jackknife spread over ``estimates`` (``fold_estimates`` of the fit's views, at its
    state) where that is larger: an error of each view's own (a real sensor's depth at that
    view's distance and tilt) then counts, which the covariance, built on errors independent
    between corners, does not see (few real views' fx came out 2-5 of their sigmas apart)."""
    if estimates is None:
        return fit
    m = len(estimates)
    spread = jackknife_spread(estimates[:, fit.free_global])
    std = np.sqrt(np.maximum(np.diag(fit.covariance), 1e-300))
    # raised only where the spread exceeds what the covariance predicts for it (chi-square with
    # m - 1 degrees, at JACKKNIFE_P): on views whose errors are the model's, it would only add noise
    beyond = (spread / std) ** 2 > chi2.ppf(1 - JACKKNIFE_P, m - 1) / (m - 1)
    gain = np.where(np.isin(fit.free_global, estimated) & beyond, spread / std, 1.0)
    return replace(fit, covariance=fit.covariance * np.outer(gain, gain))


def widened(views: list[Observations], fit: Fit, convention: str, term: int, folds: int,
            loss: str | None = None) -> Fit:
    """The fit at the same estimate, with the uncertainty of a ``term`` it leaves out carried into
    the covariance: for a term the data may hold but cannot fix. The term counts as uncertain as
    the data leave it (the fit with it free, its spread over ``folds`` of the views included) or
    as far as they put it from the fit's value, whichever is more: at the data's doubt alone, a
    depth scale the real Kinect v2 views at 205x170 put 2-4 of its standard deviations off left
    fx 1.7 % low, trusted at 0.2 %."""
    free = np.r_[fit.free_global, term]
    loose = solve(views, fit.state, convention, free, loss=loss, wiggle_period=fit.wiggle_period)
    cov = jackknifed(loose, fold_estimates(views, loose, convention, folds, free, loss), free).covariance
    at = len(free) - 1
    shift = loose.state.globals_[term] - fit.state.globals_[term]
    # how each parameter moves with the term; a term the data cannot place at all (infinite
    # variance) moves nothing by it and stays unconstrained, where 0/inf and inf/inf made it NaN
    along = np.divide(cov[:, at], cov[at, at], out=np.zeros(len(cov)), where=np.isfinite(cov[at, at]))
    cov = cov + np.outer(along, along) * max(shift ** 2 - cov[at, at], 0.0)
    return replace(fit, covariance=cov, free_global=loose.free_global)


def _pooled_sandwich(views: list[Observations], fit: Fit, alike: Fit, convention: str) -> np.ndarray:
    """The covariance of ``alike`` (every view's pixels weighted alike) under the noise each view
    shows in ``fit`` (its own): its weights are not its noise, so its own covariance misstates it
    (the sandwich: the Schur complement's inverse about each view's part, with the poses profiled
    out view by view)."""
    problem = Problem(views, convention, alike.sigma_px, alike.sigma_depth, alike.free_global, alike.weights,
                      alike.wiggle_period)
    _, J = problem.evaluate(alike.state, True)
    N = _normal(J, np.zeros(len(J.view)), len(views))
    Vinv = np.linalg.pinv(N.V)
    profiled = J.globals_ - np.einsum("ri,rig->rg", J.pose, np.einsum("vij,vgj->vig", Vinv, N.W)[J.view])
    n_pixel_rows = 2 * len(problem.view)
    share = np.ones(len(J.view))
    share[:n_pixel_rows] = (fit.sigma_px / alike.sigma_px)[np.repeat(problem.view, 2)] ** 2
    bread = global_covariance(N)
    unknown = np.isinf(np.diag(bread))   # unconstrained (a rational lens's trading terms): they stay so,
    bread[unknown, unknown] = 0.0        # and their infinite variance must not make the rest NaN
    cov = bread @ (profiled.T @ (profiled * share[:, None])) @ bread
    cov[unknown, unknown] = np.inf
    return cov


def reweighted(views: list[Observations], fit: Fit, stated: Fit, convention: str,
               loss: str | None = None) -> tuple[Fit, dict[str, float]]:
    """``stated`` (the fit at the same estimate, its uncertainty as stated) with the camera's
    uncertainty raised by how far the fit moves when every view's pixels are weighted alike
    (OpenCV's weighting) instead of each by its own noise (the paper's, the fit's), where the
    views' noise does not explain the move (a chi-square test at JACKKNIFE_P): under the model
    both find one camera, but views' corners can share an error their scatter does not show (the
    real Kinect v2 views at 205x170 scatter least where they are nearest, and the nearest quarter
    alone gives fx 2 % above the rest), and the weights then choose the answer. Also returns
    the move, by name, where it counted."""
    alike = solve(views, fit.state, convention, fit.free_global, loss=loss, wiggle_period=fit.wiggle_period,
                  pooled_pixels=True)
    camera = np.flatnonzero(fit.free_global < 4)   # the focal lengths and the principal point
    index = fit.free_global[camera]
    shift = alike.state.globals_[index] - fit.state.globals_[index]
    # the difference's variance where the fit's own weights are its noise's (Hausman's)
    apart = np.diag(_pooled_sandwich(views, fit, alike, convention))[camera] - np.diag(fit.covariance)[camera]
    apart = np.maximum(apart, 0.0)
    beyond = np.isfinite(shift) & np.isfinite(apart) & (shift ** 2 > chi2.ppf(1 - JACKKNIFE_P, 1) * apart)
    excess = dict(zip(index, np.where(beyond, shift ** 2 - apart, 0.0)))
    var = np.maximum(np.diag(stated.covariance), 1e-300)
    extra = np.array([excess.get(i, 0.0) for i in stated.free_global])
    gain = np.sqrt(1 + np.divide(extra, var, out=np.zeros_like(var), where=np.isfinite(var)))
    moved = {INTRINSIC_NAMES[i]: float(m) for i, m, b in zip(index, shift, beyond) if b}
    return replace(stated, covariance=stated.covariance * np.outer(gain, gain)), moved


def score(views: list[Observations], fit: Fit, convention: str, extra) -> float:
    """How much freeing the ``extra`` global parameters would lower the fit's whitened cost, to
    first order (the score test): the Gauss-Newton step's predicted gain, with the noise the fit
    assumed. At the fit's optimum only the extra parameters contribute to it."""
    free = np.r_[fit.free_global, np.asarray(extra, dtype=int)]
    problem = Problem(views, convention, fit.sigma_px, fit.sigma_depth, free, fit.weights,
                      wiggle_period=fit.wiggle_period)
    r, J = problem.evaluate(fit.state, True)
    N = _normal(J, r, len(views))
    dg, dp = _solve_normal(N, 1e-9)
    return float(-(N.g_glob @ dg + np.sum(N.g_pose * dp)))


def deviance(views: list[Observations], fit: Fit) -> float:
    """-2 log-likelihood, up to a constant, with each view's noise at the fit's own estimate
    (profiled out): sum of 2 m ln(sigma) over each view's pixels and depth, m the measurements they
    are worth. Two fits' deviances differ by the likelihood-ratio statistic of their models."""
    return float(sum(2 * 2 * len(v.pixels) * np.log(spx) + 2 * _depth_worth(v) * np.log(sd)
                     for v, spx, sd in zip(views, fit.sigma_px, fit.sigma_depth)))


def _depth_worth(view: Observations) -> float:
    """How many independent measurements a view's corner depths are: as many as are valid, at
    most what their plane is worth."""
    return min(np.isfinite(view.depth).sum(), view.depth_dof or np.inf)


def n_observations(views: list[Observations]) -> float:
    """Independent measurements the views hold: two per corner, and each view's depth as many
    as it is worth (a plane's three), for an information criterion."""
    return float(sum(2 * len(v.pixels) + _depth_worth(v) for v in views))
