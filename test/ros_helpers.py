"""The package's process helpers (tof_calib_ros.ros_processes) as pytest wants them: a package
missing from the ament index skips the node tests, a wait that runs out fails the test."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tof_calib_ros.ros_processes import (  # noqa: F401
    NodeProcess,
    NotInstalled,
    RosProcessError,
    Spinner,
    logs,
    ros_environment,
)
from tof_calib_ros.ros_processes import executable as _executable
from tof_calib_ros.ros_processes import wait_until as _wait_until


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
