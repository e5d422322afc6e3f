"""The synthetic ToF renderer against its own exact ground truth."""
import time
import warnings

import cv2
import numpy as np
import pytest

from tof_calib_ros import sim
from tof_calib_ros.core import camera as cam
from tof_calib_ros.core.board import Board
from tof_calib_ros.core.errors import CalibrationError

BOARD = Board(6, 5, 0.04)
CAMERA = sim.pmd_camera()


def frontal(distance, board=BOARD, camera=CAMERA, roll_deg=0.0, tilt=(0.0, 0.0)):
    """A board centred on the principal point at z = distance (m)."""
    Rt, _ = cv2.Rodrigues(np.array([tilt[0], tilt[1], 0.0]))
    Rr, _ = cv2.Rodrigues(np.array([0.0, 0.0, np.radians(roll_deg)]))
    R = Rt @ Rr
    centre = np.array([(board.cols - 1) / 2, (board.rows - 1) / 2, 0.0]) * board.square
    tvec = np.array([0.0, 0.0, distance]) - R @ centre
    return cv2.Rodrigues(R)[0].ravel(), tvec


TILTED = frontal(0.7, tilt=(0.35, -0.25), roll_deg=8.0)


def analytic(camera, rvec, tvec):
    """Exact ray/plane intersection at every pixel centre: rays (N,3), ray parameter s (z),
    board-plane coordinates (N,2)."""
    u, v = np.meshgrid(np.arange(camera.width, dtype=float), np.arange(camera.height, dtype=float))
    d = cam.rays(np.stack([u.ravel(), v.ravel()], 1), camera.params)
    R, _ = cv2.Rodrigues(np.asarray(rvec, float))
    n = R[:, 2]
    s = (n @ tvec) / (d @ n)
    P = d * s[:, None]
    b = (P - tvec) @ R
    return d, s, b


@pytest.mark.parametrize("convention", ["z", "radial"])
def test_noiseless_depth_is_the_ray_plane_depth(convention):
    rvec, tvec = TILTED
    f = sim.render(CAMERA, BOARD, rvec, tvec, convention=convention, flying_pixels=False)
    d, s, b = analytic(CAMERA, rvec, tvec)
    expected = s if convention == "z" else s * np.linalg.norm(d, axis=1)
    on_board = f.coverage.ravel() == 1.0
    assert on_board.sum() > 5000
    got = f.depth_true.ravel()
    assert np.max(np.abs(got[on_board] - expected[on_board])) < 1e-9
    # float32 output: rounding only.
    assert np.max(np.abs(f.depth.ravel()[on_board] - expected[on_board])) < 1e-6
    # The points the depth implies lie on the board plane.
    P = cam.points_from_depth(d[on_board], got[on_board], convention)
    R, _ = cv2.Rodrigues(rvec)
    assert np.max(np.abs((P - tvec) @ R[:, 2])) < 1e-9
    # Off the board: the 3 m wall.
    wall = f.coverage.ravel() == 0.0
    wall_depth = 3.0 if convention == "z" else 3.0 * np.linalg.norm(d[wall], axis=1)
    assert np.allclose(got[wall], wall_depth, atol=1e-12)


@pytest.mark.parametrize("convention", ["z", "radial"])
def test_ground_truth_corners(convention):
    rvec, tvec = TILTED
    f = sim.render(CAMERA, BOARD, rvec, tvec, convention=convention)
    # independently of the renderer's own camera code: OpenCV's projection, plain numpy's depth
    expected, _ = cv2.projectPoints(BOARD.object_points(), np.asarray(rvec, float), np.asarray(tvec, float),
                                    CAMERA.K, CAMERA.D)
    assert np.allclose(f.corners, expected.reshape(-1, 2), atol=1e-9)
    X = BOARD.object_points() @ cv2.Rodrigues(np.asarray(rvec, float))[0].T + tvec
    assert np.allclose(f.corner_depth, X[:, 2] if convention == "z" else np.linalg.norm(X, axis=1), atol=1e-12)
    assert f.corners.shape == (BOARD.n_corners, 2)
    assert np.allclose(f.K, CAMERA.K) and np.allclose(f.D, CAMERA.D)
    assert np.allclose(f.rvec, rvec) and np.allclose(f.tvec, tvec)
    assert f.convention == convention


