"""Depth-aided calibration of time-of-flight cameras (Pahwa, Do, Ng, Hua).

The public API::

    from tof_calib_ros import Board, View, calibrate
    result = calibrate(views, Board(cols=5, rows=7, square=0.03), depth_convention="z")

The layers, each importing only those below it (ARCHITECTURE.md): ``core`` (the method),
``collect`` (views from streams), ``files`` (files and recordings), ``sim`` and ``settings``,
then the two front ends, ``offline`` (``tof_calib``) and ``ros`` (the nodes, the only users of
rclpy). This module is the public API and imports ``core`` only.
"""
from .core.board import Board
from .core.errors import CalibrationError
from .core.inputs import View
from .core.pipeline import calibrate
from .core.result import CalibrationResult

__all__ = ["Board", "CalibrationError", "CalibrationResult", "View", "calibrate"]
