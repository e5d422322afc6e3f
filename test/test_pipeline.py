"""The whole depth-aided calibration against the renderer's ground truth, and its refusals."""
import re

import cv2
import numpy as np
import pytest

from tof_calib_ros import Board, CalibrationError, View, calibrate, sim
from tof_calib_ros.core import bundle
from tof_calib_ros.core.result import NOT_CONVERGED
from tof_calib_ros.core.traditional import calibrate_opencv

BOARD = Board(8, 6, 0.04)
CAM = sim.pmd_camera()


def _scene(n, seed, convention="z", noise=None, tilt=35.0, exact=False, distance=(0.55, 0.9), border=sim.BORDER):
    rng = np.random.default_rng(seed)
    poses = sim.random_poses(CAM, BOARD, n, rng, distance=distance, max_tilt_deg=tilt)
    frames = [sim.render(CAM, BOARD, r, t, convention=convention, noise=noise, rng=rng, border=border)
              for r, t in poses]
    views = [View(f.depth_true if exact else f.depth, f.corners) for f in frames]
    return views, frames


@pytest.mark.parametrize("convention", ["z", "radial"])
def test_noiseless_views_recover_the_truth(convention):
    views, frames = _scene(6, 1, convention, noise=sim.Noise(offset=0.025), exact=True)
    for v, f in zip(views, frames):
        v.depth = f.depth_true + 0.025
    res = calibrate(views, BOARD, depth_convention=convention, distortion="plumb_bob")
    truth = CAM.params
    got = np.r_[res.K[0, 0], res.K[1, 1], res.K[0, 2], res.K[1, 2]]
    np.testing.assert_allclose(got, truth[:4], rtol=1e-6)
    np.testing.assert_allclose(res.D[:4], truth[4:8], atol=1e-6)
    assert res.depth_offset == pytest.approx(0.025, abs=1e-7)
    assert len(res.views) == len(frames)
    for v in res.views:
        np.testing.assert_allclose(v.tvec, frames[v.index].tvec, atol=1e-7)
    assert res.ok, res.verdict


def test_the_same_views_give_the_same_calibration_to_the_last_bit():
    """OpenCV's parallel loops add up in the order their threads finish: with them free, these
    views gave fx a few 1e-9 px apart run to run (and, where a model choice was close, another
    model). A calibration is a function of its views, and the caller's thread count comes back."""
    cam = sim.SimCamera(np.array([284.4, 284.4, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0]), 200, 200)
    rng = np.random.default_rng(1)
    poses = sim.random_poses(cam, BOARD, 5, rng, distance=(0.55, 0.9), max_tilt_deg=35)
    noise = sim.Noise(depth=0.004, offset=0.02, wiggle_amplitude=0.015, wiggle_period=1.87)
    frames = [sim.render(cam, BOARD, r, t, noise=noise, rng=rng) for r, t in poses]
    views = [View(f.depth, f.corners + rng.normal(0, 0.05, f.corners.shape)) for f in frames]
    threads = cv2.getNumThreads()
    first, *again = [calibrate(views, BOARD) for _ in range(3)]
    for res in again:
        np.testing.assert_array_equal(np.r_[res.K.ravel(), res.D, res.depth_bias],
                                      np.r_[first.K.ravel(), first.D, first.depth_bias])
        assert res.std == first.std and res.verdict == first.verdict
    assert cv2.getNumThreads() == threads


