"""Where two calibrations project apart: against differences worked out by hand for a pinhole."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tof_calib_ros.core.camera import fold_distance
from tof_calib_ros.core.projection_diff import projection_difference

SIZE = (512, 424)
PINHOLE = np.array([370.0, 372.0, 256.0, 212.0, 0.0, 0.0, 0.0, 0.0, 0.0])
LENS = np.array([370.0, 372.0, 256.0, 212.0, 0.09, -0.25, 1e-3, -5e-4, 0.08])


def _grid(x0: float, x1: float, y0: float, y1: float, n: int = 12) -> np.ndarray:
    return np.stack(np.meshgrid(np.linspace(x0, x1, n), np.linspace(y0, y1, n)), axis=-1).reshape(-1, 2)


def _pixels(pd) -> np.ndarray:
    return np.stack(np.meshgrid(pd.xs, pd.ys), axis=-1)


def test_one_calibration_against_itself_differs_nowhere():
    pd = projection_difference(LENS, LENS, SIZE, _grid(100, 400, 80, 340))
    assert np.isfinite(pd.diff).all()
    assert np.nanmax(pd.diff) < 1e-6 and pd.angle_deg < 1e-6


def test_a_focal_length_1_percent_longer_moves_each_pixel_1_percent_of_its_radius():
    longer = PINHOLE * np.r_[1.01, 1.01, np.ones(7)]
    seen = _grid(56, 456, 12, 412)   # symmetric about the principal point: no rotation is implied
    pd = projection_difference(PINHOLE, longer, SIZE, seen)
    radius = np.hypot(*(_pixels(pd) - PINHOLE[2:4]).transpose(2, 0, 1))
    assert pd.angle_deg < 1e-6
    np.testing.assert_allclose(pd.diff, 0.01 * radius, atol=1e-6)


def test_a_principal_point_shift_is_mostly_a_rotation_of_the_frame():
    shifted = PINHOLE + np.r_[0.0, 0.0, 6.0, np.zeros(6)]
    seen = _grid(236, 276, 192, 232, 5)   # about the principal point
    pd = projection_difference(PINHOLE, shifted, SIZE, seen)
    about_y = Rotation.from_rotvec([0.0, -np.arctan(6.0 / 370.0), 0.0]).as_matrix()
    np.testing.assert_allclose(pd.rotation, about_y, atol=1e-4)
    assert np.max(pd.at(seen)) < 0.01 * 6.0
    # away from where it was fitted, rotation and shift part: at the image's corner, by hand
    corner = np.array([3.5, 3.5])
    ray = about_y @ np.r_[(corner - PINHOLE[2:4]) / PINHOLE[:2], 1.0]
    there = PINHOLE[:2] * ray[:2] / ray[2] + shifted[2:4]
    assert pd.at(corner[None])[0] == pytest.approx(np.hypot(*(there - corner)), rel=0.02)
    assert np.hypot(*(there - corner)) > 1.0


def test_where_a_lens_model_folds_there_is_no_answer():
    folding = LENS + np.r_[np.zeros(8), -3.0]
    fold = fold_distance(folding, SIZE)
    assert fold is not None and fold < 300
    pd = projection_difference(LENS, folding, SIZE, _grid(200, 312, 160, 264))
    radius = np.hypot(*(_pixels(pd) - LENS[2:4]).transpose(2, 0, 1))
    assert np.isfinite(pd.diff[radius < 0.8 * fold]).all()
    assert np.isnan(pd.diff[radius > 1.2 * fold]).all()
