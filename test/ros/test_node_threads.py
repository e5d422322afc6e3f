"""The calibration node's threads, with the node built in this process (no `ros2 run`): what
its worker leaves to another thread is done there."""
from __future__ import annotations

import threading

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 wheels are not installed (pip install .[ros,test])")

from rclpy.parameter import Parameter  # noqa: E402
from ros_helpers import wait_until  # noqa: E402

from tof_calib_ros import View, calibrate, sim  # noqa: E402
from tof_calib_ros.collect import tracking  # noqa: E402
from tof_calib_ros.collect.collector import WHAT_TO_DO, still_short  # noqa: E402
from tof_calib_ros.ros import node as node_module  # noqa: E402
from tof_calib_ros.ros.calibration_worker import CalibrationWorker  # noqa: E402


def test_the_worker_leaves_a_kept_view_s_accurate_corners_to_the_sharpening_thread(ros, monkeypatch):
    found = []   # (thread name, detection), as the node's accurate detections come

    def recorded(amplitude, board, quick):
        found.append((threading.current_thread().name, tracking.accurate_detect(amplitude, board, quick)))
        return found[-1][1]

    monkeypatch.setattr(node_module, "accurate_detect", recorded)
    node = node_module.CalibrationNode(context=ros[1])
    try:
        camera, rng = sim.pmd_camera(), np.random.default_rng(4)
        frames = [sim.render(camera, node.board, *pose, rng=rng)
                  for pose in sim.random_poses(camera, node.board, 3, rng, max_tilt_deg=25)]
        for i, f in enumerate(frames):   # as the worker judges a frame from the topics
            node._judge(f.amplitude, f.depth, float(i), node._generation, thorough=True)
        assert len(node.collector) == 3

        def sharpened() -> bool:
            with node._lock:
                return not node.collector.unsharpened()

        wait_until(sharpened, 20.0, "the kept views' accurate corners")
        assert [name.startswith("sharpen_views") for name, _ in found] == [True] * 3
        with node._lock:
            views = node.collector.views
        assert all(np.array_equal(v.corners, d.corners) for v, (_, d) in zip(views, found))
        assert len(found) == 3   # reading the views found nothing more
    finally:
        node.destroy_node()


def _frames(board, n: int, seed: int):
    camera, rng = sim.pmd_camera(), np.random.default_rng(seed)
    noise = sim.Noise(depth=0.003, offset=0.02)
    return [sim.render(camera, board, *pose, noise=noise, rng=rng)
            for pose in sim.random_poses(camera, board, n, rng, distance=(0.4, 0.9), max_tilt_deg=40)]


def test_the_worker_passes_on_the_stages_calibrate_reaches_and_only_its_own_call_s(ros):
    from tof_calib_ros import Board

    board = Board(5, 7, 0.03)
    views = [View(f.depth, f.corners) for f in _frames(board, 8, 3)]
    worker = CalibrationWorker()
    try:
        for some in (views, views[:6]):   # a second call hears none of the first's
            here: list[str] = []
            expected = calibrate(some, board, progress=here.append)
            there: list[str] = []
            result = worker.calibrate(some, board, progress=there.append)
            assert there == here and len(here) >= 4, (there, here)
            np.testing.assert_array_equal(result.K, expected.K)
    finally:
        worker.close()


def test_the_diagnostics_show_a_running_calibration_s_stage_then_its_result(ros, tmp_path):
    node = node_module.CalibrationNode(context=ros[1], parameter_overrides=[
        Parameter("views.min", value=8), Parameter("output_dir", value=str(tmp_path))])
    try:
        for i, f in enumerate(_frames(node.board, 8, 5)):
            node._judge(f.amplitude, f.depth, float(i), node._generation, thorough=True)
        n = len(node.collector)
        # short of coverage: the diagnostics and a refusal say where and what to do
        short = still_short(node.collector.progress())
        assert n >= 8 and any(what in short for what in WHAT_TO_DO.values()), short
        assert node.status().message == f"collecting views ({n} of at least 8): {short}"
        node.received, node.paired = [n, n], n   # as if the frames had come on the topics
        assert node._too_few(n, 20) == (f"only {n} views collected, need 20: {short} "
                                        f"(last rejection: {node.last_problem or 'none'})")
        seen: list[str] = []
        answer: list = []
        calibration = threading.Thread(target=lambda: answer.append(node._calibrate()))
        calibration.start()
        while calibration.is_alive():   # as the 1 Hz diagnostics would, only more often
            seen.append(node.status().message)
            calibration.join(0.05)
        assert answer[0][0], answer
        running = [m for m in seen if m.startswith(f"calibrating {n} views (")]
        assert any("s): traditional calibration: fx=" in m for m in running), seen
        assert len({m.split("): ", 1)[1] for m in running}) >= 3, seen   # the stage moves on as it runs
        assert node.status().message.startswith("calibrated (fx=")
    finally:
        node.destroy_node()


def test_the_diagnostics_say_a_full_set_is_enough_and_what_would_still_help(ros):
    # views.max 6 below camera_calibration's 40: the full set is enough, axes short or not
    node = node_module.CalibrationNode(context=ros[1], parameter_overrides=[
        Parameter("views.min", value=3), Parameter("views.max", value=6)])
    try:
        for i, f in enumerate(_frames(node.board, 10, 5)):
            node._judge(f.amplitude, f.depth, float(i), node._generation, thorough=True)
        short = still_short(node.collector.progress())
        assert len(node.collector) == 6 and short, short
        status = node.status()
        assert status.level == node_module.DiagnosticStatus.OK
        assert status.message == f"enough views to calibrate (6); more would still help: {short}"
    finally:
        node.destroy_node()