def test_the_traditional_baseline_fits_the_lens_model_asked_for():
    """A lens with k3: asked for the full model, OpenCV's baseline recovers it from noiseless
    corners; by default it fixes k3 as ROS camera_calibration does, and says which it fitted."""
    cam = sim.SimCamera(np.array([284.4, 284.4, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0.2]), 200, 200)
    rng = np.random.default_rng(4)
    poses = sim.random_poses(cam, BOARD, 8, rng, distance=(0.55, 0.9), max_tilt_deg=35)
    views = [View(f.depth, f.corners) for f in (sim.render(cam, BOARD, r, t) for r, t in poses)]
    full = calibrate(views, BOARD, method="traditional", distortion="full")
    np.testing.assert_allclose(np.r_[np.diag(full.K)[:2], full.K[:2, 2], full.D], cam.params, atol=1e-4)
    assert full.model.distortion == "full"
    default = calibrate(views, BOARD, method="traditional")
    assert default.model.distortion == "plumb_bob" and default.D[4] == 0
    assert default.pixel_rms > 100 * full.pixel_rms   # k3 left out leaves its trace in the residuals
    radial = calibrate(views, BOARD, method="traditional", distortion="k1k2")
    assert radial.model.distortion == "k1k2" and np.all(radial.D[2:] == 0)


def test_four_corners_three_images_where_opencv_refuses(four_corner_views):
    views = four_corner_views
    with pytest.raises(CalibrationError, match="OpenCV"):
        calibrate_opencv([BOARD.object_points(v.ids) for v in views], [v.corners for v in views], (200, 200))
    res = calibrate(views, BOARD, depth_bias="none")
    assert res.K[0, 0] == pytest.approx(CAM.params[0], rel=0.005)
    assert any("OpenCV" in n for n in res.notes)


def test_noisy_tof_views_beat_traditional_calibration():
    """Five near-frontal views with noisy corners and depth, over four seeds: the median focal
    error is at most half OpenCV's on the same views, each within 3 of its stated sigmas. What the
    depth added (``depth_gain``) is said, and the errors bear it out to within a factor of 4."""
    ours_err, trad_err, gains = [], [], []
    for seed in (3, 4, 5, 6):
        views, _ = _scene(5, seed, noise=sim.Noise(depth=0.004, offset=0.02), tilt=10)
        rng = np.random.default_rng(seed)
        for v in views:
            v.corners = v.corners + rng.normal(0, 0.05, v.corners.shape)
        ours = calibrate(views, BOARD)
        trad = calibrate(views, BOARD, method="traditional")
        ours_err.append(abs(ours.K[0, 0] - CAM.params[0]))
        trad_err.append(abs(trad.K[0, 0] - CAM.params[0]))
        assert ours_err[-1] < 3 * ours.std["fx"] + 0.03, (seed, ours.K[0, 0], ours.std["fx"])   # honest sigma
        assert ours.depth_offset == pytest.approx(0.02, abs=0.003)
        gains.append(ours.depth_gain["fx"])
        assert f"the depth made fx {gains[-1]:.3g}" in ours.summary(5, 1.0)
        assert trad.depth_gain is None and "the depth made" not in trad.summary(5, 1.0)
    assert np.median(ours_err) < 0.5 * np.median(trad_err), (ours_err, trad_err)
    # near frontal the corners alone hardly fix fx: the depth makes it several times as certain
    assert min(gains) > 3, gains
    assert np.median(trad_err) / np.median(ours_err) > np.median(gains) / 4, (gains, ours_err, trad_err)


def test_a_joint_fit_that_does_not_converge_is_started_again_with_the_principal_point_held():
    """Three near-frontal views of 25 corners through a strong barrel lens (k1 -0.3, paper_table's
    tof+bias scene, seed 200046). The squares' sizes hardly fix the principal point there, and with
    the lens held at none the barrel moved it 122 px: the joint fit from there did not converge (fx
    648) and the calibration failed, blaming the depth. Started again with the principal point
    held, it converges, and the criterion keeps that fit."""
    board = Board(11, 11, 0.05)
    lens = np.array([284.4, 284.4, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0.0])
    camera = sim.SimCamera(lens, 200, 200)
    rng = np.random.default_rng(200046)
    poses = sim.random_poses(camera, board, 3, rng, distance=(0.9, 1.4), max_tilt_deg=5.0)
    sel = np.round(np.linspace(0, board.cols - 1, 5)).astype(int)
    ids = np.array([r * board.cols + c for r in sel for c in sel])
    noise = sim.Noise(depth=0.01, offset=0.025, dark_offset=0.015)
    views = []
    for r, t in poses:
        frame = sim.render(camera, board, r, t, noise=noise, rng=rng)
        views.append(View(frame.depth, frame.corners[ids] + rng.normal(0, 0.01, (len(ids), 2)), ids))
    res = calibrate(views, board)
    assert abs(res.K[0, 0] / 284.4 - 1) < 0.01
    assert abs(res.K[0, 0] - 284.4) < 3 * res.std["fx"]
    assert np.hypot(res.K[0, 2] - 99.5, res.K[1, 2] - 99.5) < 3
    assert any("started again with it held" in r and "kept the second" in r for r in res.model.reasons), \
        res.model.reasons