def square_centre_pixels(camera, rvec, tvec, board, colour_even):
    """Pixels at the centres of the squares whose (i + j) parity is even (dark) or odd."""
    pts = []
    for j in range(-1, board.rows):
        for i in range(-1, board.cols):
            if ((i + j) % 2 == 0) == colour_even:
                pts.append([(i + 0.5) * board.square, (j + 0.5) * board.square, 0.0])
    X, _ = cam.transform(rvec, tvec, np.array(pts))
    return np.round(cam.project(X, camera.params).pixels).astype(int)


def test_square_colours():
    rvec, tvec = TILTED
    f = sim.render(CAMERA, BOARD, rvec, tvec)
    dark = square_centre_pixels(CAMERA, rvec, tvec, BOARD, True)
    light = square_centre_pixels(CAMERA, rvec, tvec, BOARD, False)
    a_dark = f.amplitude[dark[:, 1], dark[:, 0]].astype(float)
    a_light = f.amplitude[light[:, 1], light[:, 0]].astype(float)
    assert a_light.min() > 5 * a_dark.max()
    # The border is white too.
    Xb, _ = cam.transform(rvec, tvec, np.array([[-1.5 * BOARD.square, 2 * BOARD.square, 0.0]]))
    ub, vb = np.round(cam.project(Xb, CAMERA.params).pixels[0]).astype(int)
    assert f.amplitude[vb, ub] > 0.8 * a_light.min()


def test_amplitude_scale_and_falloff():
    # A white square's centre on the optical axis, facing the camera.
    white_centre = np.array([2.5, 1.5, 0.0]) * BOARD.square
    u, v = int(CAMERA.params[2]), int(CAMERA.params[3])
    frames = {z: sim.render(CAMERA, BOARD, np.zeros(3), np.array([0, 0, z]) - white_centre,
                            dtype=np.float32) for z in (1.0, 2.0)}
    # White at 1 m facing the camera: 60 % of full scale.
    assert frames[1.0].amplitude[v, u] == pytest.approx(0.6, rel=1e-6)
    assert frames[2.0].amplitude[v, u] == pytest.approx(0.6 / 4, rel=1e-6)
    u16 = sim.render(CAMERA, BOARD, np.zeros(3), np.array([0, 0, 1.0]) - white_centre)
    assert u16.amplitude.dtype == np.uint16
    assert u16.amplitude[v, u] == round(0.6 * 65535)
    # Off axis and tilted, the amplitude falls with cos(incidence) / r^2.
    rvec = np.array([0.0, 0.5, 0.0])
    tvec = np.array([0, 0, 1.0]) - cv2.Rodrigues(rvec)[0] @ white_centre
    tilted = sim.render(CAMERA, BOARD, rvec, tvec, dtype=np.float32)
    assert tilted.amplitude[v, u] == pytest.approx(0.6 * np.cos(0.5), rel=1e-6)


def test_low_dynamic_range():
    f = sim.render(CAMERA, BOARD, *frontal(0.6), gain=0.02)
    assert f.amplitude.max() < 0.1 * 65535
    assert f.amplitude.max() > 0


def region_pixels(camera, rvec, tvec, board, dark):
    """Pixels whose centre lies on a square of one colour, well inside it."""
    _, _, b = analytic(camera, rvec, tvec)
    white = board.is_white(b[:, 0], b[:, 1], margin=0.25)
    black = board.is_white(b[:, 0] + board.square, b[:, 1], margin=0.25)  # shifted parity
    inside = ((b[:, 0] > -board.square) & (b[:, 0] < board.cols * board.square)
              & (b[:, 1] > -board.square) & (b[:, 1] < board.rows * board.square))
    return (black & inside) if dark else (white & inside)


def test_depth_noise_is_larger_on_black_squares():
    rvec, tvec = frontal(0.8)
    f = sim.render(CAMERA, BOARD, rvec, tvec, noise=sim.Noise(depth=0.003), rng=1)
    r = (f.depth - f.depth_true).ravel()
    s_black = r[region_pixels(CAMERA, rvec, tvec, BOARD, True)].std()
    s_white = r[region_pixels(CAMERA, rvec, tvec, BOARD, False)].std()
    # sqrt(0.9 / 0.1) = 3 times noisier; 1 m at 0.8 m makes white 0.8 x the reference.
    assert s_black / s_white == pytest.approx(3.0, rel=0.15)
    assert s_white == pytest.approx(0.003 * 0.8, rel=0.15)


