"""Starting the package's nodes as `ros2 run` would, and calling them as `ros2 service call` does.

A venv made from the PyPI wheels has neither the ros2 CLI nor launch, so the demo, the tests and
the benchmarks do what those do: find the executable in <prefix>/lib/tof_calib_ros through the
ament index, pass --ros-args, and talk to the node from an rclpy node spun in a thread. Every
process of a run shares one ROS_DOMAIN_ID, with discovery limited to this machine, so runs
neither see each other nor put DDS traffic on the network.
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

PACKAGE = "tof_calib_ros"
STOP_TIMEOUT_S = 10.0


class RosProcessError(RuntimeError):
    """A node could not be started, or did not answer in time."""


def ros_environment(domain_id: int | None = None) -> dict[str, str]:
    """Set and return the ROS environment of this run; call before rclpy.init.

    The domain comes from the pid (1..100) unless given, so concurrent runs on one machine rarely
    share one; AMENT_PREFIX_PATH gets this interpreter's prefix, as sourcing a ROS install would.
    """
    env = os.environ
    env["ROS_DOMAIN_ID"] = str(1 + os.getpid() % 100 if domain_id is None else domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_LOCALHOST_ONLY", None)       # deprecated; with the above it only warns
    prefixes = [p for p in env.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    if sys.prefix not in prefixes:
        env["AMENT_PREFIX_PATH"] = os.pathsep.join([sys.prefix, *prefixes])
    env["PYTHONUNBUFFERED"] = "1"
    env["RCUTILS_LOGGING_BUFFERED_STREAM"] = "0"
    return dict(env)


class NotInstalled(RosProcessError):
    """The package is not in the ament index: an editable install registers nothing there."""


def executable(name: str) -> Path:
    """<prefix>/lib/tof_calib_ros/<name>, where `ros2 run tof_calib_ros <name>` finds it."""
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix

    try:
        prefix = get_package_prefix(PACKAGE)
    except PackageNotFoundError:
        raise NotInstalled(
            f"{PACKAGE} is not in the ament index under AMENT_PREFIX_PATH={os.environ.get('AMENT_PREFIX_PATH')} "
            "(an editable install registers nothing there): install it with pip install .[ros] "
            "(tools/setup_venv.sh does), or build it with colcon and source install/setup.bash") from None
    path = Path(prefix) / "lib" / PACKAGE / name
    if not (path.is_file() and os.access(path, os.X_OK)):
        raise RosProcessError(f"{PACKAGE} is installed in {prefix} but {path} is missing or not executable: "
                              "'ros2 run' could not start it (check the launchers in setup.py's data_files)")
    return path


class NodeProcess:
    """One node started as `ros2 run` would; its stdout and stderr go to a file under ``logdir``."""

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
            # its own process group: SIGINT from the terminal reaches the caller alone, which
            # decides when the node stops
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


def tree_memory_mb(pid: int) -> float:
    """Memory of a process and all it started (the node's calibration worker and its fork
    server), MB: the proportional set size, so that pages a forked worker shares with its
    parent count once (their resident sizes would count them twice)."""
    import psutil

    try:
        root = psutil.Process(pid)
        processes = [root, *root.children(recursive=True)]
    except psutil.NoSuchProcess:
        return float("nan")
    total = 0
    for p in processes:
        try:
            total += p.memory_full_info().pss
        except psutil.NoSuchProcess:   # ended meanwhile
            pass
    return total / 2**20


def logs(*procs: NodeProcess) -> str:
    return "\n".join(p.tail() for p in procs)


class Spinner:
    """An rclpy node of this process, spun in a background thread so futures complete and
    messages arrive while the caller waits."""

    def __init__(self, context: Any, name: str):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.node = rclpy.create_node(name, context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._clients: dict[tuple[Any, str], Any] = {}
        self._thread = threading.Thread(target=self._spin, name=f"spin {name}", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

        try:
            self.executor.spin()
        except ExternalShutdownException:
            pass

    def client(self, srv_type: Any, name: str) -> Any:
        """One client per service for the spinner's life: a client's first answers are the ones
        at risk (see ``call``), so new clients are not made per call."""
        key = (srv_type, name)
        if key not in self._clients:
            self._clients[key] = self.node.create_client(srv_type, name)
        return self._clients[key]

    def call(self, srv_type: Any, name: str, request: Any = None, timeout: float = 30.0,
             procs: tuple[NodeProcess, ...] = (), resend_after: float | None = None,
             busy: Callable[[Any], bool] | None = None) -> Any:
        """Call a service as `ros2 service call` does: wait for it, send, wait for the answer.

        Fast DDS drops an answer when the server has not yet discovered the client's reply reader
        ("failed to send response (timeout)" in the server's log), which a loaded machine makes
        likely for a new client. A call that may safely be repeated (parameters, reset, commit)
        passes ``resend_after`` and is sent again while unanswered; the first answer counts, but
        one that ``busy`` says is the server still at work on an earlier copy (~/calibrate's
        "already running", when a calibration outlasts ``resend_after``): that answer shows the
        call arrived, so nothing more is sent and the earlier copy's answer is awaited.
        """
        client = self.client(srv_type, name)
        if not client.wait_for_service(timeout_sec=timeout):
            raise RosProcessError(f"service {name} not available within {timeout:g} s\n" + logs(*procs))
        request = srv_type.Request() if request is None else request
        done = threading.Event()
        futures: list = []
        deadline = time.monotonic() + timeout
        while True:
            done.clear()   # before looking: an answer that comes after it sets it again
            answers = [f for f in futures if f.done()]
            taken = [f for f in answers if busy is None or not busy(f.result())]
            if taken:
                break
            left = deadline - time.monotonic()
            if left <= 0:
                for f in futures:
                    client.remove_pending_request(f)
                raise RosProcessError(f"service {name} did not answer within {timeout:g} s\n" + logs(*procs))
            if not futures or (resend_after is not None and not answers):
                future = client.call_async(request)
                future.add_done_callback(lambda _f: done.set())
                futures.append(future)
            done.wait(left if resend_after is None else min(left, resend_after))
        answered = taken[0]
        for f in futures:
            if f is not answered:
                client.remove_pending_request(f)
        return answered.result()

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=5.0)
        self.node.destroy_node()
        self._thread.join(timeout=5.0)


def answered(client: Any, timeout: float) -> bool:
    """Whether a std_srvs/Trigger call through ``client`` is answered within ``timeout`` s (a
    client's first answers can be lost to discovery: see ``Spinner.call``); an unanswered call
    is withdrawn."""
    from std_srvs.srv import Trigger

    future, done = client.call_async(Trigger.Request()), threading.Event()
    future.add_done_callback(lambda _f: done.set())
    if done.wait(timeout):
        return True
    client.remove_pending_request(future)
    return False


def wait_until(condition: Callable[[], Any], timeout: float, what: str | Callable[[], str], *procs: NodeProcess,
               period: float = 0.05) -> Any:
    """Poll ``condition`` until it returns something true; raise with ``what`` (or what it returns
    then, to show the state at that time) and the logs when the time is up or a node ended."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        ended = [p.name for p in procs if not p.alive()]
        if ended or time.monotonic() > deadline:
            why = f"{ended[0]} ended" if ended else f"timed out after {timeout:g} s"
            raise RosProcessError(f"{why} while waiting for {what() if callable(what) else what}\n" + logs(*procs))
        time.sleep(period)


def play(node: Any, namespace: str, bag: Path, rate: float, procs: tuple[NodeProcess, ...] = (),
         timeout: float = 30.0) -> int:
    """Publish a recording's amplitude and depth pairs to ``namespace``/amplitude and /depth at
    ``rate`` pairs a second (a camera, live), with their recorded stamps, once the subscriber is
    there; returns the pairs sent. ``node``: the rclpy node to publish from (a ``Spinner``'s)."""
    from builtin_interfaces.msg import Time
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    from ..collect.replay import Skip
    from ..files.bag_io import BagSource, stamp_parts

    pubs = [node.create_publisher(Image, f"{namespace}/{topic}", qos_profile_sensor_data)
            for topic in ("amplitude", "depth")]
    sent = 0
    try:
        wait_until(lambda: all(p.get_subscription_count() for p in pubs), timeout, "the node's image subscriptions",
                   *procs)
        with BagSource(bag) as source:
            due = time.monotonic()
            for frame in source.frames():
                if isinstance(frame, Skip):
                    continue
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                sec, nanosec = stamp_parts(frame.stamp)
                stamp = Time(sec=sec, nanosec=nanosec)
                for pub, fields in zip(pubs, (frame.amplitude, frame.depth)):
                    msg = Image(height=fields.height, width=fields.width, encoding=fields.encoding,
                                is_bigendian=fields.is_bigendian, step=fields.step)
                    msg.header.stamp, msg.header.frame_id = stamp, fields.frame_id
                    msg.data = fields.data.tobytes()
                    pub.publish(msg)
                sent += 1
                due += 1.0 / rate
    finally:
        for p in pubs:
            node.destroy_publisher(p)
    return sent
