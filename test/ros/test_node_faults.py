"""The calibration node under faults: a driver that is absent, slow or failing; services called
while a calibration runs; parameters changed while views are collected; SIGKILL while the
calibration files are written. Real processes, as in test_node.py.

Defined behaviour (README, "Concurrency and faults"):
- ~/calibrate while one runs: answered at once, "already running".
- ~/reset while a calibration runs: the views are cleared for the next one; the running one
  finishes with the views it started with and is published.
- a parameter changed while collecting applies from the next frame (depth.scale, sync.slop) or
  the next calibration (depth.convention, views.min); views already kept stay.
- ~/commit: the driver absent, slow (over 5 s) or refusing is reported; the node goes on.
- SIGKILL at any moment leaves the previous calibration files whole.
- the calibration's worker process killed: that calibration fails saying so; the next one works.
"""
from __future__ import annotations

import os
import re
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="the ROS 2 wheels are not installed (pip install .[ros,test])")

from ros_helpers import (  # noqa: E402
    RESEND_S,
    START_TIMEOUT_S,
    Spinner,
    answered,
    calibrating,
    logs,
    set_parameter,
    wait_until,
)
from sensor_msgs.srv import SetCameraInfo  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from tof_calib_ros.files.calibration_file import read_camera_yaml  # noqa: E402
from tof_calib_ros.files.image_folder import load_views  # noqa: E402

COLLECT_TIMEOUT_S = 90.0
BOARD = ("-p", "board.cols:=5", "-p", "board.rows:=7", "-p", "board.square:=0.03")


def _start(launch, ns: str, out: Path, *node_args: str):
    simulator = launch("tof_sim_node", "-r", f"__ns:={ns}", *BOARD, "-p", "rate:=20.0")
    node = launch("calibration_node", "-r", f"__ns:={ns}", *BOARD, "-p", "views.min:=8",
                  "-p", f"output_dir:={out}", *node_args)
    return simulator, node


def _calibrate_when_ready(spinner: Spinner, ns: str, procs) -> Trigger.Response:
    deadline = time.monotonic() + COLLECT_TIMEOUT_S
    while True:
        # a resent copy that meets the first still running is no answer: the first's is awaited
        # (without that, calibrations longer than RESEND_S, 20 s with 41 views on a slow machine,
        # answered every call "already running" until the deadline)
        resp = spinner.call(Trigger, f"{ns}/calibration_node/calibrate", timeout=COLLECT_TIMEOUT_S,
                            procs=procs, resend_after=RESEND_S, busy=calibrating)
        if resp.success:
            return resp
        assert "views collected" in resp.message, \
            resp.message + "\n" + logs(*procs)
        if time.monotonic() > deadline:
            pytest.fail(f"no calibration within {COLLECT_TIMEOUT_S:g} s: {resp.message}\n" + logs(*procs))
        time.sleep(0.5)


def _call_async(spinner: Spinner, name: str):
    """Send a Trigger call now; returns wait() -> response."""
    client = spinner.client(Trigger, name)
    assert client.wait_for_service(timeout_sec=START_TIMEOUT_S), name
    future, done = client.call_async(Trigger.Request()), threading.Event()
    future.add_done_callback(lambda _f: done.set())

    def wait(timeout: float = 60.0):
        assert done.wait(timeout), f"{name} did not answer within {timeout:g} s"
        return future.result()
    wait.done = done
    return wait


@pytest.mark.slow
def test_commit_reports_an_absent_failing_or_slow_driver(launch, spinner, ros, tmp_path):
    ns = "/f1"
    procs = _start(launch, ns, tmp_path / "out", "-p", f"set_camera_info_service:={ns}/fake_driver")
    _calibrate_when_ready(spinner, ns, procs)
    commit = f"{ns}/calibration_node/commit"

    resp = spinner.call(Trigger, commit, timeout=30.0, procs=procs, resend_after=RESEND_S)
    assert not resp.success and resp.message == f"the driver's service {ns}/fake_driver is not available"

    behaviour = {"mode": "refuse"}
    received: list = []
    slow_answered = threading.Event()

    def driver(req: SetCameraInfo.Request, out: SetCameraInfo.Response) -> SetCameraInfo.Response:
        received.append(req.camera_info)
        mode = behaviour["mode"]
        if mode == "slow":
            time.sleep(8.0)
        out.success = mode == "ok"
        out.status_message = {"refuse": "disk full: calibration not stored", "slow": "late", "ok": "stored"}[mode]
        if mode == "slow":
            slow_answered.set()
        return out

    _, context = ros
    fake = Spinner(context, "fake_driver")   # its own executor: a slow answer blocks only itself
    try:
        fake.node.create_service(SetCameraInfo, f"{ns}/fake_driver", driver)
        resp = spinner.call(Trigger, commit, timeout=30.0, procs=procs, resend_after=RESEND_S)
        assert not resp.success and resp.message == f"{ns}/fake_driver: disk full: calibration not stored"
        assert received and received[-1].width == 200 and received[-1].k[0] > 0

        behaviour["mode"] = "slow"
        t0 = time.monotonic()
        resp = spinner.call(Trigger, commit, timeout=30.0, procs=procs)
        assert not resp.success and resp.message == f"{ns}/fake_driver did not answer within 5 s", resp.message
        assert time.monotonic() - t0 < 7.5
        # the node answers others meanwhile and afterwards
        resp = spinner.call(Trigger, f"{ns}/calibration_node/reset", timeout=5.0, procs=procs, resend_after=RESEND_S)
        assert resp.success

        assert slow_answered.wait(15.0), "the fake driver's slow answer never ended"
        behaviour["mode"] = "ok"
        resp = spinner.call(Trigger, commit, timeout=30.0, procs=procs, resend_after=RESEND_S)
        assert resp.success and resp.message == f"{ns}/fake_driver: stored", resp.message
    finally:
        fake.close()
    assert all(p.alive() for p in procs), logs(*procs)


