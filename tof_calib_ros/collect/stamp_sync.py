"""Pairs amplitude and depth frames by their header stamps (message_filters' approximate-time
policy, which has no wheel here, reduced to the two streams a ToF camera publishes)."""
from __future__ import annotations

from collections import deque
from typing import Any


class StampSync:
    """Keeps the last few frames of each stream; a frame is paired with the other stream's
    frame nearest in time, if within ``slop`` seconds. Older unpaired frames are dropped:
    a frame can only be matched by a newer one if the camera sends stamps out of order."""

    def __init__(self, slop: float, queue_size: int = 8):
        if not slop >= 0:
            raise ValueError(f"slop must be a non-negative number of seconds, got {slop}")
        self.slop = slop
        self._pending: tuple[deque, deque] = (deque(maxlen=queue_size), deque(maxlen=queue_size))

    def add(self, stream: int, stamp: float, frame: Any) -> tuple[Any, Any] | None:
        """Offer a frame of stream 0 (amplitude) or 1 (depth); returns (amplitude, depth) when paired."""
        other = self._pending[1 - stream]
        best = min(range(len(other)), key=lambda k: abs(other[k][0] - stamp), default=None)
        if best is None or abs(other[best][0] - stamp) > self.slop:
            self._pending[stream].append((stamp, frame))
            return None
        match_stamp, match = other[best]
        # Everything up to the pair is stale now: the streams have moved past it.
        for queue, limit in ((other, match_stamp), (self._pending[stream], stamp)):
            while queue and queue[0][0] <= limit:
                queue.popleft()
        return (frame, match) if stream == 0 else (match, frame)

    def clear(self) -> None:
        for queue in self._pending:
            queue.clear()
