"""The ROS nodes as a user runs them: separate processes started as `ros2 run` does, driven
through their topics, services and parameters from rclpy.

Needs the package installed non-editable (pip install .[ros,test]), so that the ament index
and <prefix>/lib/tof_calib_ros hold it; skips otherwise. Each test starts its own nodes, in a
namespace of its own where it can, so a slow shutdown in one test never answers for another.
"""
from __future__ import annotations

import json
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="the ROS 2 wheels are not installed (pip install .[ros,test])")

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from ros_helpers import (  # noqa: E402
    RESEND_S,
    START_TIMEOUT_S,
    calibrating,
    call_together,
    logs,
    set_parameter,
    wait_until,
)
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from tof_calib_ros import sim  # noqa: E402
from tof_calib_ros.files.calibration_file import read_camera_yaml  # noqa: E402

CALIBRATE_TIMEOUT_S = 90.0


@pytest.mark.slow
def test_simulator_calibration_and_commit(launch, spinner, tmp_path):
    out, driver_file = tmp_path / "out", tmp_path / "driver.yaml"
    topics = ["-r", "amplitude:=/tof/amplitude", "-r", "depth:=/tof/depth", "-r", "camera_info:=/tof/camera_info"]
    simulator = launch("tof_sim_node", *topics, "-r", "set_camera_info:=/tof/set_camera_info",
                       "-p", "board.cols:=5", "-p", "board.rows:=7", "-p", "board.square:=0.03",
                       "-p", f"calibration_file:={driver_file}")
    node = launch("calibration_node", *topics, "-p", "set_camera_info_service:=/tof/set_camera_info",
                  "-p", "board.cols:=5", "-p", "board.rows:=7", "-p", "board.square:=0.03",
                  "-p", "views.min:=8", "-p", "views.max:=16", "-p", f"output_dir:={out}")
    procs = (simulator, node)

    # Calibrate as a user would: ask until enough views are in; a refusal says why.
    deadline = time.monotonic() + CALIBRATE_TIMEOUT_S
    answers = []
    while True:
        resp = spinner.call(Trigger, "/calibration_node/calibrate", timeout=CALIBRATE_TIMEOUT_S,
                            procs=procs, resend_after=RESEND_S, busy=calibrating)
        answers.append(resp.message)
        if resp.success:
            break
        assert resp.message, "a refused calibration must say why"
        if time.monotonic() > deadline:
            pytest.fail(f"no calibration within {CALIBRATE_TIMEOUT_S:g} s; answers:\n" + "\n".join(answers)
                        + "\n" + logs(*procs))
        time.sleep(1.0)
    assert "fx=" in resp.message and "views used" in resp.message, resp.message

    # Latched: a subscriber that comes after the calibration still gets it.
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    infos: list[CameraInfo] = []
    spinner.node.create_subscription(CameraInfo, "/calibration_node/camera_info", infos.append, latched)
    info = wait_until(lambda: infos and infos[-1], 15.0, "the latched CameraInfo", *procs)
    truth = sim.pmd_camera()
    K = np.reshape(info.k, (3, 3))
    assert (info.width, info.height) == (truth.width, truth.height)
    assert info.distortion_model == "plumb_bob" and len(info.d) == 5
    assert K[0, 0] == pytest.approx(truth.K[0, 0], rel=0.01) and K[1, 1] == pytest.approx(truth.K[1, 1], rel=0.01)
    assert abs(K[0, 2] - truth.K[0, 2]) < 2.0 and abs(K[1, 2] - truth.K[1, 2]) < 2.0, K
    assert np.allclose(np.reshape(info.p, (3, 4))[:, :3], K)

    saved = read_camera_yaml(out / "calibration.yaml")
    assert np.allclose(saved.K, K, rtol=1e-12) and (saved.width, saved.height) == (info.width, info.height)
    report = json.loads((out / "calibration.json").read_text())
    assert report["verdict"]["ok"] is True
    assert report["board"] == {"cols": 5, "rows": 7, "square_m": 0.03}, report["board"]
    assert report["topics"] == {"amplitude": "/tof/amplitude", "depth": "/tof/depth"}, report["topics"]
    n_views = len(list((out / "views").glob("*_ir.png")))
    assert n_views >= 8 and len(list((out / "views").glob("*_depth.png"))) == n_views

    # The diagnostics say it is calibrated (not "collecting views" at WARN); one key for the last rejection.
    statuses = []
    spinner.node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: statuses.extend(
        s for s in m.status if s.name == "/calibration_node: view collection"), 10)
    status = wait_until(lambda: next((s for s in reversed(statuses) if s.message.startswith("calibrated (fx=")),
                                     None), 15.0, "diagnostics saying calibrated", *procs)
    keys = [v.key for v in status.values]
    assert status.level == DiagnosticStatus.OK and "last rejection" in keys and "last_reason" not in keys, keys
    assert "accepted view" not in node.output() and "accepted as view 1\n" in node.output()   # said once
    assert "calibrating: traditional calibration: fx=" in node.output()   # each stage logged as reached

    # Two calibrations at once: both answered; one may be turned away, saying so.
    resps = call_together(spinner, "/calibration_node/calibrate", 2, 60.0, *procs)
    assert all(r.success or "already running" in r.message for r in resps), [r.message for r in resps]
    assert any(r.success for r in resps), [r.message for r in resps]   # not both turned away
    # the diagnostics (1 Hz) showed the stage of the calibration, which takes seconds, while it ran
    wait_until(lambda: any(s.message.startswith("calibrating ") and "views (" in s.message for s in statuses), 5.0,
               lambda: f"diagnostics showing a running calibration (saw {[s.message for s in statuses][-5:]})",
               *procs)

    # A calibration that cannot be saved is refused with the reason; the node lives on.
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    assert set_parameter(spinner, "/calibration_node", "output_dir", str(blocker / "out"), procs) == (True, "")
    resp = spinner.call(Trigger, "/calibration_node/calibrate", timeout=60.0, procs=procs)
    assert not resp.success and "not saved" in resp.message and str(blocker) in resp.message, resp.message
    assert set_parameter(spinner, "/calibration_node", "output_dir", str(out), procs) == (True, "")

    # Commit: the driver's set_camera_info gets the calibration and answers for it.
    resp = spinner.call(Trigger, "/calibration_node/commit", timeout=30.0, procs=procs, resend_after=RESEND_S)
    assert resp.success, resp.message + "\n" + logs(*procs)
    assert resp.message.startswith("/tof/set_camera_info: ") and str(driver_file) in resp.message, resp.message
    stored = read_camera_yaml(driver_file)
    assert np.allclose(stored.K, read_camera_yaml(out / "calibration.yaml").K, rtol=1e-12)

    resp = spinner.call(Trigger, "/calibration_node/reset", timeout=10.0, procs=procs, resend_after=RESEND_S)
    assert resp.success and resp.message.startswith("cleared "), resp.message
    assert int(resp.message.split()[1]) >= 8, resp.message
    assert node.alive() and simulator.alive()


