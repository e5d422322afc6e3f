"""The real Kinect v2 views: a few-view depth-aided calibration against an independent reference.

The reference is OpenCV on all the views, where Zhang's method is well conditioned (fx 370.45;
its odd and even views agree to 0.03 %); the depth offset is checked against the 25.5 mm the
data set's own calibration found. This data set's depth reads 2 % short of the distances the
corners and the 30 mm squares give (a depth scale, or squares of 29.4 mm: the views cannot
tell which). All the views see it and take a depth scale; so do both halves, whose focal
lengths agree within 0.32 % (fx; 0.20 % in fy, 2026-11-28). A few views do not see
it, and their focal length rests on the depth's scale; the all-view principal point is 3.3 px
from OpenCV's with k3 fixed (1.9 px from OpenCV's with k3 free, the lens ours chooses): the
issue's targets for these are not met (the xfail tests below, which fail the run if they start
to pass).
"""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from tof_calib_ros import Board, calibrate
from tof_calib_ros.core import depth_bias
from tof_calib_ros.core.camera import fold_distance
from tof_calib_ros.core.coverage import reach
from tof_calib_ros.core.projection_diff import projection_difference

BOARD = Board(5, 7, 0.03)
LOW_SCALE = 0.4
pytestmark = pytest.mark.slow   # real-data calibrations over all 51 views and their halves


