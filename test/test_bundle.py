"""The joint fit's analytic sparse Jacobian against finite differences."""
import numpy as np
import pytest

from tof_calib_ros import Board
from tof_calib_ros.core import bundle, depth_bias
from tof_calib_ros.core.camera import N_INTRINSICS, project, transform_views


@pytest.mark.parametrize("convention", ["z", "radial"])
@pytest.mark.parametrize("period", [None, 0.6])
def test_jacobian_matches_finite_differences(convention, period):
    rng = np.random.default_rng(0)
    board = Board(4, 3, 0.05)
    obj = board.object_points()
    state = bundle.State(np.array([300.0, 290.0, 160.0, 120.0, -0.2, 0.05, 0.001, -0.001, 0.01]),
                         np.array([0.02, 0.01, 0.03, -0.02, 0.012, -0.008, 0.015]),
                         np.array([[0.1, -0.2, 0.05, -0.1, -0.05, 0.8], [-0.2, 0.1, 0.0, -0.05, 0.0, 1.1]]))
    def wiggle():   # a plane's share of it, and what the depth off the plane says of it
        if period is None:
            return None
        a = rng.normal(0, 1e3, (3, 2))
        return bundle.WiggleShape(rng.normal(0, 0.01, (12, 2)), a.T @ a, rng.normal(0, 10, 2))

    views = [bundle.Observations(obj, rng.uniform(100, 200, (12, 2)), rng.uniform(0.7, 1.2, 12), wiggle=wiggle(),
                                 radial=bundle.RadialShape(rng.uniform(1e4, 1e5), rng.normal(0, 100),
                                                           rng.normal(0, 0.05, 12), 0.01))
             for _ in range(2)]
    views[1].depth[3] = np.nan  # a corner without depth
    free = np.r_[np.arange(13 if period is None else 15), bundle.RADIAL]   # the wiggle's terms with its period
    problem = bundle.Problem(views, convention, np.array([0.5, 0.2]), np.array([0.01, 0.003]), free,
                             wiggle_period=period)
    x = problem.pack(state)
    r, J = problem.evaluate(state, True)
    J = J.dense(len(views))
    for k in range(len(x)):
        h = 1e-6 * max(abs(x[k]), 1.0)
        up, dn = x.copy(), x.copy()
        up[k] += h
        dn[k] -= h
        fd = (problem.evaluate(problem.unpack(up, state), False)[0]
              - problem.evaluate(problem.unpack(dn, state), False)[0]) / (2 * h)
        np.testing.assert_allclose(J[:, k], fd, rtol=1e-5, atol=1e-7 * np.abs(J).max())


