"""Running the package's nodes as `ros2 run` would, and talking to them with rclpy, for the tests.

There is no ros2 CLI in a venv, so this does what it does: finds the executable in
<prefix>/lib/tof_calib_ros through the ament index, passes --ros-args, and calls services and
subscribes from an rclpy node in the test process. Every process (this one included) gets the
same private ROS_DOMAIN_ID and discovery limited to localhost, so test runs neither see each
other nor put DDS traffic on the network.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

PACKAGE = "tof_calib_ros"
STOP_TIMEOUT_S = 10.0


def ros_environment() -> dict[str, str]:
    """Set and return the ROS environment of this test run; call before rclpy.init.

    The domain comes from the pid (1..100), so concurrent runs on one machine rarely share one;
    AMENT_PREFIX_PATH gets this venv, as sourcing a ROS install would give it.
    """
    env = os.environ
    env["ROS_DOMAIN_ID"] = str(1 + os.getpid() % 100)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_LOCALHOST_ONLY", None)       # deprecated; with the above it only warns
    prefixes = [p for p in env.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    if sys.prefix not in prefixes:
        env["AMENT_PREFIX_PATH"] = os.pathsep.join([sys.prefix, *prefixes])
    env["PYTHONUNBUFFERED"] = "1"
    env["RCUTILS_LOGGING_BUFFERED_STREAM"] = "0"
    return dict(env)


def executable(name: str) -> Path:
    """<prefix>/lib/tof_calib_ros/<name>, where `ros2 run tof_calib_ros <name>` finds it.

    Skips when the package is not in the ament index (an editable install has no data files);
    fails when it is but the executable is missing, as that is a packaging bug.
    """
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix

    try:
        prefix = get_package_prefix(PACKAGE)
    except PackageNotFoundError:
        pytest.skip(f"{PACKAGE} is not in the ament index under AMENT_PREFIX_PATH="
                    f"{os.environ.get('AMENT_PREFIX_PATH')} (an editable install registers nothing there): "
                    "install it non-editable (pip install .[ros,test], as tools/setup_venv.sh does) "
                    "to test the nodes")
    path = Path(prefix) / "lib" / PACKAGE / name
    assert path.is_file() and os.access(path, os.X_OK), (
        f"{PACKAGE} is installed in {prefix} but {path} is missing or not executable: "
        "'ros2 run' could not start it (check the launchers in setup.py's data_files)")
    return path


class NodeProcess:
    """One node started as `ros2 run` would; its stdout and stderr go to files under ``logdir``."""

    def __init__(self, name: str, args: list[str], logdir: Path, env: dict[str, str]):
        self.name = name
        # one file per process: a second node of the same name must not truncate the first's
        self.log = next(path for k in range(1, 1000)
                        if not (path := logdir / f"{name}{'' if k == 1 else f'.{k}'}.log").exists())
        cmd = [str(executable(name)), "--ros-args", *args]
        env = dict(env, ROS_LOG_DIR=str(logdir / "ros_log"))
        with open(self.log, "wb") as out:
            out.write(("$ " + " ".join(cmd) + "\n").encode())
            out.flush()
            # its own process group: SIGINT from the terminal goes to pytest alone, and we
            # decide when the node stops
            self.proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env,
                                         start_new_session=True)

    def alive(self) -> bool:
        return self.proc.poll() is None

    def output(self) -> str:
        return self.log.read_text(errors="replace")

    def tail(self, lines: int = 40) -> str:
        text = self.output().splitlines()[-lines:]
        return f"--- {self.name} (exit code {self.proc.poll()}), last {len(text)} lines:\n" + "\n".join(text)

    def stop(self) -> int | None:
        """SIGINT (a node's clean shutdown), then SIGKILL if it does not end in time."""
        if self.alive():
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(STOP_TIMEOUT_S)
        return self.proc.returncode


class Spinner:
    """An rclpy node of the test process, spun in a background thread so futures complete and
    messages arrive while a test waits."""

    def __init__(self, context: Any, name: str):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.node = rclpy.create_node(name, context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name=f"spin {name}", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

        try:
            self.executor.spin()
        except ExternalShutdownException:
            pass

    def call(self, srv_type: Any, name: str, request: Any = None, timeout: float = 30.0,
             procs: tuple[NodeProcess, ...] = ()) -> Any:
        """Call a service as `ros2 service call` does: wait for it, send, wait for the answer."""
        client = self.node.create_client(srv_type, name)
        try:
            assert client.wait_for_service(timeout_sec=timeout), \
                f"service {name} not available within {timeout:g} s\n" + logs(*procs)
            future = client.call_async(srv_type.Request() if request is None else request)
            done = threading.Event()
            future.add_done_callback(lambda _f: done.set())
            assert done.wait(timeout), f"service {name} did not answer within {timeout:g} s\n" + logs(*procs)
            return future.result()
        finally:
            self.node.destroy_client(client)

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=5.0)
        self.node.destroy_node()
        self._thread.join(timeout=5.0)


def wait_until(condition: Callable[[], Any], timeout: float, what: str | Callable[[], str], *procs: NodeProcess,
               period: float = 0.05) -> Any:
    """Poll ``condition`` until it returns something true; fail with ``what`` (or what it returns
    then, to show the state at the time) and the logs."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout:g} s waiting for {_text(what)}\n" + logs(*procs))
        for p in procs:
            if not p.alive():
                pytest.fail(f"{p.name} ended while waiting for {_text(what)}\n" + logs(*procs))
        time.sleep(period)


def _text(what: str | Callable[[], str]) -> str:
    return what() if callable(what) else what


def logs(*procs: NodeProcess) -> str:
    return "\n".join(p.tail() for p in procs)
