"""The joint fit's analytic sparse Jacobian against finite differences."""
import numpy as np
import pytest

from tof_calib_ros import Board
from tof_calib_ros.core import bundle


@pytest.mark.parametrize("convention", ["z", "radial"])
def test_jacobian_matches_finite_differences(convention):
    rng = np.random.default_rng(0)
    board = Board(4, 3, 0.05)
    obj = board.object_points()
    state = bundle.State(np.array([300.0, 290.0, 160.0, 120.0, -0.2, 0.05, 0.001, -0.001, 0.01]),
                         np.array([0.02, 0.01, 0.03, -0.02]),
                         np.array([[0.1, -0.2, 0.05, -0.1, -0.05, 0.8], [-0.2, 0.1, 0.0, -0.05, 0.0, 1.1]]))
    views = [bundle.Observations(obj, rng.uniform(100, 200, (12, 2)), rng.uniform(0.7, 1.2, 12)) for _ in range(2)]
    views[1].depth[3] = np.nan  # a corner without depth
    problem = bundle.Problem(views, convention, np.array([0.5, 0.2]), np.array([0.01, 0.003]), np.arange(13))
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