def test_the_whole_board_sharpens_a_sensor_that_reads_both_colours_alike():
    # The paper's synthetic sensor: 10 mm on every pixel, no bias. Near frontal, the principal
    # point rests on the planes' tilts and the focal length on their distances: both gain
    # from the black squares' pixels.
    views, _ = _scene(5, 7, noise=sim.Noise(depth_const=0.01), tilt=5, distance=(0.9, 1.2))
    rng = np.random.default_rng(7)
    for v in views:
        v.corners = v.corners + rng.normal(0, 0.02, v.corners.shape)
    white = calibrate(views, BOARD, depth_bias="none", plane_squares="white")
    every = calibrate(views, BOARD, depth_bias="none")   # plane_squares="auto" finds the colours alike
    assert (white.model.plane_squares, every.model.plane_squares) == ("white", "all"), every.model.reasons
    assert every.views[0].plane_pixels > 2 * white.views[0].plane_pixels   # the white border in both
    got = np.r_[every.K[0, 0], every.K[1, 1], every.K[0, 2], every.K[1, 2]]
    for k, name in enumerate(("fx", "fy", "cx", "cy")):
        assert every.std[name] < 0.95 * white.std[name], name
        assert abs(got[k] - CAM.params[k]) < 4 * every.std[name], name


def test_the_boards_white_border_is_sampled_as_far_as_it_reaches():
    """Near frontal, where the planes' tilts carry the principal point and their distances the
    focal length, the samples go into the board's white border (1 square, to a square's margin
    off its edge); a board without one is fitted on its squares alone, and states less."""
    results = {}
    for border, said in ((1.0, "white border reaches 0.9 squares"), (0.0, "shows no white border")):
        views, _ = _scene(4, 9, noise=sim.Noise(depth=0.002), tilt=5, distance=(0.8, 1.1), border=border)
        res = results[border] = calibrate(views, BOARD)
        assert any(said in r for r in res.model.reasons), res.model.reasons
        got = np.r_[res.K[0, 0], res.K[1, 1], res.K[0, 2], res.K[1, 2]]
        for k, name in enumerate(("fx", "fy", "cx", "cy")):
            assert abs(got[k] - CAM.params[k]) < 3 * res.std[name], (border, name)
    assert results[1.0].views[0].plane_pixels > 1.25 * results[0.0].views[0].plane_pixels
    assert results[1.0].std["fx"] < 0.9 * results[0.0].std["fx"]


@pytest.mark.parametrize("dark_offset", [0.004, 0.015])
def test_black_squares_read_farther_keep_the_planes_on_the_white(dark_offset):
    """plane_squares="auto" sees the black squares read apart (a Kinect v2 reads them 4 mm
    farther) and fits the planes to the white squares only; the result stays on the truth."""
    views, _ = _scene(6, 8, noise=sim.Noise(depth=0.003, dark_offset=dark_offset))
    res = calibrate(views, BOARD)
    assert res.model.plane_squares == "white", res.model.reasons
    measured = float(re.search(r"black squares read ([+-][\d.]+)", " ".join(res.model.reasons))[1])
    assert measured == pytest.approx(0.89 * dark_offset * 1e3, abs=1.0)   # (1 - 0.1 / 0.9) of it on black
    assert res.K[0, 0] == pytest.approx(CAM.params[0], abs=3 * res.std["fx"])
    assert res.ok, res.verdict


