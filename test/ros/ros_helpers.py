"""The package's process helpers (tof_calib_ros.ros.processes) as pytest wants them: a package
missing from the ament index skips the node tests, a wait that runs out fails the test."""
from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip("rclpy", reason="the ROS 2 wheels are not installed (pip install .[ros,test])")

from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from tof_calib_ros.ros.processes import (  # noqa: E402, F401
    NodeProcess,
    NotInstalled,
    RosProcessError,
    Spinner,
    answered,
    logs,
    ros_environment,
)
from tof_calib_ros.ros.processes import executable as _executable  # noqa: E402
from tof_calib_ros.ros.processes import wait_until as _wait_until  # noqa: E402

START_TIMEOUT_S = 30.0   # process start (imports) plus discovery, which can take a few seconds
RESEND_S = 5.0   # a repeatable call unanswered this long is sent again (Spinner.call says why)


def calibrating(resp) -> bool:
    """~/calibrate's answer to a copy of a call it is still at work on (Spinner.call's ``busy``)."""
    return "already running" in resp.message


def executable(name: str) -> Path:
    try:
        return _executable(name)
    except NotInstalled as exc:
        pytest.skip(str(exc))


def wait_until(condition: Callable[[], Any], timeout: float, what: str | Callable[[], str], *procs: NodeProcess,
               period: float = 0.05) -> Any:
    try:
        return _wait_until(condition, timeout, what, *procs, period=period)
    except RosProcessError as exc:
        pytest.fail(str(exc))


def call_together(spinner: Spinner, name: str, n: int, timeout: float, *procs: NodeProcess) -> list:
    """n Trigger calls sent at once; every one must be answered."""
    client = spinner.client(Trigger, name)
    assert client.wait_for_service(timeout_sec=timeout), f"{name} not available\n" + logs(*procs)
    futures = [client.call_async(Trigger.Request()) for _ in range(n)]
    done = [threading.Event() for _ in futures]
    for f, d in zip(futures, done):
        f.add_done_callback(lambda _f, d=d: d.set())
    for d in done:
        assert d.wait(timeout), f"one of {n} simultaneous calls of {name} was not answered\n" + logs(*procs)
    return [f.result() for f in futures]


def set_parameter(spinner: Spinner, node: str, name: str, value, procs: tuple[NodeProcess, ...]) -> tuple[bool, str]:
    """What `ros2 param set` does: (successful, reason)."""
    req = SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()])
    resp = spinner.call(SetParameters, f"{node}/set_parameters", req, timeout=START_TIMEOUT_S, procs=procs,
                        resend_after=RESEND_S)
    return resp.results[0].successful, resp.results[0].reason