def _image(encoding: str, width: int, height: int, bytes_per_pixel: int, stamp: float, *,
           data_bytes: int | None = None, step: int | None = None) -> Image:
    msg = Image(encoding=encoding, width=width, height=height, is_bigendian=0)
    msg.step = width * bytes_per_pixel if step is None else step
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(stamp), int(round(stamp % 1 * 1e9))
    msg.header.frame_id = "test_frame"
    size = msg.step * height if data_bytes is None else data_bytes
    msg.data = np.random.default_rng(0).integers(0, 256, size, dtype=np.uint8).tobytes()
    return msg


@pytest.mark.slow
def test_bad_messages_are_reported_not_fatal(launch, spinner):
    node = launch("calibration_node", "-r", "__ns:=/t2")
    resp = spinner.call(Trigger, "/t2/calibration_node/reset", timeout=START_TIMEOUT_S,
                        procs=(node,), resend_after=RESEND_S)
    assert resp.success

    amplitude_pub = spinner.node.create_publisher(Image, "/t2/amplitude", 10)
    depth_pub = spinner.node.create_publisher(Image, "/t2/depth", 10)
    wait_until(lambda: amplitude_pub.get_subscription_count() and depth_pub.get_subscription_count(),
               START_TIMEOUT_S, "the node's image subscriptions", node)
    latest: list[dict[str, str]] = [{}]   # replaced whole by the spin thread, never half-updated

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for s in msg.status:
            if s.name.startswith("/t2/calibration_node"):
                latest[0] = {kv.key: kv.value for kv in s.values}

    spinner.node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)

    w, h = 32, 24
    cases = [  # (what, amplitude(stamp), depth(stamp), what 'last rejection' must say)
        ("rgb8 amplitude", lambda t: _image("rgb8", w, h, 3, t), lambda t: _image("16UC1", w, h, 2, t),
         "unsupported image encoding 'rgb8'"),
        ("data shorter than step x height", lambda t: _image("mono16", w, h, 2, t, data_bytes=w * h),
         lambda t: _image("16UC1", w, h, 2, t), "but step x height"),
        ("step less than a row", lambda t: _image("mono16", w, h, 2, t, step=w),
         lambda t: _image("16UC1", w, h, 2, t), "is less than width"),
        ("mono8 depth", lambda t: _image("mono16", w, h, 2, t), lambda t: _image("mono8", w, h, 1, t),
         "is not a depth encoding"),
        ("depth of another size", lambda t: _image("mono16", w, h, 2, t),
         lambda t: _image("16UC1", w + 8, h, 2, t), "differ in size"),
        ("no board in the image", lambda t: _image("mono16", w, h, 2, t), lambda t: _image("16UC1", w, h, 2, t),
         "board"),
    ]
    stamp = 1000.0
    malformed_sent = 0
    for what, amplitude, depth, expected in cases:
        def rejected() -> bool:
            nonlocal stamp, malformed_sent
            stamp += 1.0   # a new pair each time: best-effort delivery may lose one
            amplitude_pub.publish(amplitude(stamp))
            depth_pub.publish(depth(stamp))
            malformed_sent += what != "no board in the image"
            return expected in latest[0].get("last rejection", "")
        wait_until(rejected, 15.0, lambda: f"'{expected}' in the diagnostics' last rejection after {what} "
                   f"(last seen: {latest[0].get('last rejection')!r})", node, period=0.3)
    # Each malformed kind was skipped at least once and counted; a frame without a board is not malformed.
    skipped = int(latest[0].get("frames skipped (malformed)", "-1"))
    assert 5 <= skipped <= malformed_sent, (skipped, malformed_sent, latest[0])

    # A non-finite float amplitude must not end the worker either; the node then still answers.
    for _ in range(3):
        stamp += 1.0
        nan = _image("32FC1", w, h, 4, stamp)
        nan.data = np.full(w * h, np.nan, np.float32).tobytes()
        amplitude_pub.publish(nan)
        depth_pub.publish(_image("16UC1", w, h, 2, stamp))
    resp = spinner.call(Trigger, "/t2/calibration_node/reset", timeout=10.0, procs=(node,), resend_after=RESEND_S)
    assert resp.success and node.alive(), logs(node)
    status = latest[0]
    assert status.get("views") == "0" and int(status.get("frames", "0")) >= 1, status
    wait_until(lambda: "unsupported image encoding 'rgb8'" in node.output(), 5.0,
               "the rgb8 frame's warning in the log", node)


