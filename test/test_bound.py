"""The Cramér-Rao bound of a simulated scene against the simulator it describes and against
OpenCV, which is efficient from the corners at low noise: the benchmark's floor is only as
good as these."""
from dataclasses import replace

import cv2
import numpy as np
import pytest

from tof_calib_ros import sim
from tof_calib_ros.core import camera as cam
from tof_calib_ros.core.board import Board
from tof_calib_ros.sim import bound

BOARD = Board(11, 11, 0.05)
LENS = sim.SimCamera(np.array([284.4, 284.4, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0.0, 0.0, 0.0, 0.0]), 200, 200)
WIGGLE = sim.Noise(depth=0.01, offset=0.02, dark_offset=0.015, wiggle_amplitude=0.015, wiggle_period=1.87,
                   wiggle_phase=0.7)
SUBGRID = np.array([r * 11 + c for r in (0, 2, 4, 6, 8, 10) for c in (0, 2, 4, 6, 8, 10)])


def scene(n: int, tilt: float, seed: int, noise: sim.Noise = WIGGLE) -> bound.Scene:
    poses = sim.random_poses(LENS, BOARD, n, seed, distance=(0.9, 1.4), max_tilt_deg=tilt)
    return bound.Scene(LENS, BOARD, poses, SUBGRID, noise, 0.01)