@pytest.fixture(scope="module")
def kinect_real():
    """``benchmarks/kinect_real.py``, whose loader (and downsampling) the tests share."""
    path = Path(__file__).parents[1] / "benchmarks" / "kinect_real.py"
    spec = importlib.util.spec_from_file_location("kinect_real", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def views(kinect_dir, kinect_real):
    out = kinect_real.load(kinect_dir, 1.0)
    assert len(out) >= 45
    return out


@pytest.fixture(scope="module")
def even(views):
    """The even views' calibration on the defaults, against which both held-out tests measure."""
    return calibrate(views[0::2], BOARD)


@pytest.fixture(scope="module")
def odd(views):
    """The odd views' calibration on the defaults."""
    return calibrate(views[1::2], BOARD)


@pytest.fixture(scope="module")
def reference(views):
    return calibrate(views, BOARD, method="traditional")


@pytest.fixture(scope="module")
def ours_all(views):
    """All the views on the defaults."""
    return calibrate(views, BOARD)


@pytest.fixture(scope="module")
def few(views):
    """Five disjoint sets of 5-6 views, each by ours and by OpenCV."""
    return [(calibrate(views[start::9], BOARD), calibrate(views[start::9], BOARD, method="traditional"))
            for start in range(5)]


@pytest.fixture(scope="module")
def low_views(kinect_dir, kinect_real):
    """The views at 0.4 scale (a PMD-class 205x170), downsampled as the benchmark does it."""
    return kinect_real.load(kinect_dir, LOW_SCALE)


def _focal_error(result, reference) -> float:
    return float(np.mean(np.abs(np.diag(result.K)[:2] / np.diag(reference.K)[:2] - 1)))


def _offset_on_the_axis(result) -> float:
    """The depth's offset on the optical axis: the z offset and the radial offset, which are one
    there and which a few views' bows share between them."""
    return float(result.depth_bias[0] + result.depth_bias[depth_bias.TERMS["radial"][0]])


def test_few_views_fit_their_corners_and_depth(few):
    for ours, _ in few:   # 16-bit millimetre depth, as the driver gives it
        assert 0.005 < _offset_on_the_axis(ours) < 0.035, (ours.depth_bias, ours.model.depth_bias)
        assert ours.pixel_rms < 0.3 and ours.depth_rms < 0.01


@pytest.mark.xfail(strict=True, reason="a few views cannot see the depth's 2 % scale and rest fx on it (kinect_real: "
                                       "median 0.95-2.3 % from the reference, OpenCV 0.96-2.35 %)")
def test_few_views_agree_with_the_all_view_reference_better_than_opencv(few, reference):
    ours_err = [_focal_error(ours, reference) for ours, _ in few]
    trad_err = [_focal_error(trad, reference) for _, trad in few]
    assert np.median(ours_err) < 0.01
    assert np.median(ours_err) < 0.5 * np.median(trad_err)


def test_few_views_state_uncertainties_the_other_half_of_the_views_bears_out(views, even):
    """Held out: sets of 5 odd views against the even views' calibration, which shares none of
    them. A real view's depth has errors of its own (its bow, its wiggle at its distance) that
    do not average out over a few views; the covariance, built on errors independent between
    corners, does not see them, the jackknife over the views does. Every trusted result lies
    within 2 of the stated sigmas of the difference (the covariance alone trusted 2 of the 8 sets
    2.9 and 6.2 sigmas off). Measured: none of the 8 is trusted (fx's sigma 3.0-25 px, 0.0-2.3
    sigmas from the even views' 372.4 +- 1.9): 5 views cannot see the depth's 2 % scale."""
    odd = views[1::2]
    for k in range(8):
        pick = np.random.default_rng(k).choice(len(odd), size=5, replace=False)
        res = calibrate([odd[i] for i in pick], BOARD)
        z = (res.K[0, 0] - even.K[0, 0]) / np.hypot(res.std["fx"], even.std["fx"])
        # trusted or not, the stated sigmas bear the difference out (and a trusted one within 2)
        assert abs(z) < 3 and (not res.ok or abs(z) < 2), (k, res.K[0, 0], res.std["fx"], even.K[0, 0], z)


@pytest.mark.parametrize("draw", [0, 14, 16])
def test_seven_views_that_leave_the_image_s_edge_out_predict_the_views_left_out(views, kinect_real, draw):
    """Seven random views (``kinect_real.py``'s draws) reach at most 135-163 px from the centre;
    the views left out reach 251 px. With k3 the data's choice let the lens fold back 210-230 px
    out, inside the image: it fit the seven to 0.08 px and put the views left out 0.73, 1.08 and
    24.7 px off (the last trusted). Without that k3, 0.105, 0.062 and 0.090 px (OpenCV with k3
    fixed: 0.101, 0.179, 0.102)."""
    pick = np.random.default_rng(7000 + draw).choice(len(views), size=7, replace=False)
    rest = [v for i, v in enumerate(views) if i not in set(pick)]
    res = calibrate([views[i] for i in pick], BOARD)
    assert kinect_real.heldout_rms(res, rest) < 0.15, (res.D, res.model.reasons)
    folds = fold_distance(np.r_[np.diag(res.K)[:2], res.K[:2, 2], res.D], (512, 424))
    assert res.model.distortion != "full" or folds is None, (res.D, folds)


def test_all_views_take_the_depth_scale_the_corners_see_and_agree_with_opencv(ours_all, reference):
    """On its defaults, all the views: the depth reads 1.9 % short of the corners' distances, a
    depth scale is taken, and fx and fy come out within 0.3 % of OpenCV's (measured 0.12 and
    0.23 %; without the scale the depth put them 1.8 % lower, and with the corners found less
    accurately, before the detector's second look, OpenCV's halves were 2.6 % apart and agreed
    with that)."""
    reasons = ours_all.model.reasons
    assert "scale" in ours_all.model.depth_bias, reasons
    assert any("the depth reads -" in r for r in reasons), reasons
    # the stated fx (+- 2.12, the fit alone +- 0.75, 2026-11-29) is the spread over runs of the
    # views, and the result says so
    assert any("runs of views taken one after another" in r and f"fx spreads ±{ours_all.std['fx']:.2f} px" in r
               for r in reasons), reasons
    apart = np.diag(ours_all.K)[:2] / np.diag(reference.K)[:2] - 1
    assert np.all(np.abs(apart) < 0.003), apart


def test_the_odd_half_takes_a_scale_from_its_bows_and_is_not_trusted_off_the_even_views(views, odd):
    """The odd views' level (-0.8 +- 0.5 %) is under the depth check's 2 sigmas, but their depth
    bows off its planes by amounts that differ between views (from -934 to +52 mm): a depth error
    over distance, whose slope is a scale. Resting on the depth's scale the odd half was trusted
    at 363.2 +- 0.9 px, 1.5 % and 3.8 sigmas of the difference below OpenCV on the even views,
    which share none of its views (368.8 +- 1.2); with the scale, 371.3 +- 4.5 (0.7 % above),
    refused as poorly constrained."""
    reference = calibrate(views[0::2], BOARD, method="traditional")
    assert "scale" in odd.model.depth_bias, odd.model.reasons
    assert any("between the views" in r and "a depth scale term" in r for r in odd.model.reasons), odd.model.reasons
    assert abs(odd.K[0, 0] / reference.K[0, 0] - 1) < 0.01, (odd.K[0, 0], reference.K[0, 0])
    z = (odd.K[0, 0] - reference.K[0, 0]) / np.hypot(odd.std["fx"], reference.std["fx"])
    assert abs(z) < 2, (odd.K[0, 0], odd.std["fx"], reference.K[0, 0], z, odd.ok)   # trusted or not


def test_the_kinect_depth_is_read_as_z_depth(ours_all, odd, even):
    """The Kinect v2 gives z-depth: its boards are flat read so, whatever else its depth errs by."""
    for result in (ours_all, odd, even):
        assert result.depth_convention == "z"
        assert any(r.startswith("depth convention z: the boards are flat read as z-depth")
                   for r in result.model.reasons), result.model.reasons


def test_the_halves_agree_within_their_uncertainty(odd, even):
    """Measured 0.32 and 0.20 % apart (2026-11-28), 0.6 sigmas of the difference; the even half
    took k3 = -0.88, which folds its lens back 237 px from the centre, and was 0.14 and 0.03 %
    from the odd; without it, 370.16 px, 0.01 % from OpenCV on all the views. The odd half is
    refused as poorly constrained (+- 5.0 px)."""
    apart = np.diag(odd.K)[:2] - np.diag(even.K)[:2]
    sigma = np.hypot([odd.std["fx"], odd.std["fy"]], [even.std["fx"], even.std["fy"]])
    assert np.all(np.abs(apart / np.diag(even.K)[:2]) < 0.005) and np.all(np.abs(apart) < 2 * sigma), (apart, sigma)


@pytest.mark.xfail(strict=True, reason="measured 0.32 and 0.20 % apart (the issue's 0.3 %)")
def test_the_halves_agree_within_0_3_percent(odd, even):
    apart = np.diag(odd.K)[:2] / np.diag(even.K)[:2] - 1
    assert np.all(np.abs(apart) < 0.003), apart


@pytest.fixture(scope="module")
def recording_halves(views):
    """The first and the second half of the views in the recording's order, each on the defaults."""
    n = len(views)
    return calibrate(views[:n // 2], BOARD), calibrate(views[n // 2:], BOARD)


def test_a_depth_error_beyond_the_periods_looked_for_yields_to_the_corners(views, reference):
    """Views 8-23 of the recording: the wiggle's search gains 185 against a price of 21 at the
    longest period it looks at (4.7 m, 8 MHz), an error over distance that no wiggle looked for
    explains. Left to the depth, fx came out 360.4 +- 0.72 px, trusted 10 px (13 stated sigmas)
    from OpenCV's all-view fx, where the corners alone said 374.7 +- 2.2. Such an error is one the
    model does not explain: the depth yields until it leaves fx no less certain than the corners
    alone, and the uncertainty takes in the scale it may hide (2026-12-06)."""
    res = calibrate(views[8:24], BOARD)
    assert any("end of the periods looked for" in r for r in res.model.reasons), res.model.reasons
    assert res.model.depth_inflation > 1, res.model.reasons
    for k, name in ((0, "fx"), (1, "fy")):
        apart = res.K[k, k] - reference.K[k, k]
        assert abs(apart) <= 2 * np.hypot(res.std[name], reference.std[name]), (name, apart, res.std[name])


def test_the_recording_s_halves_are_not_both_trusted_beyond_their_uncertainty(recording_halves):
    """Split in the recording's order, the halves cover other parts of the image (x 166-500 px
    against 170-388): OpenCV's cx 7.8 sigmas apart, both trusted. With every-5th-view folds ours'
    were 6.1 sigmas apart, both trusted; over runs of consecutive views 3.8, the second half
    refused as poorly constrained (2026-11-29). Two trusted results this far apart would be one
    trusted and wrong."""
    first, second = recording_halves
    keys = ("fx", "fy", "cx", "cy")
    apart = np.array([second.K[0, 0] - first.K[0, 0], second.K[1, 1] - first.K[1, 1], second.K[0, 2] - first.K[0, 2],
                      second.K[1, 2] - first.K[1, 2]])
    z = apart / np.hypot([first.std[k] for k in keys], [second.std[k] for k in keys])
    assert not (first.ok and second.ok) or np.all(np.abs(z) < 3), (z, first.ok, second.ok)
    assert np.all(np.abs(z) < 5), z


def test_where_no_view_reached_the_result_says_so_and_the_halves_bear_it_out(views, ours_all, recording_halves):
    """No view reaches the image's left third or its corners. The result's note gives the
    projection's spread over the runs of views there (18.8 px at worst, 0.72 px in the median
    where the views reached); the recording's halves, calibrated apart, differ by up to 49.5 px
    there and by 1.88 px in the median where the views reached (2026-11-29). Their difference
    has about twice the whole's spread (each half has twice its variance): measured 1.30 and
    1.32 times that, so the spread is of the right size."""
    size = ours_all.image_size
    corners = np.concatenate([views[v.index].corners for v in ours_all.views])
    spread = reach(np.r_[np.diag(ours_all.K)[:2], ours_all.K[:2, 2], ours_all.D], ours_all.run_intrinsics, corners,
                   size)
    assert spread.beyond.max() > 10 * np.median(spread.known)
    assert ours_all.extrapolated == (spread.cells, spread.beyond.max(), np.median(spread.known))
    assert ours_all.extrapolated.note() in ours_all.notes
    assert f"known to {spread.beyond.max():.1f} px only" in ours_all.summary(len(views), 1.0)
    first, second = (np.r_[np.diag(r.K)[:2], r.K[:2, 2], r.D] for r in recording_halves)
    halves = projection_difference(first, second, size, corners).diff
    ratios = (np.median(halves[spread.inside]) / (2 * np.median(spread.known)),
              np.nanmax(halves[~spread.inside]) / (2 * spread.beyond.max()))
    assert all(1 / 3 < r < 3 for r in ratios), ratios


@pytest.mark.xfail(strict=True, reason="measured 3.3 and 2.7 px from OpenCV's principal point")
def test_all_views_put_the_principal_point_within_3_px_of_opencvs(ours_all, reference):
    assert np.all(np.abs(ours_all.K[:2, 2] - reference.K[:2, 2]) < 3), (ours_all.K[:2, 2], reference.K[:2, 2])


def test_the_principal_point_is_within_3_px_of_opencvs_with_the_lens_model_ours_chose(views, ours_all):
    """OpenCV's principal point moves with the lens model it fits: k3 fixed (ROS's default, the
    reference above) 252.7, 201.8; k3 free (OpenCV's own default) 254.1, 200.7. Its halves' cx
    are 3.7 and 5.2 px apart with each, beyond their stated sigmas. Ours chooses k3; beside
    OpenCV with the same terms it is 1.9 and 1.6 px off (2026-11-27), within 3 sigmas of the
    difference; the xfail above compares across lens models."""
    same = calibrate(views, BOARD, method="traditional", distortion=ours_all.model.distortion)
    apart = ours_all.K[:2, 2] - same.K[:2, 2]
    sigma = np.hypot([ours_all.std["cx"], ours_all.std["cy"]], [same.std["cx"], same.std["cy"]])
    assert np.all(np.abs(apart) < 3) and np.all(np.abs(apart) < 3 * sigma), (apart, sigma)


@pytest.fixture(scope="module")
def low(low_views):
    """All the 205x170 views, the even ones and the odd ones, on the defaults."""
    return {name: calibrate(low_views[which], BOARD)
            for name, which in (("all", slice(None)), ("even", slice(0, None, 2)), ("odd", slice(1, None, 2)))}


@pytest.mark.parametrize("which", ["all", "even", "odd"])
def test_at_205x170_the_focal_length_is_within_2_sigmas_of_the_full_resolution_one(low, reference, which):
    """Downsampled by 0.4 (a PMD-class 205x170, as ``kinect_real.py`` does it), the views bow
    alike and their depth reads 1.4 % short of the corners, too little for the depth check to
    take a scale: at its full weight the depth put fx 1.7 % below the full-resolution reference,
    and what its model leaves open (the scale) made fx 145.6 +- 2.7 px, refused, where the
    corners alone said 148.3 +- 1.2 (their spread over folds of the views). The depth now yields
    until the uncertainty stated is no larger than the corners' (at 16 times its noise): all
    three were trusted, measured 147.73 +- 0.85, 148.01 +- 0.86 and 147.70 +- 0.63 (all, even,
    odd; the reference, scaled, 148.04). The even half's pixels weighted alike move fx 1.47 px,
    which their noise does not explain: its uncertainty includes the move, +- 1.65, and it was
    refused as poorly constrained; without the k3 that folded its lens inside the image, 147.57
    +- 1.44, trusted (2026-11-28). All the views are trusted; a half, trusted or refused for its
    uncertainty alone."""
    res = low[which]
    truth = np.diag(reference.K)[:2] * LOW_SCALE   # the principal point aside, focal lengths scale plainly
    z = (np.diag(res.K)[:2] - truth) / np.array([res.std["fx"], res.std["fy"]])
    assert np.all(np.abs(z) < 2), (np.diag(res.K)[:2], res.std, truth, z, res.model.reasons)
    assert res.ok or (which != "all" and all("poorly constrained" in r for r in res.verdict)), res.verdict


@pytest.mark.parametrize("which", ["odd at full resolution", "all at 205x170"])
def test_told_one_of_the_camera_s_frequencies_a_trusted_focal_length_is_within_2_sigmas(views, low_views, reference,
                                                                                        which):
    """Told 80 MHz, one of the three frequencies the Kinect v2 unwraps, as a user may in good faith:
    the wiggle modelled at its period leaves the depth's error over distance unexplained (F = 43
    at 205x170) and its level, -1.5 % off the corners, too uncertain for a scale term. Without
    the scale in fx's uncertainty, the odd views were trusted 364.44 +- 1.79 px, 3.2 sigmas below
    the reference (370.11), and all the views at 205x170 145.64 +- 0.50, 4.8 sigmas below it,
    scaled (148.04). With it, the odd views are refused as poorly constrained (364.50 +- 5.64)
    and the depth at 205x170 yields to the corners: 146.91 +- 1.15, trusted (2026-11-28)."""
    odd = which.startswith("odd")
    res = calibrate(views[1::2] if odd else low_views, BOARD, modulation_hz=80e6)
    truth = np.diag(reference.K)[:2] * (1.0 if odd else LOW_SCALE)
    z = (np.diag(res.K)[:2] - truth) / np.array([res.std["fx"], res.std["fy"]])
    # within 2 sigmas, trusted or not (measured -1.0 both, 2026-11-28)
    assert np.all(np.abs(z) < 2), (np.diag(res.K)[:2], res.std, truth, z, res.ok, res.model.reasons)


def test_at_205x170_the_halves_agree_closer_than_opencvs(low, low_views):
    """The odd and the even views at 205x170: measured 0.09 % apart in fx and 0.15 % in fy
    (2026-11-28), within the issue's 0.3 %; OpenCV's halves are 0.88 and 0.72 % apart. They were
    0.21 and 0.43 % apart while the even half took k3 = -0.97, which folds its lens back 94 px
    from the centre, where the image's corners are 137 px out (1.59 and 1.50 % before the depth
    yielded to what its model leaves open)."""
    apart = np.abs(np.diag(low["odd"].K)[:2] / np.diag(low["even"].K)[:2] - 1)
    halves = (slice(0, None, 2), slice(1, None, 2))
    trad_even, trad_odd = (calibrate(low_views[which], BOARD, method="traditional") for which in halves)
    trad_apart = np.abs(np.diag(trad_odd.K)[:2] / np.diag(trad_even.K)[:2] - 1)
    assert np.all(apart < 0.003) and np.all(apart < trad_apart), (apart, trad_apart)
