"""How the package's nodes run: usage on ``--help``, the executor, and a clean end on a signal.

rclpy's own signal handler shuts the context down the moment SIGINT arrives, while callbacks
may still be publishing: the simulated camera then ended every Ctrl-C with "RCLError: Failed to
publish: publisher's context is invalid" and exit 1. Here SIGINT and SIGTERM stop the executor
first, running callbacks finish, the node is destroyed, and only then is the context shut down:
exit 0, no traceback. A signal during start-up ends the node the same way, once it has started.
The signal only raises a flag that the spinning loop reads between callbacks: raised as a
KeyboardInterrupt it could land inside the thread pool's submit, between a new thread's start
and its registration for the interpreter's exit, which then waited for that thread forever (a
SIGTERM in CI, 2026-11-27). Whatever a thread is doing, a stop ends the process within
``STOP_DEADLINE_S``: past it, the threads still running are printed and the process exits 1.

``Executor`` is the multi-threaded executor the calibration node needs on Jazzy (see its doc).
"""
from __future__ import annotations

import faulthandler
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

import rclpy
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import (
    ConditionReachedException,
    ExternalShutdownException,
    MultiThreadedExecutor,
    ShutdownException,
    SingleThreadedExecutor,
    TimeoutException,
)
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from ..core.errors import CalibrationError

STOP_TIMEOUT_S = 5.0   # callbacks still running when a signal comes get this long to finish
STOP_DEADLINE_S = 15.0  # the whole stop, threads joined at the interpreter's exit included
SPIN_PERIOD_S = 0.1    # the longest a stop waits for the executor to look up from an idle wait


class Executor(MultiThreadedExecutor):
    """MultiThreadedExecutor that hands each task to its thread pool once.

    Jazzy's (rclpy 7.1) yields a task again while it still waits in the pool and submits it again;
    under a steady stream of frames its spinning thread then does little else, holding the GIL, and
    the callbacks starve: frames are lost before they are paired and ~/calibrate is answered
    seconds late (ros2/rclpy#1452, fixed in later rclpy). A task is submitted again only once its
    previous run has ended (a coroutine resumed after an await).
    """

    def __init__(self, num_threads: int) -> None:
        super().__init__(num_threads=num_threads)
        self._runs: dict = {}   # task -> its latest run in the pool

    def _spin_once_impl(self, timeout_sec=None, wait_condition=lambda: False) -> None:
        try:
            task, _entity, _node = self.wait_for_ready_callbacks(timeout_sec, None, wait_condition)
        except (ExternalShutdownException, ShutdownException, TimeoutException, ConditionReachedException):
            return
        run = self._runs.get(task)
        if run is not None and not run.done():
            time.sleep(0.001)   # it waits for a pool thread: let one take the GIL and start it
            return
        self._runs[task] = self._executor.submit(task)
        for done in [t for t in self._runs if t.done()]:
            del self._runs[done]
            done.result()   # raise what a callback raised, as MultiThreadedExecutor does


def usage(name: str, doc: str, parameters: Mapping[str, tuple[Any, str]]) -> str:
    """What ``--help`` prints: the node's docstring and its parameters with their defaults."""
    width = max(map(len, parameters), default=0)
    lines = [f"usage: ros2 run tof_calib_ros {name} [--ros-args [-r FROM:=TO] [-p NAME:=VALUE] ...]", "",
             doc.strip(), "", "parameters (-p NAME:=VALUE):"]
    lines += [f"  {p:<{width}}  {default!r:<12} {text}" for p, (default, text) in parameters.items()]
    return "\n".join(lines)


def run(name: str, make_node: Callable[[], Node], doc: str, parameters: Mapping[str, tuple[Any, str]],
        args: list[str] | None = None, executor: Callable[[], Any] = SingleThreadedExecutor) -> int:
    """Run a node until SIGINT or SIGTERM; returns the exit code. ``-h``/``--help`` before any
    ``--ros-args`` prints the usage instead. A node that cannot start (a bad parameter) exits 1
    with the reason, without a traceback."""
    argv = sys.argv[1:] if args is None else args
    own = argv[:argv.index("--ros-args")] if "--ros-args" in argv else argv
    if "-h" in own or "--help" in own:
        print(usage(name, doc, parameters))
        return 0
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    # Set here, not inherited: a process started in the background of a script inherits SIGINT
    # ignored, and such a node could not be stopped the way launch stops nodes.
    stop: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):   # SIGTERM ends the node as SIGINT does
        signal.signal(sig, lambda signum, _frame: stop.append(signum))
    node = spinner = None
    try:
        try:
            node = make_node()
        except (InvalidParameterValueException, InvalidParameterTypeException, CalibrationError) as exc:
            rclpy.logging.get_logger(name).fatal(str(exc))
            return 1
        spinner = executor()
        spinner.add_node(node)
        while not stop and rclpy.ok():
            spinner.spin_once(timeout_sec=SPIN_PERIOD_S)
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)    # a second Ctrl-C must not cut the clean-up short
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        _deadline(name, STOP_DEADLINE_S)
        if spinner is not None:
            spinner.shutdown(timeout_sec=STOP_TIMEOUT_S)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def _deadline(name: str, seconds: float) -> None:
    """End the process ``seconds`` from now unless it has ended: a thread stuck in a library (a
    DDS participant's clean-up, a pool joined at the interpreter's exit) must not keep a node
    alive after Ctrl-C. What was still running is printed, so that the cause can be found."""
    def expire() -> None:
        sys.stderr.write(f"[{name}] stopping took more than {seconds:g} s: ended by force; its threads were at\n")
        faulthandler.dump_traceback(file=sys.stderr, all_threads=True)
        sys.stderr.flush()
        os._exit(1)

    timer = threading.Timer(seconds, expire)
    timer.daemon = True   # the interpreter's exit does not wait for it, and it outlives the threads it waits for
    timer.start()
