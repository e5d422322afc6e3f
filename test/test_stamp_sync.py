"""Pairing amplitude and depth frames by stamp."""
import pytest

from tof_calib_ros.collect.stamp_sync import StampSync


def test_pairs_within_slop_in_either_order():
    sync = StampSync(0.01)
    assert sync.add(0, 1.000, "a1") is None
    assert sync.add(1, 1.004, "d1") == ("a1", "d1")
    assert sync.add(1, 2.000, "d2") is None
    assert sync.add(0, 2.009, "a2") == ("a2", "d2")


def test_frames_too_far_apart_stay_unpaired_and_stale_ones_are_dropped():
    sync = StampSync(0.01)
    assert sync.add(0, 1.0, "a1") is None
    assert sync.add(1, 1.5, "d1") is None          # 0.5 s off: no pair
    assert sync.add(0, 1.502, "a2") == ("a2", "d1")
    assert sync.add(1, 1.001, "late") is None      # a1 was dropped as stale when d1 paired with a2


def test_nearest_frame_wins_and_queues_are_bounded():
    sync = StampSync(0.05, queue_size=3)
    for t in (0.00, 0.02, 0.04):
        assert sync.add(0, t, f"a{t}") is None
    assert sync.add(1, 0.035, "d") == ("a0.04", "d")
    assert not sync._pending[0]  # the older amplitude frames went stale with the pair
    for k in range(100):
        sync.add(1, float(k), k)
    assert len(sync._pending[1]) == 3


def test_rejects_a_negative_slop():
    with pytest.raises(ValueError, match="slop"):
        StampSync(-1.0)