def _views_given(summary: str) -> int:
    """The views a calibration was given, from its summary line ("12 of 14 views used")."""
    return int(re.search(r"\d+ of (\d+) views used", summary)[1])


def test_reset_while_calibrating_and_parameters_while_collecting(launch, spinner, tmp_path):
    ns, out = "/f2", tmp_path / "out"
    procs = _start(launch, ns, out)
    node = f"{ns}/calibration_node"
    # parameters changed while frames flow: accepted, and the collection goes on
    for name, value in [("depth.scale", 0.001), ("sync.slop", 0.05), ("views.min", 9), ("depth.convention", "z"),
                        ("sync.slop", 0.02), ("views.min", 8)]:
        assert set_parameter(spinner, node, name, value, procs) == (True, "")
    first = _calibrate_when_ready(spinner, ns, procs)
    n_views = _views_given(first.message)

    calibration = _call_async(spinner, f"{node}/calibrate")
    reset = spinner.call(Trigger, f"{node}/reset", timeout=10.0, procs=procs, resend_after=RESEND_S)
    assert not calibration.done.is_set(), "the calibration ended before the reset: nothing ran at once"
    resp = calibration(60.0)
    assert reset.success and reset.message.startswith("cleared "), reset.message
    assert int(reset.message.split()[1]) >= n_views, reset.message   # the views were there, and went
    # the running calibration used the views it started with, all of them
    assert resp.success and _views_given(resp.message) >= n_views, resp.message
    again = spinner.call(Trigger, f"{node}/calibrate", timeout=30.0, procs=procs)
    # after the reset: refused for want of views, or calibrated on views collected since (frames flow)
    assert again.success or "views collected" in again.message, again.message
    assert all(p.alive() for p in procs), logs(*procs)


def _files(out: Path) -> tuple[np.ndarray, int]:
    """The calibration in ``out`` must be whole: the YAML and JSON parse, the views load."""
    import json

    K = read_camera_yaml(out / "calibration.yaml").K
    doc = json.loads((out / "calibration.json").read_text())
    assert np.asarray(doc["camera_matrix"]).shape == (3, 3)
    return K, len(load_views(out / "views"))


def test_sigkill_while_writing_keeps_the_previous_files(launch, spinner, tmp_path):
    ns, out = "/f3", tmp_path / "out"
    simulator, node = _start(launch, ns, out)
    _calibrate_when_ready(spinner, ns, (simulator, node))
    K_before, n_before = _files(out)

    # the next calibration is killed while its set is being written
    seen = threading.Event()

    def kill_when_writing() -> None:
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and node.alive():
            if any((out / ".generations").glob(".staging.*")):
                os.kill(node.proc.pid, signal.SIGKILL)
                seen.set()
                return
            time.sleep(0.0005)

    killer = threading.Thread(target=kill_when_writing)
    killer.start()
    client = spinner.client(Trigger, f"{ns}/calibration_node/calibrate")
    client.call_async(Trigger.Request())   # never answered: the node dies while writing
    wait_until(lambda: not node.alive(), 60.0, "the node to be killed while writing", simulator)
    killer.join()
    assert seen.is_set(), "the node ended, but not by the kill while writing\n" + logs(node)
    K_after, n_after = _files(out)
    assert np.array_equal(K_after, K_before)
    assert n_after == n_before   # the old views, not a part of the new ones


