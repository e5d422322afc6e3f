"""The joint fit's analytic sparse Jacobian against finite differences."""
import numpy as np
import pytest

from tof_calib_ros import Board
from tof_calib_ros.core import bundle, depth_bias


@pytest.mark.parametrize("convention", ["z", "radial"])
@pytest.mark.parametrize("period", [None, 0.6])
def test_jacobian_matches_finite_differences(convention, period):
    rng = np.random.default_rng(0)
    board = Board(4, 3, 0.05)
    obj = board.object_points()
    state = bundle.State(np.array([300.0, 290.0, 160.0, 120.0, -0.2, 0.05, 0.001, -0.001, 0.01]),
                         np.array([0.02, 0.01, 0.03, -0.02, 0.012, -0.008]),
                         np.array([[0.1, -0.2, 0.05, -0.1, -0.05, 0.8], [-0.2, 0.1, 0.0, -0.05, 0.0, 1.1]]))
    curve = (lambda: None) if period is None else (lambda: rng.normal(0, 0.01, (12, 2)))   # a plane's share of it
    views = [bundle.Observations(obj, rng.uniform(100, 200, (12, 2)), rng.uniform(0.7, 1.2, 12), wiggle_curve=curve())
             for _ in range(2)]
    views[1].depth[3] = np.nan  # a corner without depth
    free = np.arange(13 if period is None else 15)   # the wiggle's terms with its period
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
    bias = np.array([0.025, 0.01, 0.02, -0.01, 0.012, -0.009])
    reported = depth_bias.measured(bias, depth, u * depth[:, None], period=1.87)
    assert np.ptp(reported - depth_bias.measured(bias, depth, u * depth[:, None])) > 0.01   # the wiggle is there
    np.testing.assert_allclose(depth_bias.true_depth(bias, reported, u, period=1.87), depth, atol=1e-7)
