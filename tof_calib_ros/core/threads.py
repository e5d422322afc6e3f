"""One thread for OpenCV and the BLAS while a calibration or a worker runs."""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import cv2
from threadpoolctl import threadpool_limits


@contextmanager
def single_threaded() -> Iterator[None]:
    """Hold OpenCV and the BLAS to one thread, and give the caller its settings back after.

    Two reasons. The linear algebra here is small, so threads only contend (with each other and
    with whatever else runs, a camera driver say): on two cores they made solves 300x slower.
    And OpenCV's parallel loops add up in whatever order its threads finish, so the same views
    gave a different calibration on each run, sometimes a different model where a choice was
    close; one thread makes a calibration a function of its views.
    """
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with threadpool_limits(1):
            yield
    finally:
        cv2.setNumThreads(threads)