def test_end_to_end_from_rendered_amplitude_images():
    views, frames = _scene(6, 4, noise=sim.Noise(depth=0.003, amplitude=0.002))
    for v, f in zip(views, frames):
        v.corners, v.amplitude = None, f.amplitude
    res = calibrate(views, BOARD, distortion="plumb_bob")
    assert res.K[0, 0] == pytest.approx(CAM.params[0], rel=0.01)
    assert res.pixel_rms < 0.2
    assert len(res.views) == 6


def test_clear_errors_for_bad_input():
    views, frames = _scene(3, 5)
    blank = np.zeros((200, 200), np.uint16)
    with pytest.raises(CalibrationError, match="no board found in any of the 3 views"):
        calibrate([View(f.depth, amplitude=blank) for f in frames], BOARD)
    with pytest.raises(CalibrationError, match="too few usable views"):
        calibrate(views[:2], BOARD)
    with pytest.raises(CalibrationError, match="image size"):
        calibrate([views[0], View(np.zeros((100, 120), np.float32), views[1].corners), views[2]], BOARD)
    with pytest.raises(CalibrationError, match="valid depth|too few usable"):
        calibrate([View(np.full_like(v.depth, np.nan), v.corners) for v in views], BOARD)
    with pytest.raises(CalibrationError, match="convention"):
        calibrate(views, BOARD, depth_convention="disparity")
    with pytest.raises(CalibrationError, match="plane_squares must be one of 'auto', 'white', 'all'"):
        calibrate(views, BOARD, plane_squares="black")
    for cols in (1, 2):   # OpenCV's detectors raise on 2 a side
        with pytest.raises(CalibrationError, match="at least 3x3 interior corners"):
            Board(cols, 5, 0.03)


def test_parallel_views_are_refused():
    rng = np.random.default_rng(6)
    (r, t), = sim.random_poses(CAM, BOARD, 1, rng, distance=(0.6, 0.7), max_tilt_deg=20)
    frames = [sim.render(CAM, BOARD, r, t + np.array([dx, 0, dz]), rng=rng)
              for dx, dz in ((0, 0), (0.03, 0.1), (-0.03, 0.2))]
    with pytest.raises(CalibrationError, match="same orientation"):
        calibrate([View(f.depth, f.corners) for f in frames], BOARD)


def test_a_view_with_unusable_depth_counts_with_its_corners_only():
    views, _ = _scene(4, 7, noise=sim.Noise(depth=0.003))
    views[1].depth = np.zeros_like(views[1].depth)
    res = calibrate(views, BOARD, distortion="plumb_bob")
    assert len(res.views) == 4
    assert any(n.startswith("view 1:") and "corners only" in n for n in res.notes)
    assert np.all(np.isnan(res.views[1].depth_residuals))
    assert res.K[0, 0] == pytest.approx(CAM.params[0], rel=0.01)


@pytest.mark.slow
def test_robust_losses_resist_a_misdetected_corner():
    views, _ = _scene(5, 8, noise=sim.Noise(depth=0.003))
    rng = np.random.default_rng(8)
    for v in views:
        v.corners = v.corners + rng.normal(0, 0.05, v.corners.shape)
    clean = calibrate(views, BOARD, distortion="plumb_bob")
    views[2].corners[10] += (12.0, -9.0)  # one corner fifteen pixels off
    sigma = np.array([clean.noise_std["fx"], clean.noise_std["fy"]])   # the noise's, which the outlier defies
    pull = {loss: np.abs((np.diag(calibrate(views, BOARD, distortion="plumb_bob", loss=loss).K)[:2]
                          - np.diag(clean.K)[:2]) / sigma).max() for loss in (None, "huber", "cauchy")}
    assert pull[None] > 1.0  # plain least squares is dragged off by more than its own sigma
    for loss in ("huber", "cauchy"):
        assert pull[loss] < 0.5  # within half its own sigma of the clean calibration
    robust = calibrate(views, BOARD, distortion="plumb_bob", loss="cauchy")
    assert any("dropped outlier corners" in n and "2: [10]" in n for n in robust.notes)


