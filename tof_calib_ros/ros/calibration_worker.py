"""Calibrations in a worker process, for the node.

The node keeps receiving frames while it calibrates. In one process, handling them takes
Python's GIL from the calibration: under a 45 pairs/s stream a calibration took a seventh longer
than with no stream. In its own process it has a core to itself (one thread: ``core.threads``),
and a crash in a numerical library ends the worker, not the node with its views. The stages
it reaches come back as they are reached, through a pipe of its own, for the node's log and
diagnostics: a calibration takes seconds (17 s for 48 views at 512x424).
"""
from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from multiprocessing.connection import Connection
from typing import Any

from ..collect.replay import worker_context
from ..core.errors import CalibrationError
from ..core.pipeline import calibrate
from ..core.result import CalibrationResult

PARENT_CHECK_S = 1.0
PROGRESS_POLL_S = 0.1   # how often the node looks for the worker's answer between its stages

_stages: Connection | None = None   # in the worker: where the stages a calibration reaches go


def _watch_parent(pid: int) -> None:
    """A SIGKILLed node cannot stop its worker: the worker ends itself once the node is gone."""
    while True:
        time.sleep(PARENT_CHECK_S)
        try:
            os.kill(pid, 0)
        except (ProcessLookupError, PermissionError):   # gone, or its pid taken by another process
            os._exit(0)


def _init(parent: int, stages: Connection) -> None:
    global _stages
    _stages = stages
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True).start()


def _calibrate(*args: Any, **kwargs: Any) -> CalibrationResult:
    """``calibrate`` with each stage it reaches sent as it is reached. Sent at once, not by a
    thread as a multiprocessing queue would: the last stage is in the pipe before the answer, so
    none is left for the next call to hear."""
    return calibrate(*args, progress=_stages.send, **kwargs)


def _ready() -> bool:
    return True


class CalibrationWorker:
    """One worker process, started at once (its imports take about a second) so that the first
    calibration does not wait for it; started anew if it ends."""

    def __init__(self) -> None:
        self._start()

    def _start(self) -> None:
        # A pipe for each worker: one killed (a timed-out call's) would leave half a message or a
        # stage of its call in it. Its sending end stays open here too, so a worker's end is told
        # by the pool, not the pipe.
        context = worker_context()
        self._stages, self._sender = context.Pipe(duplex=False)
        self._pool = ProcessPoolExecutor(1, mp_context=context, initializer=_init,
                                         initargs=(os.getpid(), self._sender))
        self._pool.submit(_ready)

    def calibrate(self, *args: Any, timeout: float | None = None, progress: Callable[[str], None] | None = None,
                  **kwargs: Any) -> CalibrationResult:
        """``tof_calib_ros.calibrate`` in the worker; raises what it raises. ``progress`` gets
        the stages the calibration reaches, in this thread, as they are reached. A worker that
        has not answered in ``timeout`` seconds (stopped, or stuck) is killed and replaced. One
        call at a time."""
        try:
            future = self._pool.submit(_calibrate, *args, **kwargs)
            deadline = None if timeout is None else time.monotonic() + timeout
            while not future.done():
                if deadline is not None and time.monotonic() > deadline:
                    raise TimeoutError
                self._relay(progress, PROGRESS_POLL_S)
            self._relay(progress, 0.0)   # the stages sent just before the answer
            return future.result()
        except BrokenProcessPool:
            self._restart()
            raise CalibrationError("the calibration's worker process ended (killed, or a crash in a numerical "
                                   "library); a new one is started: call again") from None
        except TimeoutError:
            self._restart(kill=True)
            raise CalibrationError(f"the calibration's worker process did not answer in {timeout:g} s (stopped "
                                   "or stuck; calibration.timeout); it was killed and a new one started: "
                                   "call again") from None

    def _relay(self, progress: Callable[[str], None] | None, wait: float) -> None:
        """Pass on the stages sent so far, waiting up to ``wait`` for the first."""
        while self._stages.poll(wait):
            wait = 0.0
            stage = self._stages.recv()
            if progress is not None:
                progress(stage)

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