@pytest.mark.slow
def test_soak_under_load_and_faults(ros, tmp_path):
    """benchmarks/reliability.py's soak, shorter outside CI (TOF_CALIB_SOAK_MINUTES overrides):
    every call answered (a burst of 300 at once among them), no file damaged, no NaN published,
    the node alive (its calibration worker stopped once, and replaced), memory bounded."""
    import json
    import subprocess
    import sys

    minutes = float(os.environ.get("TOF_CALIB_SOAK_MINUTES", "10" if os.environ.get("CI") else "1"))
    script = Path(__file__).resolve().parents[2] / "benchmarks" / "reliability.py"
    report = tmp_path / "reliability.json"
    env, _ = ros
    env = {k: v for k, v in env.items() if k != "ROS_DOMAIN_ID"}   # its own domain
    run = subprocess.run([sys.executable, str(script), "--minutes", str(minutes), "--fuzz", "300", "--no-faults",
                          "--json", str(report)], capture_output=True, text=True, timeout=minutes * 60 + 300, env=env)
    assert run.returncode == 0, run.stdout + run.stderr
    soak = json.loads(report.read_text())["soak"]
    assert soak["data lost"] == 0 and soak["node alive at the end"], soak
    assert soak["calls answered"] == soak["calls made"] >= 10 * minutes, soak
    assert all(n > 0 for n in soak["malformed injected"].values()), soak["malformed injected"]
    assert soak["calls"]["calibrate"]["succeeded"] >= 1, soak["calls"]
    assert all(soak["events"].values()), soak["events"]   # the 300-call burst and the stopped worker
    # bounded: the views (30 of 200x200) and the calibrations' working memory, not the stream
    first, full, end = soak["memory MB (first; median once views full, at end)"]
    assert end < 600 and end - full < 50, soak


def test_any_parameter_value_is_applied_or_refused_with_a_reason(launch, spinner):
    """Property: whatever `ros2 param set` sends, the node answers, stays up, and every value
    it then holds is one it would accept."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st
    from rcl_interfaces.srv import GetParameters

    from tof_calib_ros.ros.node import PARAMETERS
    from tof_calib_ros.settings import CAMERA_NAME

    node = launch("calibration_node", "-r", "__ns:=/f4")
    procs = (node,)
    names = st.sampled_from([*PARAMETERS, "board.size", "", "views", "depth.scale.x"])
    values = st.one_of(st.integers(-2**63, 2**63 - 1), st.floats(allow_nan=True, allow_infinity=True),
                       st.text(max_size=30), st.booleans(), st.sampled_from(["z", "radial", "x_1", "/tmp/o"]),
                       st.lists(st.integers(-5, 5), max_size=3))
    outcomes = {"ok": 0, "refused": 0}

    @settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
    @given(name=names, value=values)
    def check(name, value):
        ok, reason = set_parameter(spinner, "/f4/calibration_node", name, value, procs)
        outcomes["ok" if ok else "refused"] += 1
        assert ok or reason, f"{name}={value!r} refused without a reason"

    check()
    assert node.alive() and outcomes["ok"] > 0 and outcomes["refused"] > 0, outcomes
    req = GetParameters.Request(names=list(PARAMETERS))
    got = spinner.call(GetParameters, "/f4/calibration_node/get_parameters", req,
                       procs=procs, resend_after=RESEND_S).values
    held = {}
    for name, v in zip(PARAMETERS, got):
        held[name] = [v.bool_value, v.integer_value, v.double_value, v.string_value][v.type - 1]
    assert (held["board.cols"], held["board.rows"], held["board.square"]) == (5, 7, 0.03)   # read-only
    assert held["depth.convention"] in ("auto", "z", "radial")
    assert 1e-6 <= held["depth.scale"] <= 10.0 and 0.0 <= held["sync.slop"] <= 1.0
    assert 3 <= held["views.min"] <= held["views.max"] <= 1000
    assert CAMERA_NAME.fullmatch(held["camera_name"]) and held["output_dir"].strip()
    resp = spinner.call(Trigger, "/f4/calibration_node/reset", timeout=10.0, procs=procs, resend_after=RESEND_S)
    assert resp.success


@pytest.mark.slow
def test_the_calibration_worker_killed_is_reported_and_replaced(launch, spinner, tmp_path):
    """The calibration runs in a worker process: a crash there (here a SIGKILL) costs that one
    calibration, said in the answer; the node, its views and the next calibration go on."""
    import psutil

    ns = "/f5"
    procs = _start(launch, ns, tmp_path / "out")
    node = procs[1]
    _calibrate_when_ready(spinner, ns, procs)
    workers = [p for p in psutil.Process(node.proc.pid).children(recursive=True) if not p.children()]
    assert workers, "no calibration worker process"
    for p in workers:
        p.kill()
    psutil.wait_procs(workers, timeout=10)
    resp = spinner.call(Trigger, f"{ns}/calibration_node/calibrate", timeout=START_TIMEOUT_S, procs=procs)
    assert not resp.success and "worker process ended" in resp.message, resp.message
    again = spinner.call(Trigger, f"{ns}/calibration_node/calibrate", timeout=START_TIMEOUT_S, procs=procs)
    assert again.success, again.message + "\n" + logs(*procs)
    assert all(p.alive() for p in procs), logs(*procs)


@pytest.mark.slow
def test_a_stopped_calibration_worker_times_out_and_is_replaced(launch, spinner, tmp_path):
    """A worker that stops answering (SIGSTOP here; a numerical library stuck in a loop alike)
    must not hold ~/calibrate for ever: after calibration.timeout it is killed and replaced."""
    import psutil

    ns = "/f6"
    # short, but beyond a calibration of the first views (3.1 s for 11 in a CI run, where the
    # depth of the simulator's moving board shows a sub-millimetre wiggle and it is fitted)
    timeout = 10
    procs = _start(launch, ns, tmp_path / "out", "-p", f"calibration.timeout:={timeout:.1f}")
    node = procs[1]
    _calibrate_when_ready(spinner, ns, procs)
    workers = [p for p in psutil.Process(node.proc.pid).children(recursive=True)
               if not p.children() and "resource_tracker" not in " ".join(p.cmdline())]
    assert workers, "no calibration worker process"
    for p in workers:
        p.suspend()
    t0 = time.monotonic()
    resp = spinner.call(Trigger, f"{ns}/calibration_node/calibrate", timeout=START_TIMEOUT_S, procs=procs)
    assert not resp.success and f"did not answer in {timeout} s" in resp.message, resp.message
    assert time.monotonic() - t0 < timeout + 17.0
    psutil.wait_procs(workers, timeout=10)
    assert not any(p.is_running() and p.status() != psutil.STATUS_ZOMBIE for p in workers), "the stopped worker lives"
    again = spinner.call(Trigger, f"{ns}/calibration_node/calibrate", timeout=START_TIMEOUT_S, procs=procs)
    assert again.success, again.message + "\n" + logs(*procs)


def test_a_burst_of_calls_from_three_clients_is_answered_whole(launch, spinner, tmp_path):
    """300 ~/calibrate calls at once from 3 clients: every one answered (here: too few views)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    node = launch("calibration_node", "-r", "__ns:=/f7", *BOARD, "-p", f"output_dir:={tmp_path / 'out'}")
    name = "/f7/calibration_node/calibrate"
    clients = [spinner.node.create_client(Trigger, name, qos_profile=QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.RELIABLE)) for _ in range(3)]
    for client in clients:   # each client's first answer may be lost to discovery (Spinner.call): warm it
        assert client.wait_for_service(timeout_sec=START_TIMEOUT_S), logs(node)
        wait_until(lambda c=client: answered(c, 2.0), START_TIMEOUT_S, "a first answer", node)
    futures = [client.call_async(Trigger.Request()) for client in clients for _ in range(100)]
    wait_until(lambda: all(f.done() for f in futures), 60.0,
               lambda: f"{sum(not f.done() for f in futures)} of 300 calls unanswered", node)
    assert all("views collected" in f.result().message for f in futures)
    assert node.proc.poll() is None