def test_services_answer_and_refuse_with_reasons(launch, spinner):
    node = launch("calibration_node", "-r", "__ns:=/t3", "-p", "views.min:=5")
    procs = (node,)
    resp = spinner.call(Trigger, "/t3/calibration_node/reset", timeout=START_TIMEOUT_S,
                        procs=procs, resend_after=RESEND_S)
    assert resp.success and resp.message == "cleared 0 views", resp.message
    resp = spinner.call(Trigger, "/t3/calibration_node/calibrate", timeout=10.0, procs=procs, resend_after=RESEND_S)
    # nothing publishes on its topics: the answer says so, and where it listens
    assert not resp.success and resp.message.startswith(
        "only 0 views collected, need 5: no frame has arrived on '/t3/amplitude' or '/t3/depth': check the remaps"), \
        resp.message
    resp = spinner.call(Trigger, "/t3/calibration_node/commit", timeout=10.0, procs=procs, resend_after=RESEND_S)
    assert not resp.success and "nothing to commit" in resp.message, resp.message
    for resp in call_together(spinner, "/t3/calibration_node/calibrate", 2, 10.0, *procs):
        assert not resp.success and ("only 0 views" in resp.message or "already running" in resp.message), \
            resp.message
    assert node.alive()


def test_parameters_are_checked(launch, spinner):
    node = launch("calibration_node", "-r", "__ns:=/t4")
    procs = (node,)

    def set_one(name: str, value) -> tuple[bool, str]:
        return set_parameter(spinner, "/t4/calibration_node", name, value, procs)

    ok, reason = set_one("depth.convention", "disparity")
    assert not ok and "depth.convention must be one of 'auto', 'z', 'radial'" in reason, reason
    ok, reason = set_one("board.cols", 6)
    assert not ok and "read-only" in reason, reason
    ok, reason = set_one("camera_name", "tof-camera")
    assert not ok and "camera_name" in reason, reason
    ok, reason = set_one("views.min", 100)       # views.max is 60
    assert not ok and "views.max" in reason, reason
    ok, reason = set_one("depth.convention", "radial")
    assert ok, reason
    ok, reason = set_one("sync.slop", 0.05)
    assert ok, reason
    assert node.alive()

    # The same check refuses a bad value given at start-up, with the reason, not at calibration.
    bad = launch("calibration_node", "-r", "__ns:=/t4b", "-p", "depth.convention:=disparity")
    wait_until(lambda: not bad.alive(), START_TIMEOUT_S, "the node to refuse depth.convention:=disparity")
    assert bad.proc.returncode == 1 and "must be one of 'auto', 'z', 'radial'" in bad.output(), logs(bad)


