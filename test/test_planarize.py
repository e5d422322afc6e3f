"""Depth planarization against the renderer's exact depth."""
import numpy as np
import pytest

from tof_calib_ros import Board, CalibrationError, sim
from tof_calib_ros.core.planarize import (
    board_samples,
    corner_depth,
    fit_samples,
    planarize,
    sample_depth,
    white_square_pixels,
)

BOARD = Board(8, 6, 0.04)
CAM = sim.pmd_camera()


def _frames(convention, n=8, noise=0.01, seed=0):
    rng = np.random.default_rng(seed)
    poses = sim.random_poses(CAM, BOARD, n, rng, distance=(0.6, 0.9), max_tilt_deg=30)
    return [sim.render(CAM, BOARD, r, t, convention=convention, noise=sim.Noise(depth_const=noise), rng=rng)
            for r, t in poses]


@pytest.mark.parametrize("convention", ["z", "radial"])
def test_planarization_lowers_corner_depth_error_as_pixel_count_predicts(convention):
    raw_err, flat_err, predicted_se, n_pixels = [], [], [], []
    for f in _frames(convention):
        ids = np.arange(BOARD.n_corners)
        samples = board_samples(f.depth, f.corners, ids, BOARD, CAM.params, f.amplitude)
        plane = fit_samples(samples, CAM.params, convention)
        d, se = corner_depth(plane, f.corners, CAM.params, convention)
        raw_err.append(sample_depth(f.depth, f.corners, radius=0) - f.corner_depth)
        flat_err.append(d - f.corner_depth)
        predicted_se.append(se)
        n_pixels.append(len(plane.pixels))
    raw = np.sqrt(np.nanmean(np.concatenate(raw_err) ** 2))
    flat = np.sqrt(np.mean(np.concatenate(flat_err) ** 2))
    predicted = np.sqrt(np.mean(np.concatenate(predicted_se) ** 2))
    # The plane averages N white-square pixels: the error falls to about sigma * sqrt(k / N).
    assert 0.008 < raw < 0.012
    assert flat < raw / np.sqrt(np.median(n_pixels) / 10)
    assert 0.6 < flat / predicted < 1.6, (flat, predicted)


def test_noiseless_planarization_is_exact():
    f = _frames("radial", n=1, noise=0.0)[0]
    d, plane = planarize(f.depth.astype(np.float64), f.corners, np.arange(BOARD.n_corners), BOARD, CAM.params,
                         "radial")
    np.testing.assert_allclose(d, f.corner_depth, atol=2e-6)  # float32 depth image
    assert plane.sigma < 1e-6


def test_white_squares_follow_the_amplitude_when_the_labelling_is_turned():
    board = Board(6, 5, 0.04)  # 7x6 squares: a 180 degree turn swaps the colours
    rng = np.random.default_rng(3)
    (r, t), = sim.random_poses(CAM, board, 1, rng, distance=(0.6, 0.7), max_tilt_deg=10)
    f = sim.render(CAM, board, r, t, rng=rng)
    ids = np.arange(board.n_corners)
    turned = f.corners[::-1]
    fooled = white_square_pixels(f.depth.shape, turned, ids, board, CAM.params, 0.15, None)
    right = white_square_pixels(f.depth.shape, turned, ids, board, CAM.params, 0.15, f.amplitude)
    amp = f.amplitude.astype(float)
    assert np.median(amp[fooled[:, 1], fooled[:, 0]]) < 0.3 * np.median(amp[right[:, 1], right[:, 0]])


def test_flying_pixels_and_invalid_depth_do_not_bias_the_plane():
    rng = np.random.default_rng(4)
    (r, t), = sim.random_poses(CAM, BOARD, 1, rng, distance=(0.7, 0.8), max_tilt_deg=35)
    f = sim.render(CAM, BOARD, r, t, noise=sim.Noise(depth_const=0.005, invalid_fraction=0.2), rng=rng,
                   flying_pixels=True, background=1.5)
    d, _ = planarize(f.depth, f.corners, np.arange(BOARD.n_corners), BOARD, CAM.params, "z", f.amplitude)
    assert np.sqrt(np.mean((d - f.corner_depth) ** 2)) < 0.001


@pytest.mark.parametrize("bad", [0.0, np.nan])
def test_all_invalid_depth_is_a_clear_error(bad):
    f = _frames("z", n=1)[0]
    depth = np.full_like(f.depth, bad)
    with pytest.raises(CalibrationError, match="valid depth pixels"):
        planarize(depth, f.corners, np.arange(BOARD.n_corners), BOARD, CAM.params, "z")