def test_verdict_names_what_is_poorly_constrained():
    views, _ = _scene(4, 9, noise=sim.Noise(depth=0.003))
    res = calibrate(views, BOARD)
    assert res.ok
    res.std["cx"] = 50.0
    res.views[0].pixel_residuals = res.views[0].pixel_residuals + 5.0
    reasons = " ".join(res.verdict)
    assert "cx is poorly constrained" in reasons and "pixel RMS" in reasons
    assert not res.ok
    assert res.to_dict()["verdict"]["ok"] is False


def test_a_joint_fit_stopped_at_its_iteration_cap_is_not_trusted(monkeypatch):
    """The same views, their joint fits cut short at a few iterations and counted as having met
    the cap: the result says it did not converge and is refused for that, where the full fits are
    trusted and within 3 stated sigmas of the truth. OpenCV's baseline has no fit of ours to cap."""
    views, _ = _scene(4, 9, noise=sim.Noise(depth=0.003))
    settled = calibrate(views, BOARD)
    assert settled.ok and settled.converged, settled.verdict
    assert abs(settled.K[0, 0] - CAM.params[0]) < 3 * settled.std["fx"]
    real = bundle.levenberg_marquardt

    def cut_short(problem, state, max_iter=100, tol=1e-12):
        return real(problem, state, min(max_iter, 4), tol)[0], max_iter

    monkeypatch.setattr(bundle, "levenberg_marquardt", cut_short)
    stopped = calibrate(views, BOARD)
    assert not stopped.converged and NOT_CONVERGED in stopped.verdict and not stopped.ok
    assert stopped.to_dict()["converged"] is False
    assert calibrate(views, BOARD, method="traditional").converged


def test_a_focal_length_the_wiggles_period_leaves_open_asks_for_the_modulation_frequency():
    """Where the folds of the views, choosing the wiggle's period again, set fx's uncertainty, the
    verdict says what would settle it, and blames the period only where the folds chose other
    ones; where the views alone leave it open, it asks for views."""
    views, _ = _scene(4, 9, noise=sim.Noise(depth=0.003))
    res = calibrate(views, BOARD)
    assert res.ok and not res.model.period_spread
    assert "stated with the refits" not in res.gain_brief(), res.gain_brief()
    res.std["fx"] = 0.05 * res.K[0, 0]
    assert [r for r in res.verdict if r.startswith("fx")] == [
        f"fx is poorly constrained (std {res.std['fx']:.3g} px): add views at other distances and tilts"]
    assert f"stated with the refits, fx ±{res.std['fx']:.2f} px (the corners alone ±" in res.gain_brief(), \
        res.gain_brief()
    res.model.period_spread["fx"] = res.std["fx"]
    res.model.wiggle_period = 0.459
    res.model.fold_periods = [0.459, 0.364, 0.459, None, 0.459]   # the folds chose other periods
    (reason,) = [r for r in res.verdict if r.startswith("fx")]
    assert "modulation frequency" in reason and "--modulation-mhz" in reason and "modulation_hz" in reason
    assert "do not settle the wiggle's period" in reason and "folds chose other periods" in reason, reason
    assert res.to_dict()["model"]["period_spread"] == {"fx": res.std["fx"]}
    assert res.to_dict()["model"]["fold_periods"] == [0.459, 0.364, 0.459, None, 0.459]
    res.model.fold_periods = [0.459] * 5   # each chose the data's: the spread is the views', not the period's
    (reason,) = [r for r in res.verdict if r.startswith("fx")]
    assert "modulation frequency" in reason and "every fold choosing the period all of them chose" in reason, reason
    assert "do not settle" not in reason and reason.endswith("add views at other distances and tilts"), reason


