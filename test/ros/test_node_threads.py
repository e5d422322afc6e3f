"""The calibration node's threads, with the node built in this process (no `ros2 run`): what
its worker leaves to another thread is done there."""
from __future__ import annotations

import threading

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 wheels are not installed (pip install .[ros,test])")

from ros_helpers import wait_until  # noqa: E402

from tof_calib_ros import sim  # noqa: E402
from tof_calib_ros.collect import tracking  # noqa: E402
from tof_calib_ros.ros import node as node_module  # noqa: E402


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
