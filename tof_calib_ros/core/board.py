"""The calibration checkerboard: corner coordinates and square colours.

Corners are counted as ROS camera_calibration and OpenCV count them: ``cols`` x ``rows``
interior corners, ordered row by row. Corner ``i`` sits at ``(i % cols, i // cols) * square``
on the board plane (z = 0). The square whose lower corner is at ``(i, j) * square``
(``i`` from -1 to ``cols - 1``, ``j`` from -1 to ``rows - 1``) is dark when ``i + j`` is even,
so the top-left square of the pattern is dark, as on a printed OpenCV board.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import CalibrationError

# Beyond these a board is a typo (or millimetres given as metres), not a calibration target.
MAX_CORNERS_PER_SIDE = 1000
MIN_CORNERS_PER_SIDE = 3
MIN_SQUARE_M = 1e-3
MAX_SQUARE_M = 10.0


def whole_number(value: object) -> int | None:
    """``value`` as an int when it is a whole number (an integral float counts), else None."""
    if isinstance(value, (bool, np.bool_)):
        return None
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)) and float(value).is_integer():
        return int(value)
    return None


@dataclass(frozen=True)
class Board:
    """A checkerboard with ``cols`` x ``rows`` interior corners and squares of ``square`` metres."""

    cols: int
    rows: int
    square: float

    def __post_init__(self) -> None:
        cols, rows = whole_number(self.cols), whole_number(self.rows)
        if cols is None or rows is None:
            raise CalibrationError(f"board size must be whole numbers, got {self.cols!r}x{self.rows!r}")
        if cols < MIN_CORNERS_PER_SIDE or rows < MIN_CORNERS_PER_SIDE:
            raise CalibrationError(f"board must have at least {MIN_CORNERS_PER_SIDE}x{MIN_CORNERS_PER_SIDE} interior "
                                   f"corners (OpenCV's detectors need 3 a side), got {cols}x{rows}")
        if cols > MAX_CORNERS_PER_SIDE or rows > MAX_CORNERS_PER_SIDE:
            raise CalibrationError(f"board must have at most {MAX_CORNERS_PER_SIDE} interior corners a side, "
                                   f"got {cols}x{rows}")
        square = self.square
        if isinstance(square, (bool, np.bool_)) or not isinstance(square, (int, float, np.integer, np.floating)) \
                or not MIN_SQUARE_M <= square <= MAX_SQUARE_M:
            raise CalibrationError(f"square size must be a length in metres from {MIN_SQUARE_M} to {MAX_SQUARE_M}, "
                                   f"got {square!r}")
        # frozen: set the normalised values the way dataclasses do
        object.__setattr__(self, "cols", cols)
        object.__setattr__(self, "rows", rows)
        object.__setattr__(self, "square", float(square))

    @property
    def n_corners(self) -> int:
        return self.cols * self.rows

    @property
    def pattern_size(self) -> tuple[int, int]:
        """The ``patternSize`` OpenCV's chessboard detectors expect."""
        return (self.cols, self.rows)

    def object_points(self, ids: np.ndarray | None = None) -> np.ndarray:
        """Corner positions on the board plane, metres, shape (N, 3)."""
        idx = np.arange(self.n_corners) if ids is None else np.asarray(ids, dtype=int)
        pts = np.zeros((idx.size, 3))
        pts[:, 0] = (idx % self.cols) * self.square
        pts[:, 1] = (idx // self.cols) * self.square
        return pts

    def outline(self, border: float, per_edge: int = 16) -> np.ndarray:
        """Points along the outline ``border`` squares beyond the interior corners, on the board
        plane (edges are sampled because distortion bends them): 1 is the squared area's edge."""
        sq = self.square
        x0, x1 = -border * sq, (self.cols - 1 + border) * sq
        y0, y1 = -border * sq, (self.rows - 1 + border) * sq
        s = np.linspace(0.0, 1.0, per_edge, endpoint=False)
        xs = np.r_[x0 + (x1 - x0) * s, np.full_like(s, x1), x1 - (x1 - x0) * s, np.full_like(s, x0)]
        ys = np.r_[np.full_like(s, y0), y0 + (y1 - y0) * s, np.full_like(s, y1), y1 - (y1 - y0) * s]
        return np.column_stack([xs, ys, np.zeros_like(xs)])

    def in_squared_area(self, x: np.ndarray, y: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """True where board-plane points (metres) lie on the squares, at least ``margin`` (a
        fraction of a square) inside the pattern's outline."""
        u = np.asarray(x, dtype=float) / self.square
        v = np.asarray(y, dtype=float) / self.square
        return (u >= margin - 1) & (u <= self.cols - margin) & (v >= margin - 1) & (v <= self.rows - margin)

    def is_white(self, x: np.ndarray, y: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """True where board-plane points (metres) lie on a white square, at least ``margin``
        (a fraction of the square) away from its edges and inside the squared area."""
        return self._on_squares(x, y, margin, 1)

    def is_black(self, x: np.ndarray, y: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """As ``is_white``, for the black squares."""
        return self._on_squares(x, y, margin, 0)

    def _on_squares(self, x: np.ndarray, y: np.ndarray, margin: float, parity: int) -> np.ndarray:
        u = np.asarray(x, dtype=float) / self.square
        v = np.asarray(y, dtype=float) / self.square
        i = np.floor(u)
        j = np.floor(v)
        fu = u - i
        fv = v - j
        inside = (i >= -1) & (i <= self.cols - 1) & (j >= -1) & (j <= self.rows - 1)
        away = (fu >= margin) & (fu <= 1 - margin) & (fv >= margin) & (fv <= 1 - margin)
        return inside & away & ((i + j) % 2 == parity)