@pytest.mark.parametrize("convention", ["z", "radial"])
def test_the_depth_model_inverts_with_a_wiggle(convention):
    """Planes are fitted to the depth with the model taken out: true_depth must undo measured."""
    rng = np.random.default_rng(1)
    xy = rng.uniform(-0.5, 0.5, (50, 2))
    u = np.column_stack([xy, np.ones(50)])
    if convention == "radial":
        u /= np.linalg.norm(u, axis=1, keepdims=True)
    depth = rng.uniform(0.5, 4.0, 50)
    bias = np.array([0.025, 0.01, 0.02, -0.01, 0.012, -0.009, 0.03])
    reported = depth_bias.measured(bias, depth, u * depth[:, None], period=1.87)
    assert np.ptp(reported - depth_bias.measured(bias, depth, u * depth[:, None])) > 0.01   # the wiggle is there
    np.testing.assert_allclose(depth_bias.true_depth(bias, reported, u, period=1.87), depth, atol=1e-7)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_depth_scale_left_out_is_carried_as_far_as_the_data_put_it(seed):
    """A depth scale the model leaves out moves the depth-aided fx by about as much (the fit
    trusts the depth's scale), whatever the tilts. Widened by the scale, fx's uncertainty is
    never below the fit's with the scale free (the data's own doubt of it), and where the data
    put the scale beyond that doubt it reaches as far as they put it, so a 3 % scale left out
    is stated, not trusted at the fit's own precision (as it was: 2.4 px stated, 8 px off).
    Where the depth's scale is right the widening stays near the data's doubt (the views' spread
    over folds may raise it)."""
    rng = np.random.default_rng(seed)
    board = Board(6, 5, 0.05)
    obj = board.object_points()
    truth = np.array([280.0, 280.0, 100.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    poses = np.array([[*rng.normal(0, 0.3, 3), -0.12, -0.1, z] for z in np.linspace(0.8, 1.4, 8)])
    std = {}
    for scale in (0.03, 0.0):
        views = []
        for pose in poses:
            X = transform_views(pose[None], obj, np.zeros(len(obj), dtype=int))[0]
            views.append(bundle.Observations(obj, project(X, truth).pixels + rng.normal(0, 0.05, (len(obj), 2)),
                                             (1 + scale) * X[:, 2] + rng.normal(0, 0.002, len(obj))))
        fit = bundle.solve(views, bundle.State(truth.copy(), np.zeros(depth_bias.N_BIAS), poses.copy()), "z",
                           [0, 1, 2, 3, N_INTRINSICS])
        moved = fit.state.intrinsics[0] - truth[0]
        wide = bundle.widened(views, fit, "z", N_INTRINSICS + 1, 5)
        freed = bundle.solve(views, fit.state, "z", [0, 1, 2, 3, N_INTRINSICS, N_INTRINSICS + 1])
        assert wide.state is fit.state and list(wide.free_global) == list(freed.free_global)
        std[scale] = wide.covariance[0, 0] ** 0.5
        assert std[scale] >= 0.99 * freed.covariance[0, 0] ** 0.5
        assert abs(moved) < 2 * std[scale]   # the truth within 2 stated sigmas
        if scale:
            assert abs(moved) > 0.5 * scale * truth[0] and abs(moved) > 10 * fit.covariance[0, 0] ** 0.5
            assert abs(freed.state.intrinsics[0] - truth[0]) < 3 * freed.covariance[0, 0] ** 0.5   # about the truth
    assert std[0.0] < 0.4 * std[0.03]


def _camera_and_poses(rng):
    """A lens-free camera and 8 general views of a 6x5 board from 0.7 to 1.4 m."""
    return np.array([280.0, 280.0, 100.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0]), _poses(rng, 8)


def _board_views(rng, truth, poses, sigma_px, sigma_depth):
    """The 6x5 board's corners and their z-depth in each pose, with white noise of these sigmas."""
    obj = Board(6, 5, 0.05).object_points()
    views = []
    for pose in poses:
        X = transform_views(pose[None], obj, np.zeros(len(obj), dtype=int))[0]
        views.append(bundle.Observations(obj, project(X, truth).pixels + rng.normal(0, sigma_px, (len(obj), 2)),
                                         X[:, 2] + rng.normal(0, sigma_depth, len(obj))))
    return views


@pytest.mark.filterwarnings("error")
def test_a_term_the_data_cannot_place_is_left_unconstrained():
    """Widened by a term the views cannot place at all, the fit states it unknown (an infinite
    variance, where it read NaN) and the camera stays finite: a rational lens's k4 about no
    distortion, where it trades exactly with k1."""
    rng = np.random.default_rng(4)
    truth, poses = _camera_and_poses(rng)
    views = _board_views(rng, truth, poses, 0.0, 0.0)   # noise-free: k1 stays 0
    state = bundle.State(truth, np.zeros(depth_bias.N_BIAS), poses)
    k1, k4 = 4, 9
    fit = bundle.solve(views, state, "z", [0, 1, 2, 3, k1])
    wide = bundle.widened(views, fit, "z", k4, 5)
    variance = np.diag(wide.covariance)
    assert list(wide.free_global) == [0, 1, 2, 3, k1, k4] and np.isposinf(variance[-2:]).all()
    assert np.isfinite(wide.covariance[:4, :4]).all() and (variance[:4] >= 0.99 * np.diag(fit.covariance)[:4]).all()
    assert (np.abs(wide.state.intrinsics[:4] - truth[:4]) < 3 * variance[:4] ** 0.5).all()


def _quiet_and_noisy(rng, poses, obj, truth, magnify=1.0):
    """Corners only: every third view quiet (0.02 px), the rest noisy (0.1 px); the quiet ones'
    pattern ``magnify``-d about the principal point, as a detector's error on the nearest boards
    (which their scatter does not show) would be."""
    views = []
    for j, pose in enumerate(poses):
        X = transform_views(pose[None], obj, np.zeros(len(obj), dtype=int))[0]
        quiet = j % 3 == 0
        px = project(X, truth).pixels + rng.normal(0, 0.02 if quiet else 0.1, (len(obj), 2))
        if quiet:
            px = truth[2:4] + (px - truth[2:4]) * magnify
        views.append(bundle.Observations(obj, px, np.full(len(obj), np.nan)))
    return views


def _poses(rng, n):
    return np.array([[*rng.normal(0, 0.35, 3), -0.12, -0.1, z] for z in np.linspace(0.7, 1.4, n)])


def test_the_move_between_pixel_weightings_has_the_spread_the_sandwich_gives():
    """Weighted alike, views whose noise differs tenfold give a camera that moves from the one
    each view's own noise weights; over 60 draws of the noise the move's spread is what the
    sandwich (the alike fit's covariance under each view's own noise) less the own fit's
    covariance says (Hausman's), within the draws' own error."""
    rng = np.random.default_rng(4)
    obj = Board(6, 5, 0.05).object_points()
    truth = np.array([280.0, 280.0, 100.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    poses = _poses(rng, 12)
    moves, predicted = [], []
    for _ in range(60):
        views = _quiet_and_noisy(rng, poses, obj, truth)
        start = bundle.State(truth.copy(), np.zeros(depth_bias.N_BIAS), poses.copy())
        own = bundle.solve(views, start, "z", [0, 1, 2, 3])
        alike = bundle.solve(views, own.state, "z", [0, 1, 2, 3], pooled_pixels=True)
        moves.append(alike.state.intrinsics[:4] - own.state.intrinsics[:4])
        predicted.append(np.diag(bundle._pooled_sandwich(views, own, alike, "z")) - np.diag(own.covariance))
    ratio = np.std(moves, axis=0) / np.sqrt(np.mean(predicted, axis=0))
    assert np.all((ratio > 0.75) & (ratio < 1.3)), ratio


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_what_the_pixel_weights_choose_is_stated(seed):
    """The quiet views' pattern 2 % magnified: weighted by its own noise the fit follows them,
    fx 4.2-5.6 px off at 7-17 of its sigmas; weighted alike it moves, beyond what the views'
    noise explains, and the stated uncertainty takes the move in (the truth then 1.6-2.4 of its
    sigmas away: weighted alike the fit is off too, by the quiet views' share). Without that
    error the move is the noise's, and nothing is added."""
    rng = np.random.default_rng(seed)
    obj = Board(6, 5, 0.05).object_points()
    truth = np.array([280.0, 280.0, 100.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    poses = _poses(rng, 18)
    for magnify in (1.02, 1.0):
        views = _quiet_and_noisy(rng, poses, obj, truth, magnify)
        fit = bundle.solve(views, bundle.State(truth.copy(), np.zeros(depth_bias.N_BIAS), poses.copy()), "z",
                           [0, 1, 2, 3])
        stated, _ = bundle.reweighted(views, fit, fit, "z")
        off, own, said = fit.state.intrinsics[0] - truth[0], fit.covariance[0, 0] ** 0.5, stated.covariance[0, 0] ** 0.5
        if magnify > 1:
            assert abs(off) > 5 * own and abs(off) < 3 * said, (off, own, said)
        else:
            assert said == own and abs(off) < 3 * own, (off, own, said)


@pytest.mark.parametrize("n, folds", [(23, 10), (7, 10), (49, 10)])
def test_runs_of_consecutive_views_leave_out_each_view_once(n, folds):
    """The block jackknife's folds: each refit leaves out one run of views in their order, and the
    runs together are every view once (the Kinect recording's halves, which every-5th-view folds
    never separate, need both)."""
    left_out = [np.setdiff1d(np.arange(n), kept) for kept in bundle.jackknife_folds(n, folds, consecutive=True)]
    assert len(left_out) == min(n, folds)
    assert np.array_equal(np.sort(np.concatenate(left_out)), np.arange(n))
    assert all(np.all(np.diff(run) == 1) and 1 <= len(run) <= -(-n // folds) for run in left_out)


def test_a_fold_refit_that_runs_off_is_refitted_from_the_fits_own_noise(monkeypatch):
    """A fold's refit that ends far worse than the whole fit it started from ran off in a valley
    (a rational lens's fx went to 581-1437 px for 248 on one machine and not on another): it is
    refitted from the fit's per-view noise instead of the first round's 1 px and 10 mm, and the
    better of the two kept. Refits that converge are left as they are."""
    rng = np.random.default_rng(4)
    truth, poses = _camera_and_poses(rng)
    views = _board_views(rng, truth, poses, 0.05, 0.002)
    free = [0, 1, 2, 3, N_INTRINSICS]
    fit = bundle.solve(views, bundle.State(truth.copy(), np.zeros(depth_bias.N_BIAS), poses.copy()), "z", free)
    real_solve, seeded = bundle.solve, []

    def counted(*args, **kwargs):
        seeded.append(kwargs.get("noise") is not None)
        return real_solve(*args, **kwargs)

    monkeypatch.setattr(bundle, "solve", counted)
    converged = bundle.fold_estimates(views, fit, "z", 4, free)
    assert not any(seeded) and np.all(np.abs(converged[:, 0] - fit.state.intrinsics[0]) < 1.0), converged[:, 0]

    def running_off(views_, state, *args, **kwargs):
        if kwargs.get("noise") is None:   # one LM step from a focal length 4 times too long
            state = bundle.State(state.intrinsics * np.r_[4, 4, np.ones(len(state.intrinsics) - 2)], state.bias,
                                 state.poses)
            return real_solve(views_, state, *args, **{**kwargs, "max_iter": 1, "rounds": 1})
        return real_solve(views_, state, *args, **kwargs)

    monkeypatch.setattr(bundle, "solve", running_off)
    refits = bundle.fold_estimates(views, fit, "z", 4, free)
    np.testing.assert_allclose(refits[:, :4], converged[:, :4], atol=0.5)