@pytest.mark.slow
def test_demo_calibrates_the_simulated_camera_and_commits(ros, tmp_path):
    """README command 1, as a user runs it."""
    import subprocess
    import sys

    env, _ = ros
    env = {k: v for k, v in env.items() if k != "ROS_DOMAIN_ID"}   # the demo picks its own
    run = subprocess.run([sys.executable, "-m", "tof_calib_ros.ros.demo", "--views", "10", "--output", str(tmp_path)],
                         capture_output=True, text=True, timeout=300, env=env)
    assert run.returncode == 0, run.stdout + run.stderr
    rows = {line.split()[0]: line.split() for line in run.stdout.splitlines() if line[:2] in ("fx", "fy")}
    truth = sim.pmd_camera().K
    assert float(rows["fx"][3]) == pytest.approx(truth[0, 0], rel=0.01), run.stdout
    assert float(rows["fy"][3]) == pytest.approx(truth[1, 1], rel=0.01), run.stdout
    assert "nan" not in run.stdout.split("error/std")[-1], run.stdout   # terms held at 0 say so
    assert "the driver now holds the calibration: True" in run.stdout
    assert np.allclose(read_camera_yaml(tmp_path / "driver_camera_info.yaml").K,
                       read_camera_yaml(tmp_path / "calibration.yaml").K)


@pytest.mark.slow
def test_bag_parameter_replays_a_recording_then_calibrates_and_publishes(launch, spinner, tmp_path):
    """`-p bag.path:=BAG`: views from a recording instead of the topics, then the usual
    calibration, CameraInfo and files, to the recording's ground truth."""
    from tof_calib_ros.sim.recording import FRAME_ID, Scene, truth_path, write_recording

    bag, out = tmp_path / "recording", tmp_path / "out"
    write_recording(bag, Scene(frames=240, hold=5, transit=5, seed=1), "mcap")
    truth = json.loads(truth_path(bag).read_text())
    node = launch("calibration_node", "-r", "__ns:=/b1", "-p", f"bag.path:={bag}", "-p", f"output_dir:={out}")
    infos: list[CameraInfo] = []
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    spinner.node.create_subscription(CameraInfo, "/b1/calibration_node/camera_info", infos.append, latched)
    info = wait_until(lambda: infos and infos[-1], CALIBRATE_TIMEOUT_S, "the calibration of the replayed bag", node)
    K, K_true = np.reshape(info.k, (3, 3)), np.array(truth["camera_matrix"])
    assert K[0, 0] == pytest.approx(K_true[0, 0], rel=0.005) and K[1, 1] == pytest.approx(K_true[1, 1], rel=0.005)
    assert abs(K[0, 2] - K_true[0, 2]) < 1.0 and abs(K[1, 2] - K_true[1, 2]) < 1.0, K
    assert info.header.frame_id == FRAME_ID
    np.testing.assert_allclose(read_camera_yaml(out / "calibration.yaml").K, K)
    assert "replayed" in node.tail() and node.alive()

    # A bag that cannot be read: said in the log and by ~/calibrate; the node stays up.
    broken = launch("calibration_node", "-r", "__ns:=/b2", "-p", f"bag.path:={tmp_path / 'no_such_bag'}")
    resp = spinner.call(Trigger, "/b2/calibration_node/calibrate", timeout=START_TIMEOUT_S, procs=(broken,),
                        resend_after=RESEND_S, busy=calibrating)
    assert not resp.success and "cannot replay the bag" in resp.message and "no such bag" in resp.message, \
        resp.message
    assert broken.alive()


