"""Where the views reached, and the note a result carries where its projection beyond them is
much less known than inside."""
from __future__ import annotations

import numpy as np

from tof_calib_ros.core.coverage import CELLS, Reach, cell_counts, cell_of


def test_cells_split_the_image_into_equal_parts_edge_pixels_included():
    assert cell_of(np.array([-0.5, 0.0, 63.4, 63.6, 511.0, 511.5]), 512).tolist() == [0, 0, 0, 1, CELLS - 1, CELLS - 1]
    counts = cell_counts(np.array([[0.0, 0.0], [511.0, 0.0], [511.0, 423.0], [300.0, 200.0]]), (512, 424))
    assert counts.sum() == 4 and counts[0, 0] == counts[CELLS - 1, 0] == counts[CELLS - 1, CELLS - 1] == 1
    assert counts[cell_of(300.0, 512), cell_of(200.0, 424)] == 1


def _reach(known: float, beyond: float | None) -> Reach:
    spread = np.full((4, 4), known)
    inside = np.ones((4, 4), bool)
    if beyond is not None:
        spread[0, 0], inside[0, 0] = beyond, False
    return Reach(np.arange(4.0), np.arange(4.0), spread, inside, 12)


def test_a_note_only_where_the_projection_beyond_the_views_is_much_less_known():
    far = _reach(0.5, 20.0).extrapolated()
    assert far == (12, 20.0, 0.5)
    assert "20.0 px at worst" in far.note() and "0.50 px" in far.note() and "12 of" in far.note()
    assert _reach(0.5, 2.5).extrapolated() is None    # under 3 px: what a moving-board recording leaves
    assert _reach(2.0, 5.0).extrapolated() is None    # under 3 times what the views reached
    assert _reach(0.5, None).extrapolated() is None   # the views reached every cell
