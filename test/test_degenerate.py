"""Degenerate view sets and numerical faults, rendered with known truth.

Whatever the views, ``calibrate`` either raises a CalibrationError whose message names the
problem, or returns finite K and D (nothing NaN can reach a CameraInfo) with an honest verdict:
``ok`` only for a calibration that is close to the truth.
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from tof_calib_ros import Board, CalibrationError, View, calibrate, sim
from tof_calib_ros.core import bundle
from tof_calib_ros.core import camera as cam
from tof_calib_ros.core.result import CalibrationResult

BOARD = Board(8, 6, 0.04)
CAM = sim.pmd_camera()
NOISE = sim.Noise(depth=0.003, amplitude=0.002)
METHODS = ["depth", "traditional"]
CENTRE = np.array([(BOARD.cols - 1) / 2, (BOARD.rows - 1) / 2, 0.0]) * BOARD.square
# Close to the truth: every pixel's ray within this many pixels of the true one. The verdict
# allows a focal length std of 1 % and a principal point std of 2 % of the image (4 px here).
CLOSE_PX = 4.0


def _pose(tilt_deg: float, axis_deg: float = 0.0, z: float = 0.7, px=(100, 100)):
    """The board centre on pixel ``px`` at depth ``z``, tilted about an in-plane axis."""
    phi = np.radians(axis_deg)
    R, _ = cv2.Rodrigues(np.array([np.cos(phi), np.sin(phi), 0.0]) * np.radians(tilt_deg))
    t = cam.rays(np.array([px], float), CAM.params)[0] * z - R @ CENTRE
    return cv2.Rodrigues(R)[0].ravel(), t


def _frames(poses, noise=NOISE, seed=0) -> list[sim.Frame]:
    rng = np.random.default_rng(seed)
    return [sim.render(CAM, BOARD, r, t, noise=noise, rng=rng) for r, t in poses]


TILTED = [_pose(30, a, z, px) for a, z, px in [(0, 0.6, (100, 100)), (90, 0.7, (95, 100)),
                                                (200, 0.8, (100, 105)), (300, 0.65, (105, 95))]]
FRONTAL = [_pose(0, 0, z, px) for z, px in [(0.55, (90, 95)), (0.7, (110, 100)), (0.85, (100, 110)),
                                             (0.65, (95, 105))]]


@pytest.fixture(scope="module")
def tilted() -> list[sim.Frame]:
    return _frames(TILTED)


def _ray_error_px(result: CalibrationResult) -> float:
    """Largest distance, over a grid of the image, between where the calibration and the truth
    project the same ray: what using the calibration would get wrong."""
    xs, ys = np.meshgrid(np.linspace(0, CAM.width - 1, 9), np.linspace(0, CAM.height - 1, 9))
    pixels = np.column_stack([xs.ravel(), ys.ravel()])
    rays = cam.rays(pixels, CAM.params)
    params = cam.pack_intrinsics(result.K, result.D)
    return float(np.abs(cam.project(rays, params).pixels - pixels).max())


def _calibrate(views: list[View], method: str, **kwargs) -> CalibrationResult | CalibrationError:
    """The result or the refusal, after checking what must hold of any result."""
    try:
        result = calibrate(views, BOARD, method=method, **kwargs)
    except CalibrationError as exc:
        assert str(exc) and "\n" not in str(exc)
        return exc
    assert np.all(np.isfinite(result.K)) and np.all(np.isfinite(result.D))
    assert np.all(np.isfinite(result.depth_bias))
    if result.ok:   # a verdict that says ok on a calibration far from the truth lies
        assert _ray_error_px(result) < CLOSE_PX, (result.K, result.D, result.std)
    return result


def _refused(outcome, match: str) -> None:
    assert isinstance(outcome, CalibrationError), f"calibrated, verdict {getattr(outcome, 'verdict', None)}"
    assert match in str(outcome), str(outcome)


def _refused_or_flagged(outcome, error: str, verdict: str) -> None:
    """Refused with ``error`` in the message, or not ok with ``verdict`` among the reasons."""
    if isinstance(outcome, CalibrationError):
        assert error in str(outcome), str(outcome)
    else:
        assert not outcome.ok and verdict in " ".join(outcome.verdict), outcome.verdict


def _good(outcome) -> None:
    assert isinstance(outcome, CalibrationResult), str(outcome)
    assert outcome.ok, outcome.verdict   # so also close to the truth


# ---------------------------------------------------------------------------------------------
# view geometry

def _refused_flagged_or_close(outcome, method: str) -> None:
    """OpenCV must refuse or flag frontal views. The depth method may also calibrate them: each
    plane's tilt holds the principal point, and with the distortion the data call for (not the
    decentering terms that trade with it) it comes out within a fraction of a pixel; a trusted
    result was checked close to the truth by _calibrate."""
    if method == "depth" and isinstance(outcome, CalibrationResult) and outcome.ok:
        return
    _refused_or_flagged(outcome, "same orientation", "poorly constrained")


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("noise", [None, NOISE], ids=["exact", "noisy"])
def test_fronto_parallel_views_at_several_distances(method, noise):
    # Zhang: the principal point trades against the boards' positions: no tilt, no principal
    # point (OpenCV also loses the focal length: 4x the truth, which its verdict said was fine).
    frames = _frames(FRONTAL, noise)
    outcome = _calibrate([View(f.depth, f.corners) for f in frames], method)
    _refused_flagged_or_close(outcome, method)


@pytest.mark.parametrize("method", METHODS)
def test_fronto_parallel_views_with_detected_corners(method):
    # Detected corners: the fit found cx 78 px off, and said std 0.07 px before the fix.
    frames = _frames(FRONTAL)
    outcome = _calibrate([View(f.depth, amplitude=f.amplitude) for f in frames], method)
    _refused_flagged_or_close(outcome, method)


@pytest.mark.parametrize("method", METHODS)
def test_fronto_parallel_views_at_one_distance(method):
    frames = _frames([_pose(0, 0, 0.7, px) for px in [(90, 95), (110, 100), (100, 110), (95, 105)]])
    outcome = _calibrate([View(f.depth, f.corners) for f in frames], method)
    _refused_or_flagged(outcome, "same orientation", "poorly constrained")


@pytest.mark.parametrize("method", METHODS)
def test_tilted_views_all_at_one_distance_calibrate(method):
    frames = _frames([_pose(30, a, 0.7, px) for a, px in [(0, (100, 100)), (90, (95, 100)), (200, (100, 105)),
                                                           (300, (105, 95))]])
    _good(_calibrate([View(f.depth, f.corners) for f in frames], method))


@pytest.mark.parametrize("method", METHODS)
def test_boards_seen_edge_on_are_not_found(method):
    frames = _frames([_pose(t, a) for t, a in [(85, 0), (87, 90), (89, 45)]])
    _refused(_calibrate([View(f.depth, amplitude=f.amplitude) for f in frames], method),
             "no board found in any of the 3 views")


@pytest.mark.parametrize("method", METHODS)
def test_corners_of_a_board_seen_edge_on_are_rejected(method, tilted):
    frames = _frames([_pose(89.8, a) for a in (0, 90)])
    outcome = _calibrate([View(f.depth, f.corners) for f in frames] + [View(f.depth, f.corners) for f in tilted[:1]],
                         method)
    _refused(outcome, "view 0: its corners lie on one line in the image")
    assert "view 1: its corners lie on one line in the image" in str(outcome)


@pytest.mark.parametrize("method", METHODS)
def test_edge_on_views_among_good_ones_are_left_out(method, tilted):
    edge = _frames([_pose(87, 0), _pose(88, 90)])
    outcome = _calibrate([View(f.depth, amplitude=f.amplitude) for f in tilted + edge], method)
    _good(outcome)
    assert sorted(outcome.rejected) == [4, 5] and all("no board found" in r for r in outcome.rejected.values())


@pytest.mark.parametrize("method", METHODS)
def test_a_single_view_repeated(method, tilted):
    view = View(tilted[0].depth, tilted[0].corners)
    _refused_or_flagged(_calibrate([view] * 5, method), "same orientation" if method == "depth" else "OpenCV",
                        "poorly constrained")
    _refused(_calibrate([view], method), "too few usable views: 1 of 1, need at least 3")
    _refused(_calibrate([view], method, min_views=1), "min_views must be a whole number of at least 2")


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("ids", [np.arange(BOARD.cols), np.arange(0, BOARD.n_corners, BOARD.cols),
                                 np.arange(0, BOARD.n_corners, BOARD.cols + 1)[:BOARD.rows]],
                         ids=["row", "column", "diagonal"])
def test_corners_on_one_line_of_the_board(method, ids, tilted):
    outcome = _calibrate([View(f.depth, f.corners[ids], ids) for f in tilted], method)
    _refused(outcome, "too few usable views: 0 of 4")
    assert str(outcome).count("its corners lie on one line of the board") == 4


@pytest.mark.parametrize("method", METHODS)
def test_a_view_with_corners_on_a_line_is_left_out(method, tilted):
    row = np.arange(BOARD.cols)
    views = [View(f.depth, f.corners) for f in tilted[:3]] + [View(tilted[3].depth, tilted[3].corners[row], row)]
    outcome = _calibrate(views, method)
    _good(outcome)
    assert "one line of the board" in outcome.rejected[3]


@pytest.mark.parametrize("method", METHODS)
def test_corners_outside_the_image(method, tilted):
    outcome = _calibrate([View(f.depth, f.corners * 50) for f in tilted], method)
    _refused(outcome, "corners lie outside the 200x200 image")


# ---------------------------------------------------------------------------------------------
# depth

@pytest.mark.parametrize("value", [0.7, 45.0, 1e-30])
def test_constant_depth_contradicts_the_corners(value, tilted):
    views = [View(np.full_like(f.depth, value), f.corners) for f in tilted]
    _refused(_calibrate(views, "depth"), "the depth images do not show the board")
    _good(_calibrate(views, "traditional"))   # which never reads the depth


@pytest.mark.slow
def test_constant_radial_depth_is_flagged(tilted):
    views = [View(np.full_like(f.depth, 0.7), f.corners) for f in tilted]
    _refused_or_flagged(_calibrate(views, "depth", depth_convention="radial"),
                        "the depth images do not show the board", "depth RMS")


@pytest.mark.parametrize("invalid", [
    lambda d: np.zeros_like(d), lambda d: np.full_like(d, np.nan), lambda d: np.full_like(d, np.inf),
    lambda d: np.full_like(d, -0.7), lambda d: np.zeros(d.shape, np.uint16), lambda d: np.full_like(d, 1e30)],
    ids=["zero", "nan", "inf", "negative", "uint16-zero", "beyond-any-range"])
def test_all_depth_invalid(invalid, tilted):
    views = [View(invalid(f.depth), f.corners) for f in tilted]
    _refused(_calibrate(views, "depth"), "no valid depth at any corner of any view")
    _good(_calibrate(views, "traditional"))


def test_depth_on_the_board_in_one_view_only(tilted):
    """One view's squares cannot size K: their size is (distance + offset) / focal length. With
    the depth invalid in all views but one, the sizing once ran off (fx 80 times the truth,
    refused for its depth RMS) or failed on a pose, each with a reason that blamed the corners."""
    views = [View(f.depth if k == 0 else np.zeros_like(f.depth), f.corners) for k, f in enumerate(tilted)]
    _refused(_calibrate(views, "depth"), "the depth shows the board in 1 of 4 views")
    _good(_calibrate(views, "traditional"))
    two = [View(f.depth if k < 2 else np.zeros_like(f.depth), f.corners) for k, f in enumerate(tilted)]
    _good(_calibrate(two, "depth"))


# ---------------------------------------------------------------------------------------------
# corners that make the optimiser diverge

def _shuffled(frames):
    rng = np.random.default_rng(5)
    return [View(f.depth, rng.permutation(f.corners)) for f in frames]


def _swapped(frames):
    return [View(f.depth, g.corners) for f, g in zip(frames, frames[1:] + frames[:1])]


def _noisy(frames):
    rng = np.random.default_rng(6)
    return [View(f.depth, np.clip(f.corners + rng.normal(0, 20, f.corners.shape), 0, 199)) for f in frames]


@pytest.mark.slow
@pytest.mark.parametrize("corrupt", [_shuffled, _swapped, _noisy], ids=["shuffled", "swapped", "noise-20px"])
def test_corrupt_corners_fail_or_are_flagged(corrupt, tilted):
    outcome = _calibrate(corrupt(tilted), "depth")
    if isinstance(outcome, CalibrationError) and "the depth shows the board in" in str(outcome):
        # shuffled corners put the squares' depth samples off the board: refused for that in one CI
        # run (ci77) of the same code another run (ci76) refused for the disagreement
        assert corrupt is _shuffled, str(outcome)
    else:
        _refused_or_flagged(outcome, "the corners and the depth disagree", "RMS")   # pixel or depth residuals


@pytest.mark.parametrize("corrupt", [_shuffled, _noisy], ids=["shuffled", "noise-20px"])
def test_corrupt_corners_fail_or_are_flagged_traditionally(corrupt, tilted):
    _refused_or_flagged(_calibrate(corrupt(tilted), "traditional"), "OpenCV calibration diverged", "pixel RMS")


def test_corners_swapped_between_views_are_still_corners(tilted):
    # Without the depth, another view's corners are a view like any other: a good calibration.
    _good(_calibrate(_swapped(tilted), "traditional"))


def test_an_unconstrained_combination_has_infinite_variance_not_none():
    # Parameters 0 and 1 act identically (their difference is unconstrained); parameter 2, in
    # other units (x1000), is constrained. A pseudo-inverse gave 0 and 1 a small finite variance.
    J = np.array([[1.0, 1.0, 0.0], [2.0, 2.0, 1000.0], [0.0, 0.0, 3000.0]])
    normal = bundle._Normal(J.T @ J, np.zeros((0, 3, 6)), np.zeros((0, 6, 6)), np.zeros(3), np.zeros((0, 6)))
    cov = bundle.global_covariance(normal)
    assert np.isinf(cov[0, 0]) and np.isinf(cov[1, 1])
    reduced = J[:, 1:]   # parameter 0 folded into 1: what the views do constrain
    assert cov[2, 2] == pytest.approx(np.linalg.inv(reduced.T @ reduced)[1, 1], rel=1e-9)