@pytest.mark.slow
def test_a_board_that_never_stops_is_calibrated_live(launch, spinner, tmp_path):
    """A recording of a board waved without a pause, entering after a second without one,
    played to the node's topics at its own rate (10 frames/s), as a camera would: the views it
    keeps calibrate to the truth."""
    from tof_calib_ros.ros.processes import play
    from tof_calib_ros.sim.recording import Scene, truth_path, write_recording

    bag, out = tmp_path / "moving", tmp_path / "out"
    write_recording(bag, Scene(motion="continuous", rate=10.0, frames=200, lead_in=10, segment=1.5, seed=3,
                               camera_info="none"))
    truth = json.loads(truth_path(bag).read_text())
    node = launch("calibration_node", "-r", "__ns:=/m1", "-p", f"output_dir:={out}")
    assert play(spinner.node, "/m1", bag, 10.0, (node,)) == 200
    resp = spinner.call(Trigger, "/m1/calibration_node/calibrate", timeout=CALIBRATE_TIMEOUT_S, procs=(node,),
                        resend_after=RESEND_S, busy=calibrating)
    assert resp.success, resp.message + "\n" + logs(node)
    doc = json.loads((out / "calibration.json").read_text())
    K, K_true = np.array(doc["camera_matrix"]), np.array(truth["camera_matrix"])
    assert K[0, 0] == pytest.approx(K_true[0, 0], rel=0.01) and K[1, 1] == pytest.approx(K_true[1, 1], rel=0.01), K
    assert abs(K[0, 2] - K_true[0, 2]) < 1.0 and abs(K[1, 2] - K_true[1, 2]) < 1.0, K
    sharp = sum(f["board"] == "whole" and f["blur_px"] <= 1.5 for f in truth["per_frame"])
    assert len(doc["views"]) >= 0.8 * min(sharp, 60), (len(doc["views"]), sharp)
    assert node.alive()


