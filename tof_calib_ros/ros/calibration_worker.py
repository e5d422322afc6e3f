"""Calibrations in a worker process, for the node.

The node keeps receiving frames while it calibrates. In one process, handling them takes
Python's GIL from the calibration: under a 45 pairs/s stream a calibration took a seventh longer
than with no stream. In its own process it has a core to itself (one thread: ``core.threads``),
and a crash in a numerical library ends the worker, not the node with its views.
"""
from __future__ import annotations

import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from ..collect.replay import worker_context
from ..core.errors import CalibrationError
from ..core.pipeline import calibrate
from ..core.result import CalibrationResult

PARENT_CHECK_S = 1.0


def _watch_parent(pid: int) -> None:
    """A SIGKILLed node cannot stop its worker: the worker ends itself once the node is gone."""
    while True:
        time.sleep(PARENT_CHECK_S)
        try:
            os.kill(pid, 0)
        except (ProcessLookupError, PermissionError):   # gone, or its pid taken by another process
            os._exit(0)


def _init(parent: int) -> None:
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True).start()


def _ready() -> bool:
    return True


class CalibrationWorker:
    """One worker process, started at once (its imports take about a second) so that the first
    calibration does not wait for it; started anew if it ends."""

    def __init__(self) -> None:
        self._start()

    def _start(self) -> None:
        self._pool = ProcessPoolExecutor(1, mp_context=worker_context(), initializer=_init, initargs=(os.getpid(),))
        self._pool.submit(_ready)

    def calibrate(self, *args: Any, timeout: float | None = None, **kwargs: Any) -> CalibrationResult:
        """``tof_calib_ros.calibrate`` in the worker; raises what it raises. A worker that has
        not answered in ``timeout`` seconds (stopped, or stuck) is killed and replaced."""
        try:
            return self._pool.submit(calibrate, *args, **kwargs).result(timeout=timeout)
        except BrokenProcessPool:
            self._restart()
            raise CalibrationError("the calibration's worker process ended (killed, or a crash in a numerical "
                                   "library); a new one is started: call again") from None
        except TimeoutError:
            self._restart(kill=True)
            raise CalibrationError(f"the calibration's worker process did not answer in {timeout:g} s (stopped "
                                   "or stuck; calibration.timeout); it was killed and a new one started: "
                                   "call again") from None

    def _restart(self, kill: bool = False) -> None:
        if kill:
            self._kill()
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._start()

    def _kill(self) -> None:
        for process in list((self._pool._processes or {}).values()):   # noqa: SLF001 - no public way to kill it
            process.kill()

    def close(self) -> None:
        """Kill the worker and wait for the pool's threads: left running, they met closed pipes at
        the interpreter's exit (an "OSError: Bad file descriptor" traceback on some stops)."""
        self._kill()
        self._pool.shutdown(wait=True, cancel_futures=True)