def test_malformed_frames_of_every_size_give_a_few_warnings(launch, spinner, tmp_path):
    """300 frame pairs whose amplitude and depth differ in size, each pair another size: the log
    says so a few times (once per kind per 5 s, with how many were held back), not 300 times."""
    from sensor_msgs.msg import Image

    node = launch("calibration_node", "-r", "__ns:=/f8", *BOARD, "-p", f"output_dir:={tmp_path / 'out'}",
                  "-p", "qos.reliable:=true")
    pubs = {topic: spinner.node.create_publisher(Image, f"/f8/{topic}", 10) for topic in ("amplitude", "depth")}
    wait_until(lambda: all(p.get_subscription_count() for p in pubs.values()), START_TIMEOUT_S, "subscribers", node)
    t0, i = time.monotonic(), 0
    while i < 300 or "more like it" not in logs(node):   # past one 5 s period: the held-back count shows
        w = 20 + i % 500
        for topic, width, encoding in (("amplitude", w, "mono16"), ("depth", w + 1, "16UC1")):
            msg = Image(height=10, width=width, encoding=encoding, step=width * 2, data=bytes(20 * width))
            msg.header.stamp.sec = 1000 + i
            pubs[topic].publish(msg)
        i += 1
        time.sleep(0.01)
        assert time.monotonic() - t0 < 60.0, "no warning counting the frames held back\n" + logs(node)
    seconds = time.monotonic() - t0
    warnings = [line for line in logs(node).splitlines() if "differ in size" in line]
    assert 1 <= len(warnings) <= seconds / 5.0 + 2, "\n".join(warnings)
