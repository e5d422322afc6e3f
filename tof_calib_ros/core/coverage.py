"""How much of the image the views reached, and how well the calibration knows the pixels they
did not: lens terms fitted where the board was are extrapolated elsewhere, which no parameter's
standard deviation shows (mrcal's uncertainty map does)."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .projection_diff import projection_spread

CELLS = 8   # the image is split CELLS x CELLS to count where the corners fell
# Beyond the cells the views reached, a projection known this many times worse than inside them,
# and to no better than this many pixels, is worth a note: the calibration is not to be used there
# as it is inside. Simulated moving-board recordings that miss the image's corners reach 0.1-1.6 px
# there (their true error 0.04-1.6 px); the real Kinect v2 views 19-31 px.
EXTRAPOLATION_RATIO = 3.0
EXTRAPOLATION_PX = 3.0


def cell_of(x: np.ndarray, length: int) -> np.ndarray:
    """Which of CELLS equal cells along an image side of ``length`` px each coordinate is in."""
    return np.clip(((np.asarray(x) + 0.5) * CELLS / length).astype(int), 0, CELLS - 1)


def cell_counts(pixels: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """(CELLS, CELLS) how many of ``pixels`` (N, 2) fall in each cell, indexed by x then y."""
    counts = np.zeros((CELLS, CELLS), dtype=int)
    np.add.at(counts, (cell_of(pixels[:, 0], image_size[0]), cell_of(pixels[:, 1], image_size[1])), 1)
    return counts


def in_cells(cells: np.ndarray, pixels: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """Whether each of ``pixels`` (..., 2) lies in a cell ``cells`` (CELLS, CELLS, by x then y) marks."""
    return cells[cell_of(pixels[..., 0], image_size[0]), cell_of(pixels[..., 1], image_size[1])]


def grid_in_cells(cells: np.ndarray, xs: np.ndarray, ys: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """(len(ys), len(xs)): whether each pixel of the grid of columns ``xs`` and rows ``ys`` lies in
    a cell ``cells`` marks."""
    return cells[cell_of(xs, image_size[0])[None, :], cell_of(ys, image_size[1])[:, None]]


class Reach(NamedTuple):
    xs: np.ndarray        # (W',) pixel columns of the map
    ys: np.ndarray        # (H',) pixel rows
    spread: np.ndarray    # (H', W') px, how well each pixel's projection is known (projection_spread)
    inside: np.ndarray    # (H', W') whether the views reached the pixel's cell
    cells: int            # how many of the CELLS x CELLS cells they reached

    @property
    def known(self) -> np.ndarray:
        return self.spread[self.inside & np.isfinite(self.spread)]

    @property
    def beyond(self) -> np.ndarray:
        return self.spread[~self.inside & np.isfinite(self.spread)]

    def extrapolated(self) -> Extrapolated | None:
        """Where the projection beyond the views is much less known than inside them, by how much."""
        if not (self.known.size and self.beyond.size):
            return None
        inside, worst = float(np.median(self.known)), float(self.beyond.max())
        if worst <= max(EXTRAPOLATION_PX, EXTRAPOLATION_RATIO * inside):
            return None
        return Extrapolated(self.cells, worst, inside)


class Extrapolated(NamedTuple):
    cells: int        # of the CELLS x CELLS the views reached
    worst: float      # px, the projection's worst spread beyond them
    inside: float     # px, its median where they reached

    def brief(self) -> str:
        """For the one-line summary."""
        return (f"the views reached {self.cells} of {CELLS * CELLS} image cells, beyond them the projection is known "
                f"to {self.worst:.1f} px only")

    def note(self) -> str:
        return (f"the views reached {self.cells} of the image's {CELLS}x{CELLS} cells; beyond them the lens terms are "
                f"extrapolated and each pixel's projection is known to {self.worst:.1f} px at worst ({self.inside:.2f} "
                "px in the median where they reached, from the refits without each run of views): do not use the "
                "calibration there as inside, or add views that reach the image's edges")


def reach(intrinsics: np.ndarray, runs: np.ndarray, corners: np.ndarray, image_size: tuple[int, int]) -> Reach:
    """The map of how well each pixel's projection is known (``runs``: the intrinsics refitted
    without each run of views), and which pixels lie in cells the ``corners`` (N, 2) reached."""
    reached = cell_counts(corners, image_size) > 0
    xs, ys, spread = projection_spread(intrinsics, runs, image_size, corners)
    return Reach(xs, ys, spread, grid_in_cells(reached, xs, ys, image_size), int(reached.sum()))
