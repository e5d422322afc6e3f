"""Fixtures of the tests that start ROS processes (the nodes as `ros2 run` starts them) and talk
to them from an rclpy node in this process; rclpy is imported only here and in these tests."""
from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def ros():
    """This run's ROS environment and an rclpy context in it (set up before rclpy.init)."""
    rclpy = pytest.importorskip("rclpy", reason="the ROS 2 wheels are not installed (pip install .[ros,test])")
    from ros_helpers import executable, ros_environment

    env = ros_environment()
    executable("calibration_node")   # skips the module when the package is not installed
    context = rclpy.Context()
    rclpy.init(context=context)
    yield env, context
    rclpy.shutdown(context=context)


@pytest.fixture
def launch(ros, tmp_path):
    """start(name, *ros_args) -> NodeProcess; stopped (SIGINT, then kill) after the test, and
    their output printed, which pytest shows when the test failed."""
    from ros_helpers import NodeProcess

    env, _ = ros
    procs: list = []

    def start(name: str, *args: str):
        proc = NodeProcess(name, list(args), tmp_path, env)
        procs.append(proc)
        return proc

    yield start
    for proc in procs:
        proc.stop()
    for proc in procs:
        print(proc.tail(200))


@pytest.fixture
def spinner(ros):
    from ros_helpers import Spinner

    _, context = ros
    s = Spinner(context, "tof_calib_test")
    yield s
    s.close()