def test_board_image_shows_the_detected_corners(launch, spinner):
    """~/board_image: the frame with the corners the node found drawn where the detector finds
    them, and the coverage panel; only while subscribed, at most PICTURE_HZ a second."""
    from rclpy.qos import qos_profile_sensor_data

    from tof_calib_ros import Board
    from tof_calib_ros.collect.board_picture import KEPT, PANEL_WIDTH, REFUSED, TEXT_BAND_PX, enlarged, scale_for
    from tof_calib_ros.core.detection import detect
    from tof_calib_ros.files.image_decode import decode_image
    from tof_calib_ros.ros.node import PICTURE_HZ

    ns = "/pic"
    camera = launch("tof_sim_node", "-r", f"__ns:={ns}", "-p", "rate:=15.0")
    node = launch("calibration_node", "-r", f"__ns:={ns}")
    frames, pictures = {}, []
    spinner.node.create_subscription(Image, f"{ns}/amplitude", lambda m: frames.__setitem__(
        m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, m), qos_profile_sensor_data)
    spinner.node.create_subscription(Image, f"{ns}/calibration_node/board_image",
                                     lambda m: pictures.append((time.monotonic(), m)), 10)
    seen = {"pictures": 0, "with their frame": 0, "checked": 0}

    def check_new_pictures() -> bool:
        """Check the pictures that came before this call; True once 3 showed a board. (A frame
        of the camera's best-effort stream may not reach this process: its picture is passed.)
        Only those: on a busy machine the detector runs slower than pictures come, and a loop
        over every new one never returned to the deadline."""
        end = len(pictures)
        while seen["pictures"] < end and seen["checked"] < 3:
            picture = pictures[seen["pictures"]][1]
            seen["pictures"] += 1
            stamp = picture.header.stamp.sec + picture.header.stamp.nanosec * 1e-9
            source = next((m for s, m in list(frames.items()) if abs(s - stamp) < 1e-6), None)
            if source is None:
                continue
            seen["with their frame"] += 1
            check(picture, decode_image(source))
        return seen["checked"] >= 3

    def check(picture, amplitude: np.ndarray) -> None:
        h, w = amplitude.shape
        k = scale_for(h)
        assert picture.encoding == "bgr8" and (picture.height, picture.width) == (k * h, k * w + PANEL_WIDTH)
        image = np.frombuffer(bytes(picture.data), np.uint8).reshape(picture.height, picture.width, 3).astype(int)
        found = detect(amplitude, Board(5, 7, 0.03)).corners
        if found is None:
            return
        drawn = np.zeros(image.shape[:2], bool)
        for colour in (KEPT, REFUSED):
            drawn |= np.abs(image - colour).max(axis=2) < 40
        if not drawn[TEXT_BAND_PX:, :k * w].any():
            return   # the node's live tracker found no board in this frame (it may miss what detect finds)
        for x, y in np.rint(enlarged(found, k)).astype(int):
            r = k + 4   # the ring's radius and width around the corner
            assert drawn[y - r:y + r + 1, x - r:x + r + 1].any(), f"no ring drawn at the detected corner ({x}, {y})"
        # and the rings are at the corners: no drawn pixel far from every detected corner (below the
        # reason's text band, which a refused frame writes in the ring's colour)
        ys, xs = np.nonzero(drawn[:, :k * w])
        xs, ys = xs[ys >= TEXT_BAND_PX], ys[ys >= TEXT_BAND_PX]
        far = np.min(np.hypot(xs[:, None] - enlarged(found, k)[None, :, 0],
                              ys[:, None] - enlarged(found, k)[None, :, 1]), axis=1) > 3 * k + 4
        assert far.mean() < 0.01, "rings drawn away from the detected corners"
        seen["checked"] += 1

    wait_until(check_new_pictures, 60.0, lambda: f"3 pictures of a board checked against the detector ({seen})",
               camera, node, period=0.2)
    times = [t for t, _ in pictures]
    assert len(times) - 1 <= PICTURE_HZ * (times[-1] - times[0]) + 1   # bounded rate


@pytest.mark.slow
def test_a_node_with_the_kinect_options_calibrates_the_kinect_views_as_tof_calib_does(launch, kinect_dir, tmp_path,
                                                                                     capsys):
    """One home for the settings: -p depth.bias:=offset+tilt reaches the node's calibration as
    --depth-bias offset+tilt reaches tof_calib's, and bag.path takes a folder of stills as
    `tof_calib images` does: the same views, the same result."""
    from tof_calib_ros.offline.cli import main

    assert main(["images", str(kinect_dir), "--size", "5x7", "--square", "0.03", "--depth-bias", "offset+tilt",
                 "--output", str(tmp_path / "cli")]) == 0, capsys.readouterr().err
    node = launch("calibration_node", "-r", "__ns:=/kinect", "-p", "board.cols:=5", "-p", "board.rows:=7",
                  "-p", "board.square:=0.03", "-p", f"bag.path:={kinect_dir}", "-p", "depth.bias:=offset+tilt",
                  "-p", f"output_dir:={tmp_path / 'node'}")
    wait_until(lambda: (tmp_path / "node" / "calibration.json").exists(), 180.0, "the node's calibration", node)
    ours, theirs = (json.loads((tmp_path / d / "calibration.json").read_text()) for d in ("node", "cli"))
    assert ours["depth_bias"]["depth_tilt_x"] != 0.0 and theirs["depth_bias"]["depth_tilt_x"] != 0.0   # tilt fitted
    assert len(ours["views"]) == len(theirs["views"])
    np.testing.assert_allclose(ours["camera_matrix"], theirs["camera_matrix"], rtol=1e-6)