@pytest.mark.slow
@pytest.mark.parametrize("square, depth_factor", [
    (0.08, 1.0),   # the square given twice its size
    (0.04, 2.0),   # depth read in units twice too large
    (0.02, 1.0),   # half its size
])
def test_a_wrong_square_size_or_depth_unit_is_not_trusted(square, depth_factor):
    """The corners alone fix the focal length whatever the square size; the depth scales with
    the square and the depth's unit. Either the depth-aided focal length moves away from the
    corners' or the depth model takes a scale far from 1: refused, saying what square size the
    depth implies."""
    views, _ = _scene(8, 11, noise=sim.Noise(depth=0.002))
    right = calibrate(views, BOARD)
    assert right.ok, right.verdict
    for v in views:
        v.depth = v.depth * depth_factor
    res = calibrate(views, Board(BOARD.cols, BOARD.rows, square))
    assert not res.ok
    reason = res.verdict[0]   # the cause leads, before the residuals and spreads it makes
    assert "the squares look" in reason, res.verdict
    # the depth's unit too large looks like a square as much larger
    implied = float(re.search(r"the depth says ([\d.]+) mm, not the", reason)[1])
    assert implied == pytest.approx(BOARD.square * 1e3 * depth_factor, rel=0.05), reason
    assert res.to_dict()["corner_only_focal"]["fx"] == pytest.approx(CAM.params[0], rel=0.01)


@pytest.mark.slow
@pytest.mark.parametrize("factor", [1.1, 1 / 1.2, 0.9])
def test_a_square_a_tenth_off_is_refused_saying_which_way(factor):
    """Not a fixed 25 %: the depth-aided and corner-only focal lengths are compared with the
    standard deviations of their difference (a square 18 % off was once trusted at 140 of them)."""
    views, _ = _scene(8, 11, noise=sim.Noise(depth=0.002))
    res = calibrate(views, Board(BOARD.cols, BOARD.rows, BOARD.square * factor))
    assert not res.ok, f"a square {factor - 1:+.0%} off was trusted: {res.K[0, 0]:.1f}"
    reason = res.verdict[0]
    assert "the squares look" in reason, res.verdict
    # a square given too small makes the depth read long: the squares look larger
    assert f"the squares look {'larger' if factor < 1 else 'smaller'} than the size given" in reason, reason
    implied = float(re.search(r"the depth says ([\d.]+) mm, not the", reason)[1])
    assert implied == pytest.approx(BOARD.square * 1e3, rel=0.02), reason


def test_views_whose_white_squares_clip_are_named_with_their_share():
    """The result says which views' white squares clip, by how much, and what it costs (the corners'
    accuracy: test_detection.py measures it), in its notes, its per-view figures and its file;
    a view exposed within the amplitude's range is neither named nor marked."""
    board = Board(5, 7, 0.03)
    camera = sim.SimCamera(np.array([212.0, 212.0, 111.3, 86.6, -0.25, 0.08, 0.0, 0.0, 0.0]), 224, 171)
    poses = sim.random_poses(camera, board, 4, rng=5, distance=(0.3, 0.5), max_tilt_deg=35)
    gains = [0.6, 0.05, 0.05, 0.05]   # the first view at 2.4-6.7 times full scale, the rest at 0.2-0.6 of it
    frames = [sim.render(camera, board, *p, noise=sim.Noise(amplitude=0.002), rng=k, gain=g)
              for k, (p, g) in enumerate(zip(poses, gains))]
    said: list[str] = []
    res = calibrate([View(f.depth, amplitude=f.amplitude) for f in frames], board, method="traditional",
                    progress=said.append)
    shares = [v.saturation for v in res.views]
    assert shares[0] >= 0.4 and max(shares[1:]) < 0.01, shares
    note = next(n for n in res.notes if "clip" in n)
    assert note.startswith("1 of 4 views' white squares clip (view 0: ") and "view 1" not in note, note
    assert "less accurately: lower the exposure" in note and note in said
    assert [v["saturation"] for v in res.to_dict()["views"]] == pytest.approx(shares)
    given = calibrate([View(f.depth, corners=f.corners) for f in frames], board, method="traditional")
    assert [v["saturation"] for v in given.to_dict()["views"]] == [None] * 4   # no amplitude: not known
