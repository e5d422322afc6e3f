"""Depth-aided calibration of time-of-flight cameras (Pahwa, Do, Ng, Hua).

The public API::

    from tof_calib_ros import Board, View, calibrate
    result = calibrate(views, Board(cols=5, rows=7, square=0.03), depth_convention="z")
"""
from .core.board import Board
from .core.errors import CalibrationError
from .core.pipeline import View, calibrate
from .core.result import CalibrationResult

__all__ = ["Board", "CalibrationError", "CalibrationResult", "View", "calibrate"]