def test_constant_depth_noise():
    f = sim.render(CAMERA, BOARD, *TILTED, noise=sim.Noise(depth_const=0.01), rng=2)
    r = f.depth - f.depth_true
    assert np.std(r) == pytest.approx(0.01, rel=0.1)
    assert abs(np.mean(r)) < 0.001


def test_offset_and_wiggling():
    f = sim.render(CAMERA, BOARD, *TILTED, noise=sim.Noise(offset=0.025), convention="radial")
    assert np.allclose(f.depth - f.depth_true, 0.025, atol=1e-6)
    noisy = sim.render(CAMERA, BOARD, *TILTED, noise=sim.Noise(offset=0.025, depth_const=0.005))
    assert np.mean(noisy.depth - noisy.depth_true) == pytest.approx(0.025, abs=0.001)
    # the wiggle follows the radial distance (the light's path), carried into a z-depth
    w = sim.Noise(wiggle_amplitude=0.005, wiggle_period=0.5, wiggle_phase=0.3)
    radial = sim.render(CAMERA, BOARD, *TILTED, noise=w, convention="radial")
    assert np.allclose(radial.depth - radial.depth_true, 0.005 * np.sin(2 * np.pi * radial.depth_true / 0.5 + 0.3),
                       atol=1e-6)
    g = sim.render(CAMERA, BOARD, *TILTED, noise=w)
    assert np.allclose(g.depth / g.depth_true, radial.depth / radial.depth_true, equal_nan=True)


@pytest.mark.parametrize("invalid", [np.nan, 0.0])
def test_invalid_fraction(invalid):
    f = sim.render(CAMERA, BOARD, *TILTED, noise=sim.Noise(invalid_fraction=0.2), rng=3,
                   invalid=invalid)
    bad = np.isnan(f.depth) if np.isnan(invalid) else f.depth == 0
    assert bad.mean() == pytest.approx(0.2, abs=0.01)
    if invalid == 0:
        assert not np.any(np.isnan(f.depth))


def test_no_background_and_flying_pixels():
    rvec, tvec = TILTED
    f = sim.render(CAMERA, BOARD, rvec, tvec, background=None)
    off = f.coverage == 0
    assert np.all(np.isnan(f.depth[off])) and np.all(f.amplitude[off] == 0)
    fly = sim.render(CAMERA, BOARD, rvec, tvec, flying_pixels=True)
    edge = (fly.coverage > 0) & (fly.coverage < 1)
    _, s, _ = analytic(CAMERA, rvec, tvec)
    s = s.reshape(CAMERA.height, CAMERA.width)
    # Straddling pixels read between the board plane and the 3 m wall; the rest are exact.
    assert edge.sum() > 100
    assert np.all((fly.depth_true[edge] > s[edge]) & (fly.depth_true[edge] < 3.0))
    assert np.allclose(fly.depth_true[edge],
                       fly.coverage[edge] * s[edge] + (1 - fly.coverage[edge]) * 3.0)
    sharp = sim.render(CAMERA, BOARD, rvec, tvec, flying_pixels=False)
    assert np.all(np.isclose(sharp.depth_true, s) | (sharp.depth_true == 3.0))


def test_deterministic():
    noise = sim.Noise(depth=0.003, amplitude=0.01, invalid_fraction=0.1)
    a = sim.render(CAMERA, BOARD, *TILTED, noise=noise, rng=7)
    b = sim.render(CAMERA, BOARD, *TILTED, noise=noise, rng=np.random.default_rng(7))
    c = sim.render(CAMERA, BOARD, *TILTED, noise=noise, rng=8)
    assert np.array_equal(a.depth, b.depth, equal_nan=True)
    assert np.array_equal(a.amplitude, b.amplitude)
    assert not np.array_equal(a.depth, c.depth, equal_nan=True)
    p1 = sim.random_poses(CAMERA, BOARD, 3, 5)
    p2 = sim.random_poses(CAMERA, BOARD, 3, 5)
    assert all(np.array_equal(x[0], y[0]) and np.array_equal(x[1], y[1]) for x, y in zip(p1, p2))


