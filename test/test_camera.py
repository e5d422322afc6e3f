"""The plumb_bob and rational_polynomial models against OpenCV and finite differences."""
import cv2
import numpy as np
import pytest

from tof_calib_ros.core.camera import (
    depth_of,
    fold_distance,
    points_from_depth,
    project,
    rays,
    split_intrinsics,
    transform,
    undistort_normalized,
)

PARAMS = np.array([284.4, 280.1, 101.0, 98.0, -0.3, 0.12, 0.001, -0.002, -0.02])
# the Azure Kinect depth camera's wide lens (its factory model)
RATIONAL = np.array([252.0, 251.0, 256.5, 254.5, 4.7247, 3.2092, 1.2e-4, 5.9e-6, 0.1706, 5.0559, 4.7758, 0.8865])
LENSES = pytest.mark.parametrize("params", [np.r_[PARAMS, 0.0, 0.0, 0.0], RATIONAL], ids=["plumb_bob", "rational"])


@pytest.fixture
def points():
    rng = np.random.default_rng(0)
    return np.column_stack([rng.uniform(-0.3, 0.3, (60, 2)), rng.uniform(0.5, 2.0, 60)])


@LENSES
def test_projection_matches_opencv(points, params):
    K, D = split_intrinsics(params)
    assert D.size == (5 if params is not RATIONAL else 8)
    ref, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), K, D)
    np.testing.assert_allclose(project(points, params).pixels, ref[:, 0], atol=1e-9)
    np.testing.assert_array_equal(project(points, params[:9] if D.size == 5 else params).pixels,
                                  project(points, params).pixels)   # a packing of 9 is plumb_bob


@LENSES
def test_projection_jacobians_match_finite_differences(points, params):
    pr = project(points, params, jac=True)
    analytic = np.concatenate([pr.d_k, pr.d_dist], axis=2)
    for i in range(12):
        h = 1e-5 * max(abs(params[i]), 1.0)
        up, dn = params.copy(), params.copy()
        up[i] += h
        dn[i] -= h
        fd = (project(points, up).pixels - project(points, dn).pixels) / (2 * h)
        np.testing.assert_allclose(analytic[:, :, i], fd, rtol=1e-6, atol=1e-6)
    for i in range(3):
        up, dn = points.copy(), points.copy()
        up[:, i] += 1e-7
        dn[:, i] -= 1e-7
        fd = (project(up, params).pixels - project(dn, params).pixels) / 2e-7
        np.testing.assert_allclose(pr.d_point[:, :, i], fd, rtol=1e-5, atol=1e-4)


@LENSES
def test_undistortion_inverts_projection_to_1e9_px(points, params):
    pix = project(points, params).pixels
    xy = undistort_normalized(pix, params)
    back = project(np.column_stack([xy, np.ones(len(xy))]), params).pixels
    assert np.abs(back - pix).max() < 1e-9
    np.testing.assert_allclose(xy, points[:, :2] / points[:, 2:], atol=1e-12)


@pytest.mark.parametrize("convention", ["z", "radial"])
def test_depth_conventions_and_gradient(points, convention):
    d, grad = depth_of(points, convention)
    expected = points[:, 2] if convention == "z" else np.linalg.norm(points, axis=1)
    np.testing.assert_allclose(d, expected)
    for i in range(3):
        up = points.copy()
        up[:, i] += 1e-7
        np.testing.assert_allclose((depth_of(up, convention)[0] - d) / 1e-7, grad[:, i], atol=1e-6)
    back = points_from_depth(rays(project(points, PARAMS).pixels, PARAMS), d, convention)
    np.testing.assert_allclose(back, points, atol=1e-10)


def test_pose_jacobian_matches_finite_differences():
    rng = np.random.default_rng(1)
    board = np.column_stack([rng.uniform(0, 0.3, (20, 2)), np.zeros(20)])
    pose = np.array([0.1, -0.2, 0.3, 0.1, 0.2, 1.0])
    X, J = transform(pose[:3], pose[3:], board, jac=True)
    for i in range(6):
        up, dn = pose.copy(), pose.copy()
        up[i] += 1e-7
        dn[i] -= 1e-7
        fd = (transform(up[:3], up[3:], board)[0] - transform(dn[:3], dn[3:], board)[0]) / 2e-7
        np.testing.assert_allclose(J[:, :, i], fd, atol=1e-7)


def test_a_lens_that_folds_back_inside_the_image_is_found_where_it_folds():
    """Radial only, fx = fy: the model folds where d(r (1 + k1 r^2 + k2 r^4 + k3 r^6))/dr = 0,
    at the first root r* of 1 + 3 k1 u + 5 k2 u^2 + 7 k3 u^3 (u = r^2), f r*(1 + ...) px out.
    A k3 of -2 (7 real Kinect v2 views fitted it) folds inside a 512x424 image; a strong barrel
    lens of the simulator does not, nor one whose fold lies beyond the image's corners."""
    f, k1, k2, k3 = 370.0, 0.05, 0.25, -2.0
    u = min(r.real for r in np.roots([7 * k3, 5 * k2, 3 * k1, 1]) if abs(r.imag) < 1e-12 and r.real > 0)
    radius = f * np.sqrt(u) * (1 + k1 * u + k2 * u ** 2 + k3 * u ** 3)
    assert radius < np.hypot(256, 212)
    assert fold_distance(np.array([f, f, 256.0, 212.0, k1, k2, 0, 0, k3]), (512, 424)) == pytest.approx(radius, abs=1.0)
    assert fold_distance(np.array([f, f, 256.0, 212.0, -0.3, 0.1, 1e-3, 1e-3, 0]), (512, 424)) is None
    assert fold_distance(np.array([f, f, 256.0, 212.0, k1, k2, 0, 0, k3]), (128, 106)) is None

