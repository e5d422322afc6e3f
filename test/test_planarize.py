"""Depth planarization against the renderer's exact depth."""
import numpy as np
import pytest

from tof_calib_ros import Board, CalibrationError, sim
from tof_calib_ros.core import camera as cam
from tof_calib_ros.core import depth_bias
from tof_calib_ros.core.planarize import (
    SQUARE_MARGIN,
    board_samples,
    border_reach,
    corner_depth,
    corner_depth_along,
    fit_plane_to,
    fit_samples,
    noise_spread,
    off_plane,
    on_surface,
    planar_part,
    planarize,
    ransac_inliers,
    sample_depth,
    smoothed,
    square_pixels,
    squares_moved,
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


def test_square_colours_and_the_outline_of_the_squared_area():
    board = Board(3, 3, 0.05)   # 4x4 squares from (-0.05, -0.05) to (0.15, 0.15); the top-left is dark
    x, y = np.meshgrid(np.linspace(-0.1, 0.2, 298), np.linspace(-0.1, 0.2, 248))  # no point on an edge
    x, y = x.ravel(), y.ravel()
    area = board.in_squared_area(x, y)
    np.testing.assert_array_equal(area, (x >= -0.05) & (x <= 0.15) & (y >= -0.05) & (y <= 0.15))
    white, black = board.is_white(x, y), board.is_black(x, y)
    assert not (white & black).any() and ((white | black) == area).mean() > 0.99   # only edges differ
    assert black[np.argmin(np.hypot(x + 0.025, y + 0.025))] and white[np.argmin(np.hypot(x - 0.025, y + 0.025))]
    inner = board.in_squared_area(x, y, margin=0.2)
    np.testing.assert_array_equal(inner, (x >= -0.04) & (x <= 0.14) & (y >= -0.04) & (y <= 0.14))


def test_how_far_another_lens_moves_the_squares_the_samples_see():
    """The samples are chosen through one lens; a lens that fits the corners as well moves no
    square (K's scale and centre are absorbed by the board's homography), a barrel the first lens
    lacks moves the squares near the image's edge beyond the samples' margin, and little at the centre."""
    pinhole = np.array([200.0, 200.0, 100.0, 100.0] + [0.0] * 8)
    barrel = np.r_[pinhole[:4], -0.4, 0.15, np.zeros(6)]
    board = Board(6, 5, 0.03)
    ids = np.arange(board.n_corners)

    def corners(lens, centre):   # a fronto-parallel board at 0.6 m, its middle at ``centre`` (normalised)
        obj = board.object_points(ids) - [0.075, 0.06, 0.0]
        return cam.project(obj + [centre[0] * 0.6, centre[1] * 0.6, 0.6], lens).pixels

    middle, edge = corners(barrel, (0.0, 0.0)), corners(barrel, (0.35, 0.35))
    assert squares_moved(edge, ids, board, barrel, barrel, (200, 200)) < 1e-6
    shifted = np.r_[210.0, 205.0, 103.0, 98.0, np.zeros(8)]
    assert squares_moved(corners(pinhole, (0.3, 0.3)), ids, board, pinhole, shifted, (200, 200)) < 1e-6
    at_middle = squares_moved(middle, ids, board, pinhole, barrel, (200, 200))
    at_edge = squares_moved(edge, ids, board, pinhole, barrel, (200, 200))
    assert at_middle < SQUARE_MARGIN < at_edge, (at_middle, at_edge)


def test_white_squares_follow_the_amplitude_when_the_labelling_is_turned():
    board = Board(6, 5, 0.04)  # 7x6 squares: a 180 degree turn swaps the colours
    rng = np.random.default_rng(3)
    (r, t), = sim.random_poses(CAM, board, 1, rng, distance=(0.6, 0.7), max_tilt_deg=10)
    f = sim.render(CAM, board, r, t, rng=rng)
    ids = np.arange(board.n_corners)
    turned = f.corners[::-1]
    fooled, _ = square_pixels(f.depth.shape, turned, ids, board, CAM.params, 0.15, None)
    right, _ = square_pixels(f.depth.shape, turned, ids, board, CAM.params, 0.15, f.amplitude)
    amp = f.amplitude.astype(float)
    assert np.median(amp[fooled[:, 1], fooled[:, 0]]) < 0.3 * np.median(amp[right[:, 1], right[:, 0]])
    # The very white squares the right labelling gives: not a column of the margin in place of
    # the last column of squares (the same calibration however the board's corners are counted).
    truth, _ = square_pixels(f.depth.shape, f.corners, ids, board, CAM.params, 0.15, f.amplitude)
    same = set(map(tuple, truth)) & set(map(tuple, right))
    assert len(same) > 0.99 * max(len(truth), len(right)), (len(same), len(truth), len(right))
    # The whole board: its colour labels follow the amplitude the same way.
    every, black = square_pixels(f.depth.shape, turned, ids, board, CAM.params, 0.15, f.amplitude, "all")
    a = amp[every[:, 1], every[:, 0]]
    assert np.median(a[black]) < 0.3 * np.median(a[~black])
    assert 3 < len(every) / len(right) < 4.5   # both colours, and no margin between squares


def test_each_colour_counts_with_its_own_noise():
    # A plane seen along a grid of rays, black squares 4 times noisier than white: the fit must
    # weight them by the noise it finds, and state the covariance the errors then have.
    xs, ys = np.meshgrid(np.linspace(-0.3, 0.3, 60), np.linspace(-0.25, 0.25, 50))
    u = np.column_stack([xs.ravel(), ys.ravel(), np.ones(xs.size)])
    black = ((np.floor(xs.ravel() / 0.05) + np.floor(ys.ravel() / 0.05)) % 2 == 0)
    coef = np.array([0.1, -0.2, 1.0]) / 0.9
    sigma = np.where(black, 0.008, 0.002)
    rng = np.random.default_rng(5)
    J = u / (u @ coef)[:, None] ** 2
    ideal = np.linalg.inv((J / sigma[:, None] ** 2).T @ J)   # weighted least squares, the true noise
    chi2, pooled_err, fit_err = [], [], []
    for _ in range(200):
        depth = 1 / (u @ coef) + rng.normal(0, sigma)
        plane = fit_plane_to(u, depth, u[:, :2], black)
        e = plane.coef - coef
        chi2.append(e @ np.linalg.solve(plane.covariance, e))
        fit_err.append(e)
        pooled_err.append(fit_plane_to(u, depth, u[:, :2], np.zeros_like(black)).coef - coef)
        assert plane.sigma == pytest.approx(0.002, rel=0.1)
    np.testing.assert_allclose(np.diag(plane.covariance), np.diag(ideal), rtol=0.15)
    assert 2.5 < np.mean(chi2) < 3.5                     # 3 for an honest covariance
    # Equal weights would waste the white squares' precision.
    assert np.mean(np.square(fit_err)) < 0.5 * np.mean(np.square(pooled_err))


@pytest.mark.parametrize("convention", ["z", "radial"])
def test_the_whole_board_lowers_corner_depth_error_when_both_colours_read_alike(convention):
    frames = _frames(convention)
    ids = np.arange(BOARD.n_corners)
    err, predicted = {}, {}
    for squares in ("white", "all"):
        e, p = [], []
        for f in frames:
            samples = board_samples(f.depth, f.corners, ids, BOARD, CAM.params, f.amplitude, squares=squares)
            d, se = corner_depth(fit_samples(samples, CAM.params, convention), f.corners, CAM.params, convention)
            e.append(d - f.corner_depth)
            p.append(se)
        err[squares] = np.sqrt(np.mean(np.concatenate(e) ** 2))
        predicted[squares] = np.sqrt(np.mean(np.concatenate(p) ** 2))
    # More than twice the pixels: the error falls as the stated standard error does.
    assert predicted["all"] < predicted["white"] / np.sqrt(2)
    assert 0.6 < err["all"] / predicted["all"] < 1.6, (err, predicted)


@pytest.mark.parametrize("border", [0.0, 0.5, 1.0])
def test_the_boards_border_is_found_as_far_as_it_reaches(border):
    """Rings beyond the squares read the plane's depth and white as far as the board goes: the
    border found is the rendered one less at most a few rings, and a board without one has none
    (beyond it, the wall 3 m away)."""
    rng = np.random.default_rng(5)
    ids = np.arange(BOARD.n_corners)
    for r, t in sim.random_poses(CAM, BOARD, 4, rng, distance=(0.6, 0.9), max_tilt_deg=30):
        f = sim.render(CAM, BOARD, r, t, noise=sim.Noise(depth=0.005), rng=rng, border=border)
        plane = fit_samples(board_samples(f.depth, f.corners, ids, BOARD, CAM.params, f.amplitude), CAM.params, "z")
        reach = border_reach(f.depth, f.corners, ids, BOARD, CAM.params, plane, "z", f.amplitude)
        assert border - 0.3 <= reach <= border, (reach, border)


def test_the_boards_border_lowers_the_corner_depth_error():
    """Samples taken into a 1-square border reach twice as far from the board's middle: the
    plane's tilt, and so the depth at the outer corners, is known better than from the squares
    alone, and the error stays what the plane's standard error says."""
    err, predicted = {}, {}
    for border in (0.0, 0.85):
        e, p = [], []
        for f in _frames("z", noise=0.01, seed=6):
            ids = np.arange(BOARD.n_corners)
            samples = board_samples(f.depth, f.corners, ids, BOARD, CAM.params, f.amplitude, border=border)
            d, se = corner_depth(fit_samples(samples, CAM.params, "z"), f.corners, CAM.params, "z")
            e.append(d - f.corner_depth)
            p.append(se)
        err[border] = np.sqrt(np.mean(np.concatenate(e) ** 2))
        predicted[border] = np.sqrt(np.mean(np.concatenate(p) ** 2))
    assert predicted[0.85] < 0.8 * predicted[0.0], predicted
    assert err[0.85] < err[0.0], err
    assert 0.6 < err[0.85] / predicted[0.85] < 1.6, (err, predicted)


def test_flying_pixels_and_invalid_depth_do_not_bias_the_plane():
    rng = np.random.default_rng(4)
    (r, t), = sim.random_poses(CAM, BOARD, 1, rng, distance=(0.7, 0.8), max_tilt_deg=35)
    f = sim.render(CAM, BOARD, r, t, noise=sim.Noise(depth_const=0.005, invalid_fraction=0.2), rng=rng,
                   flying_pixels=True, background=1.5)
    d, _ = planarize(f.depth, f.corners, np.arange(BOARD.n_corners), BOARD, CAM.params, "z", f.amplitude)
    assert np.sqrt(np.mean((d - f.corner_depth) ** 2)) < 0.001


def test_a_bowed_boards_rim_keeps_its_noise_on_both_sides():
    """A board that bows 8 mm towards its rim (a ToF wiggle's curvature), its black squares three
    times as noisy as the white: cut about the plane, the black squares' rim loses the tail of its
    noise on one side (it reads 0.39 mm near, 6 standard errors); cut about a smooth surface, both
    sides stay (0.9 and 1.3 standard errors). Spikes go either way."""
    rng = np.random.default_rng(3)
    n = 40000
    x, y = rng.uniform(-0.3, 0.3, n), rng.uniform(-0.3, 0.3, n)
    u = np.column_stack([x, y, np.ones(n)])
    rim = x ** 2 + y ** 2 > 0.06
    black = (np.floor(x / 0.06) + np.floor(y / 0.06)) % 2 == 1
    noise = rng.normal(0, 1, n) * np.where(black, 0.006, 0.002)
    depth = 1 / (u @ [0.05, -0.02, 0.8]) + 0.008 * (x ** 2 + y ** 2) / 0.18 + noise
    depth[:30] += rng.choice([-0.3, 0.4], 30)   # spikes and flying pixels
    for kept, biased in ((on_surface(u, depth, np.ones(n, dtype=bool)), False),
                         (ransac_inliers(u * depth[:, None], np.random.default_rng(0)), True)):
        assert not kept[:30].any()
        assert np.mean(kept[30:][~black[30:]]) > 0.99   # the white squares' noise is within the cut
        for colour in (black, ~black):
            at = kept & colour & rim
            at[:30] = False
            z = noise[at].mean() / (noise[colour & rim].std() / np.sqrt(at.sum()))
            assert abs(z) > 4 if biased and colour is black else abs(z) < 3, (z, biased)


@pytest.mark.parametrize("bad", [0.0, np.nan])
def test_all_invalid_depth_is_a_clear_error(bad):
    f = _frames("z", n=1)[0]
    depth = np.full_like(f.depth, bad)
    with pytest.raises(CalibrationError, match="valid depth pixels"):
        planarize(depth, f.corners, np.arange(BOARD.n_corners), BOARD, CAM.params, "z")


def test_the_depth_off_its_plane_measures_a_curved_term_without_bias():
    """A wiggle's curvature across near-frontal boards, about a millimetre against 10 mm noise a
    pixel: what the depth off their planes says of the wiggle's two terms (one combination a
    view, the distances telling them apart) is centred on the truth and spreads over noise draws
    as its information says (measured: 1.6 % off the truth, spread 0.95-0.99 of the stated). With
    the basis at each sample's noisy depth it was biased 10 times the wiggle; at the plane's, 5 %."""
    rng = np.random.default_rng(3)
    xs, ys = np.meshgrid(np.linspace(-0.3, 0.3, 60), np.linspace(-0.3, 0.3, 60))
    u = np.column_stack([xs.ravel(), ys.ravel(), np.ones(xs.size)])
    pixels = np.column_stack(np.unravel_index(np.arange(xs.size), xs.shape)[::-1])
    period, w = depth_bias.wiggle_period(20e6), np.array([0.012, -0.009])
    black = np.zeros(len(u), dtype=bool)
    estimates, stds = [], []
    for _ in range(200):
        info, moment = np.zeros((2, 2)), np.zeros(2)
        for distance in (0.9, 1.15, 1.4):
            true = 1.0 / (u @ np.array([0.04, -0.03, 1 / distance]))   # tilted 2-3 degrees
            reads = true + depth_bias.wiggle_basis(period, true, true * np.linalg.norm(u, axis=1)) @ w
            depth = reads + rng.normal(0, 0.01, len(u))
            plane = fit_plane_to(u, depth, pixels, black)
            # the basis at the depth without its noise, the wiggle taken out as the pipeline does
            at = depth_bias.true_depth(np.r_[0, 0, 0, 0, w, 0], smoothed(plane, u, depth), u, period)
            basis = depth_bias.wiggle_basis(period, at, at * np.linalg.norm(u, axis=1))
            i, m = off_plane(plane, u, depth, black, basis)
            info, moment = info + i, moment + m
        estimates.append(np.linalg.solve(info, moment))
        stds.append(np.sqrt(np.diag(np.linalg.inv(info))))
    estimates, std = np.array(estimates), np.mean(stds, axis=0)
    assert np.all(std < 0.005), std                                  # three views pin the wiggle to a few mm
    assert np.all(np.abs(estimates.mean(0) - w) < 3 * std / np.sqrt(len(estimates)) + 3e-4), (estimates.mean(0), w)
    assert np.all(np.abs(estimates.std(0) / std - 1) < 0.15), (estimates.std(0), std)


@pytest.mark.parametrize("with_black", [False, True])
def test_the_planar_part_of_a_term_is_where_a_refitted_plane_moves(with_black):
    """``planar_part`` (one solve of the fit's normal equations) against refitting the plane to
    the depth with a millimetre of each term added (black squares, when sampled, with their own
    noise): the corners' depth moves as the refit moves it, to a thousandth of the term (measured:
    1e-4, the refit's own millimetre step being finite)."""
    rng = np.random.default_rng(5)
    xs, ys = np.meshgrid(np.linspace(-0.3, 0.3, 50), np.linspace(-0.25, 0.25, 40))
    u = np.column_stack([xs.ravel(), ys.ravel(), np.ones(xs.size)])
    pixels = np.column_stack(np.unravel_index(np.arange(xs.size), xs.shape)[::-1])
    black = (rng.random(len(u)) < 0.4) if with_black else np.zeros(len(u), dtype=bool)
    true = 1.0 / (u @ np.array([0.3, -0.2, 1 / 0.8]))          # tilted 15-20 degrees, 0.8 m away
    depth = true + rng.normal(0, 0.004, len(u)) * np.where(black, 3.0, 1.0)
    period = depth_bias.wiggle_period(30e6)
    basis = np.column_stack([depth_bias.wiggle_basis(period, true, true * np.linalg.norm(u, axis=1)),
                             (u[:, 0] ** 2 + u[:, 1] ** 2)])   # a wiggle's two terms and a bowl
    corners = u[rng.choice(len(u), 12, replace=False)]
    plane = fit_plane_to(u, depth, pixels, black)
    at, _ = corner_depth_along(plane, corners)
    step = 1e-3
    refit = np.column_stack([(corner_depth_along(fit_plane_to(u, depth + step * basis[:, k], pixels, black),
                                                 corners)[0] - at) / step for k in range(basis.shape[1])])
    got = planar_part(plane, u, depth, black, basis, corners)
    assert np.abs(refit).max() > 0.1                  # a plane keeps much of each term
    assert np.abs(got - refit).max() < 1e-3 * np.abs(refit).max(), np.abs(got - refit).max()


def test_noise_a_smoothing_filter_shared_between_pixels_counts_as_fewer_samples():
    """A driver's smoothing filter makes neighbouring pixels' noise alike: a smooth fit to a board's
    squares is then worth fewer samples (a 3 x 3 box filter: 9 times fewer; 2 x 2: 4)."""
    from scipy.ndimage import uniform_filter
    rng = np.random.default_rng(0)
    ys, xs = np.mgrid[0:120, 0:120]
    squares = ((xs // 10 + ys // 10) % 2 == 0) & (xs % 10 > 1) & (xs % 10 < 9) & (ys % 10 > 1) & (ys % 10 < 9)
    pixels = np.column_stack([xs[squares], ys[squares]])
    for size, truth in ((1, 1.0), (2, 4.0), (3, 9.0)):
        spread = [noise_spread(pixels, uniform_filter(rng.normal(0, 1, xs.shape), size)[squares]) for _ in range(5)]
        assert abs(np.median(spread) / truth - 1) < 0.2, (size, spread)