def test_random_poses_in_view_and_tilt_bounded():
    board = Board(7, 5, 0.03)
    poses = sim.random_poses(CAMERA, board, 30, np.random.default_rng(0), distance=(0.5, 1.2),
                             max_tilt_deg=35.0, margin_px=4.0)
    assert len(poses) == 30
    tilts = []
    for rvec, tvec in poses:
        X, _ = cam.transform(rvec, tvec, board.object_points())
        pix = cam.project(X, CAMERA.params).pixels
        assert np.all(pix >= 4.0) and np.all(pix <= np.array(CAMERA.size) - 1 - 4.0)
        R, _ = cv2.Rodrigues(rvec)
        tilts.append(np.degrees(np.arccos(abs(R[2, 2]))))
        centre = R @ np.array([3 * 0.03, 2 * 0.03, 0]) + tvec
        assert 0.5 <= centre[2] <= 1.2
    assert max(tilts) <= 35.0 + 1e-9
    assert max(tilts) > 15.0  # tilts are actually drawn, not all frontal
    with pytest.raises(CalibrationError):
        sim.random_poses(CAMERA, Board(20, 15, 0.1), 1, 0, distance=(0.3, 0.4), max_tries=50)


def to_8bit(amplitude):
    lo, hi = np.percentile(amplitude, [1, 99])
    return np.clip((amplitude.astype(float) - lo) / (hi - lo) * 255, 0, 255).astype(np.uint8)


def test_opencv_finds_the_rendered_board():
    board = Board(7, 5, 0.035)
    rvec, tvec = frontal(0.65, board=board, tilt=(0.25, 0.3), roll_deg=6.0)
    f = sim.render(CAMERA, board, rvec, tvec, supersample=8,
                   noise=sim.Noise(amplitude=0.002), rng=4)
    ok, found = cv2.findChessboardCornersSB(to_8bit(f.amplitude), board.pattern_size,
                                            flags=cv2.CALIB_CB_ACCURACY)
    assert ok
    found = found.reshape(-1, 2)
    err = min(np.abs(found - f.corners).max(), np.abs(found[::-1] - f.corners).max())
    assert err < 0.3


def test_large_image_is_fast():
    camera = sim.azure_kinect_camera()
    board = Board(7, 5, 0.05)
    pose = sim.random_poses(camera, board, 1, 0)[0]
    sim._centre_normalized.cache_clear()
    t0 = time.perf_counter()
    f = sim.render(camera, board, *pose, noise=sim.Noise(depth=0.002, amplitude=0.001))
    assert time.perf_counter() - t0 < 1.0
    assert f.amplitude.shape == (576, 640) and f.depth.dtype == np.float32


def test_a_strong_real_lens_renders_exact_rays_and_a_folding_one_is_refused():
    # the Azure Kinect depth camera's lens (its rational model, fitted by plumb_bob): 90 px of
    # barrel at the image's corners
    strong = sim.SimCamera(np.array([504.0, 504.0, 321.5, 329.0, -0.3225, 0.1234, 1.2e-4, 6e-6, -0.0243]), 640, 576)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        xy = sim._centre_normalized(strong.params.tobytes(), strong.width, strong.height).reshape(-1, 2)
    back = cam.project(np.column_stack([xy, np.ones(len(xy))]), strong.params).pixels
    U, V = np.meshgrid(np.arange(strong.width), np.arange(strong.height))
    assert np.abs(back - np.stack([U.ravel(), V.ravel()], 1)).max() < 1e-6
    # fitted over too short a radius, it folds back in the top-left corner: no ray reaches those
    # pixels, and they were rendered 1e14 px off
    folding = sim.SimCamera(np.array([504.0, 504.0, 321.5, 329.0, -0.3297, 0.1407, 1.2e-4, 6e-6, -0.0339]), 640, 576)
    with pytest.raises(CalibrationError, match="folds back inside the 640x576 image: no ray reaches the pixels 45"):
        sim.render(folding, BOARD, *sim.random_poses(strong, BOARD, 1, 0)[0])


def test_bad_input():
    with pytest.raises(CalibrationError):
        sim.render(CAMERA, BOARD, *TILTED, convention="euclid")
    with pytest.raises(CalibrationError):
        sim.Noise(invalid_fraction=1.5)
    with pytest.raises(CalibrationError):
        sim.SimCamera(np.ones(4), 10, 10)
