"""The real Kinect v2 views: a few-view depth-aided calibration against an independent reference.

The reference is OpenCV on all the views, where Zhang's method is well conditioned; the
depth offset is checked against the 25.5 mm the data set's own calibration found.
"""
import cv2
import numpy as np
import pytest

from tof_calib_ros import Board, View, calibrate
from tof_calib_ros.core.detection import detect_corners

BOARD = Board(5, 7, 0.03)


@pytest.fixture(scope="module")
def views(kinect_dir):
    out = []
    for ir_path in sorted(kinect_dir.glob("*_ir.png")):
        ir = cv2.imread(str(ir_path), cv2.IMREAD_UNCHANGED)
        depth = cv2.imread(str(ir_path).replace("_ir.png", "_depth.png"), cv2.IMREAD_UNCHANGED)
        corners = detect_corners(ir, BOARD)
        if corners is not None:
            out.append(View(depth, corners, amplitude=ir))
    assert len(out) >= 45
    return out


@pytest.fixture(scope="module")
def even(views):
    """The even views' calibration on the defaults, against which both held-out tests measure."""
    return calibrate(views[0::2], BOARD)


def test_few_views_agree_with_the_all_view_reference(views):
    reference = calibrate(views, BOARD, method="traditional")
    ours_err, trad_err = [], []
    for start in range(5):  # five disjoint sets of 5-6 views
        subset = views[start::9]
        ours = calibrate(subset, BOARD)  # 16-bit millimetre depth, as the driver gives it
        trad = calibrate(subset, BOARD, method="traditional")
        ours_err.append(np.mean(np.abs(np.diag(ours.K)[:2] / np.diag(reference.K)[:2] - 1)))
        trad_err.append(np.mean(np.abs(np.diag(trad.K)[:2] / np.diag(reference.K)[:2] - 1)))
        assert 0.005 < ours.depth_offset < 0.035
        assert ours.pixel_rms < 0.3 and ours.depth_rms < 0.01
    assert np.median(ours_err) < 0.01
    assert np.median(ours_err) < 0.5 * np.median(trad_err)


def test_few_views_state_uncertainties_the_other_half_of_the_views_bears_out(views, even):
    """Held out: sets of 5 odd views against the even views' calibration, which shares none of
    them. A real view's depth has errors of its own (its bow, its wiggle at its distance) that
    do not average out over a few views; the covariance, built on errors independent between
    corners, does not see them, the jackknife over the views does. Every trusted result lies
    within 2 of the stated sigmas of the difference (measured: within 1.4; the covariance alone
    trusted 2 of the 8 sets 2.9 and 6.2 sigmas off)."""
    odd = views[1::2]
    for k in range(8):
        pick = np.random.default_rng(k).choice(len(odd), size=5, replace=False)
        res = calibrate([odd[i] for i in pick], BOARD)
        z = (res.K[0, 0] - even.K[0, 0]) / np.hypot(res.std["fx"], even.std["fx"])
        assert not res.ok or abs(z) < 2, (k, res.K[0, 0], res.std["fx"], even.K[0, 0], z)


def test_all_views_agree_with_opencv_and_their_halves_with_each_other(views, even):
    """The issue's real-data targets, on the product's defaults: the odd and the even views
    calibrate to focal lengths within 0.3 % of each other (OpenCV's halves are 2.4-2.6 % apart)
    and all views put the principal point within 3 px of OpenCV's all-view solution (measured:
    0.01 and 0.09 %; 0.1 and 2.1 px). A rule that let the corners' lens model outvote the depth
    put the halves 0.76 % apart and the principal point 4.7 px off."""
    reference = calibrate(views, BOARD, method="traditional")
    ours = calibrate(views, BOARD)
    assert np.all(np.abs(ours.K[:2, 2] - reference.K[:2, 2]) < 3), (ours.K[:2, 2], reference.K[:2, 2])
    odd = calibrate(views[1::2], BOARD)
    apart = np.diag(odd.K)[:2] / np.diag(even.K)[:2] - 1
    assert np.all(np.abs(apart) < 0.003), apart