def reads(sc: bound.Scene, pix: np.ndarray, params: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """What the simulated sensor reads at fixed pixels, less its noise, for any intrinsics and pose."""
    ray = cam.rays(pix, params)
    P = ray * (R[:, 2] @ t / (ray @ R[:, 2]))[:, None]
    r = np.linalg.norm(P, axis=1)
    n = sc.noise
    return P[:, 2] + n.wiggle_amplitude * np.sin(2 * np.pi * r / n.wiggle_period + n.wiggle_phase) * P[:, 2] / r


def test_the_depth_rows_are_the_derivatives_of_what_the_sensor_reads():
    sc = scene(1, 40, 3)
    rvec, tvec = sc.poses[0]
    R = cv2.Rodrigues(rvec)[0]
    d_int, d_pose, terms = bound._depth_rows(sc, R, tvec, rvec)
    pix, sigma, dark = bound.depth_pixels(sc, rvec, tvec)
    assert len(pix) > 5000 and np.allclose(terms[:, 0], 1 / sigma) and np.allclose(terms[:, 1], dark / sigma)
    for j, h in enumerate([1e-3] * 4 + [1e-6] * 8):
        step = np.eye(12)[j] * h
        fd = (reads(sc, pix, LENS.params + step, R, tvec) - reads(sc, pix, LENS.params - step, R, tvec)) / (2 * h)
        assert np.max(np.abs(fd / sigma - d_int[:, j])) < 1e-5 * np.max(np.abs(fd / sigma)), f"intrinsic {j}"
    h = 1e-6   # the wiggle's period, for a method not told the modulation frequency
    longer, shorter = (replace(sc, noise=replace(sc.noise, wiggle_period=sc.noise.wiggle_period + d)) for d in (h, -h))
    fd = (reads(longer, pix, LENS.params, R, tvec) - reads(shorter, pix, LENS.params, R, tvec)) / (2 * h)
    assert np.max(np.abs(fd / sigma - terms[:, 4])) < 1e-5 * np.max(np.abs(fd / sigma)), "period"
    for j in range(6):
        d = np.eye(6)[j] * 1e-6
        fd = (reads(sc, pix, LENS.params, cv2.Rodrigues(d[:3])[0] @ R, tvec + d[3:])
              - reads(sc, pix, LENS.params, cv2.Rodrigues(-d[:3])[0] @ R, tvec - d[3:])) / 2e-6
        assert np.max(np.abs(fd / sigma - d_pose[:, j])) < 1e-5 * np.max(np.abs(fd / sigma)), f"pose {j}"


def test_the_depth_noise_is_the_one_the_renderer_draws():
    sc = scene(1, 40, 4, sim.Noise(depth=0.01))
    rvec, tvec = sc.poses[0]
    pix, sigma, dark = bound.depth_pixels(sc, rvec, tvec)
    frame = sim.render(LENS, BOARD, rvec, tvec, noise=sc.noise, rng=5)
    u, v = pix.astype(int).T
    z = ((frame.depth[v, u] - frame.depth_true[v, u]) / sigma)
    assert abs(np.std(z) - 1) < 0.03 and abs(np.mean(z)) < 0.03
    black = dark > 0.5
    assert black.sum() > 1000 and np.median(sigma[black]) > 2.5 * np.median(sigma[~black])   # shot noise


def test_the_3d_error_rows_are_the_papers_error_near_the_truth():
    sc = scene(3, 40, 5)
    b = bound.Bound(sc)
    g = np.random.default_rng(0)
    delta = np.r_[g.normal(0, [0.3, 0.3, 0.2, 0.2, 1e-3, 1e-3, 1e-4, 1e-4, 1e-3, 1e-3, 1e-3, 1e-3]),
                  g.normal(0, 1e-4, 18)]
    poses, linear = [], []
    for i, ((rvec, tvec), (d_int, d_pose)) in enumerate(zip(sc.poses, b._errors)):
        d = delta[12 + 6 * i:18 + 6 * i]
        R = cv2.Rodrigues(d[:3])[0] @ cv2.Rodrigues(rvec)[0]
        poses.append((cv2.Rodrigues(R)[0].ravel(), tvec + d[3:]))
        linear.append(np.linalg.norm((d_int @ delta[:12] + d_pose @ d).reshape(-1, 3), axis=1).mean())
    exact = bound.mean_3d_error(LENS.params + delta[:12], poses, sc.poses, LENS, BOARD)
    assert exact > 0.1 and np.mean(linear) * 1e3 == pytest.approx(exact, rel=1e-3)


def test_the_corner_bound_is_what_opencv_reaches_from_the_corners():
    """OpenCV is the maximum-likelihood estimate from the corners: over noise draws on one
    scene its focal length spreads and its 3D error lands as the bound says."""
    sc = scene(5, 40, 6)
    b = bound.Bound(sc)
    obj = BOARD.object_points(SUBGRID).astype(np.float32)
    truth = [cam.project(cam.transform(r, t, BOARD.object_points(SUBGRID))[0], LENS.params).pixels for r, t in sc.poses]
    g = np.random.default_rng(7)
    fx, err = [], []
    for _ in range(60):
        corners = [(p + g.normal(0, 0.01, p.shape)).astype(np.float32) for p in truth]
        _, K, D, rvecs, tvecs = cv2.calibrateCamera([obj] * len(corners), corners, (200, 200), None, None)
        fx.append(K[0, 0])
        params = np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], D.ravel()[:5]]
        err.append(bound.mean_3d_error(params, [(r.ravel(), t.ravel()) for r, t in zip(rvecs, tvecs)], sc.poses,
                                       LENS, BOARD))
    assert np.std(fx) == pytest.approx(np.sqrt(b.covariance(list(range(9)), None)[0, 0]), rel=0.3)
    assert np.median(err) == pytest.approx(b.expected_3d_error(list(range(9)), None, g), rel=0.3)


def test_near_frontal_views_fix_the_focal_length_through_the_depth():
    """Near frontal the corners cannot tell the focal length from the distance; the depth can,
    down to what its offset (unknown) and noise leave: the benchmark's claims rest on this."""
    b = bound.Bound(scene(5, 5, 8, sim.Noise(depth=0.01)))
    corners = np.sqrt(b.covariance(list(range(8)), None)[0, 0])
    with_depth = np.sqrt(b.covariance(list(range(8)), ["offset"])[0, 0])
    known_offset = np.sqrt(b.covariance(list(range(8)), [])[0, 0])
    assert corners > 10 * with_depth > 10 * known_offset


def test_four_corners_a_view_fix_nine_lens_terms_only_with_the_depth():
    """OpenCV refuses 4 corners x 3 views; so does the bound, until the depth fixes the poses."""
    sc = scene(3, 40, 9)
    b = bound.Bound(bound.Scene(sc.camera, BOARD, sc.poses, np.array([0, 10, 110, 120]), sc.noise, 0.01))
    assert b.covariance(list(range(9)), None) is None
    assert b.expected_3d_error(list(range(9)), None, np.random.default_rng(0)) == float("inf")
    assert b.covariance(list(range(9)), ["offset", "black", "wiggle"]) is not None
