"""The no-hardware demo: the calibration node calibrates the simulated ToF camera over ROS 2.

    python -m tof_calib_ros.ros.demo [--camera pmd|azure] [--views 12] [--output DIR]

What a user does at sensor bring-up, scripted: start the camera driver (here ``tof_sim_node``, a
PMD-class 200x200 camera, or an Azure Kinect NFOV-like 640x576 one, whose factory calibration is
4 % off and whose depth has a 20 mm offset) and ``calibration_node``, as ``ros2 run`` would,
watch the views come in on /diagnostics, call ``~/calibrate`` until it succeeds, call
``~/commit`` so the driver stores the calibration, then compare with the simulator's truth.
Needs the package in the ament index (``pip install .[ros]``, as tools/setup_venv.sh does).
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from .. import sim
from ..collect.collector import LABELS
from ..files.calibration_file import read_camera_yaml
from ..sim.stream import CAMERAS, factory_K
from .processes import (
    NodeProcess,
    RosProcessError,
    Spinner,
    logs,
    ros_environment,
    wait_until,
)

START_TIMEOUT_S = 30.0
COLLECT_TIMEOUT_S = 240.0
BOARD = ("5", "7", "0.03")
DEPTH_OFFSET_M = 0.02


def _progress_printer(latest: dict):
    def on_diagnostics(msg) -> None:
        for status in msg.status:
            if status.name.startswith("/calibration_node"):
                values = {kv.key: kv.value for kv in status.values}
                if status.message.startswith("calibrating") and status.message != latest.get("stage"):
                    print(f"  ({status.message})", flush=True)   # the stage a running calibration is at
                if values.get("views") != latest.get("views"):
                    coverage = " ".join(f"{LABELS[k.split('.')[1]]} {v}" for k, v in values.items()
                                        if k.startswith("coverage."))
                    print(f"  views {values.get('views')}  (frames {values.get('frames')}; coverage {coverage})",
                          flush=True)
                latest.clear()
                latest.update(values, stage=status.message)
    return on_diagnostics


def _calibrate(spinner: Spinner, procs: tuple[NodeProcess, ...]) -> str:
    """Ask as a user would, until the node has enough views; its refusals say what is missing."""
    from std_srvs.srv import Trigger

    deadline = time.monotonic() + COLLECT_TIMEOUT_S
    while True:
        resp = spinner.call(Trigger, "/calibration_node/calibrate", timeout=START_TIMEOUT_S, procs=procs)
        if resp.success:
            return resp.message
        if time.monotonic() > deadline:
            raise RosProcessError(f"no calibration within {COLLECT_TIMEOUT_S:g} s; last answer: {resp.message}\n"
                                  + logs(*procs))
        time.sleep(2.0)


def _table(truth: sim.SimCamera, factory: np.ndarray, result: dict) -> str:
    K, D, std = np.array(result["camera_matrix"]), result["distortion_coefficients"], result["std"]
    rows = [("fx", truth.K[0, 0], factory[0, 0], K[0, 0]), ("fy", truth.K[1, 1], factory[1, 1], K[1, 1]),
            ("cx", truth.K[0, 2], factory[0, 2], K[0, 2]), ("cy", truth.K[1, 2], factory[1, 2], K[1, 2]),
            ("k1", truth.D[0], 0.0, D[0]), ("k2", truth.D[1], 0.0, D[1]), ("p1", truth.D[2], 0.0, D[2]),
            ("p2", truth.D[3], 0.0, D[3]),
            ("depth_offset", DEPTH_OFFSET_M, 0.0, result["depth_bias"]["depth_offset"])]
    lines = [f"{'':14}{'truth':>12}{'factory (driver)':>18}{'calibrated':>14}{'± std':>10}{'error/std':>11}"]
    for name, t, f, c in rows:
        s = std.get(name, 0.0)
        # a term the data did not call for is held at 0, not estimated: it has no error/std; one
        # the views leave free has an infinite std, which the file writes as null
        tail = f"{'unconstrained':>21}" if s is None else \
            f"{s:10.2g}{(c - t) / s:11.1f}" if s > 0 else f"{'held at 0':>21}"
        lines.append(f"{name:14}{t:12.4f}{f:18.4f}{c:14.4f}{tail}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--camera", choices=sorted(CAMERAS), default="pmd")
    ap.add_argument("--views", type=int, default=12, help="views to collect before calibrating (views.min)")
    ap.add_argument("--output", type=Path, help="where the nodes write (default: a temporary folder)")
    args = ap.parse_args(argv)

    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, Image
    from std_srvs.srv import Trigger

    # a domain the user set is kept, so they can watch the demo with their own tools
    mine = os.environ.get("ROS_DOMAIN_ID", "")
    env = ros_environment(int(mine) if mine.isdigit() else None)
    out = args.output or Path(tempfile.mkdtemp(prefix="tof_calib_demo_"))
    out.mkdir(parents=True, exist_ok=True)
    driver_file = out / "driver_camera_info.yaml"
    board = ["-p", f"board.cols:={BOARD[0]}", "-p", f"board.rows:={BOARD[1]}", "-p", f"board.square:={BOARD[2]}"]
    topics = ["-r", "amplitude:=/tof/amplitude", "-r", "depth:=/tof/depth", "-r", "camera_info:=/tof/camera_info"]
    print(f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}, discovery on localhost; logs and outputs in {out}")
    context = rclpy.Context()
    rclpy.init(context=context)
    procs: tuple[NodeProcess, ...] = ()
    spinner = None
    try:
        procs = (
            NodeProcess("tof_sim_node", [*topics, "-r", "set_camera_info:=/tof/set_camera_info", *board,
                                         "-p", f"camera:={args.camera}", "-p", f"depth.offset:={DEPTH_OFFSET_M}",
                                         "-p", f"calibration_file:={driver_file}"], out, env),
            NodeProcess("calibration_node", [*topics, "-p", "set_camera_info_service:=/tof/set_camera_info", *board,
                                             "-p", f"views.min:={args.views}", "-p", f"output_dir:={out}"], out, env),
        )
        spinner = Spinner(context, "tof_calib_demo")
        latest: dict = {}
        spinner.node.create_subscription(DiagnosticArray, "/diagnostics", _progress_printer(latest), 10)
        pictures: list = []   # what rqt_image_view would show of ~/board_image; the last one is saved
        spinner.node.create_subscription(Image, "/calibration_node/board_image", pictures.append, 2)
        print("$ ros2 run tof_calib_ros tof_sim_node ...   (the simulated camera)\n"
              "$ ros2 run tof_calib_ros calibration_node ...   (collecting views)")
        wait_until(lambda: latest, START_TIMEOUT_S, "the calibration node's first diagnostics", *procs)
        wait_until(lambda: int(latest.get("views", 0)) >= args.views, COLLECT_TIMEOUT_S,
                   lambda: f"{args.views} views (have {latest.get('views')}, last rejection "
                           f"{latest.get('last rejection')!r})", *procs, period=0.2)
        picture = _save_picture(pictures, out / "board_image.png")
        print("$ ros2 service call /calibration_node/calibrate std_srvs/srv/Trigger")
        print("  " + _calibrate(spinner, procs))

        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        infos: list = []
        spinner.node.create_subscription(CameraInfo, "/calibration_node/camera_info", infos.append, latched)
        info = wait_until(lambda: infos and infos[-1], START_TIMEOUT_S, "the latched CameraInfo", *procs)
        print(f"$ ros2 topic echo /calibration_node/camera_info\n  k: {[round(float(x), 3) for x in info.k]}\n"
              f"  d: {[round(float(x), 5) for x in info.d]}")
        print("$ ros2 service call /calibration_node/commit std_srvs/srv/Trigger")
        commit = spinner.call(Trigger, "/calibration_node/commit", timeout=START_TIMEOUT_S, procs=procs)
        print(f"  success={commit.success}: {commit.message}")

        truth = CAMERAS[args.camera]()
        factory = factory_K(truth)
        result = json.loads((out / "calibration.json").read_text())
        print(f"\n{truth.width}x{truth.height} px, {len(result['views'])} views, pixel RMS "
              f"{result['pixel_rms']:.3f} px, depth RMS {result['depth_rms_m'] * 1e3:.2f} mm\n")
        print(_table(truth, factory, result))
        stored = read_camera_yaml(driver_file) if driver_file.exists() else None
        same = stored is not None and np.allclose(stored.K, np.reshape(info.k, (3, 3)))
        print(f"\nthe driver now holds the calibration: {same} ({driver_file})")
        print(f"outputs: {out / 'calibration.yaml'}, {out / 'calibration.json'}, {out / 'views'}/"
              + (f", {picture} (~/board_image)" if picture else ""))
        return 0 if commit.success and result["verdict"]["ok"] and same else 1
    except RosProcessError as exc:
        print(f"demo failed: {exc}")
        return 1
    finally:
        if spinner is not None:
            spinner.close()
        for p in procs:
            p.stop()
        rclpy.shutdown(context=context)


def _save_picture(pictures: list, path: Path) -> Path | None:
    """The last ~/board_image as a PNG (bgr8, as OpenCV writes it)."""
    if not pictures:
        return None
    import cv2

    msg = pictures[-1]
    image = np.frombuffer(bytes(msg.data), np.uint8).reshape(msg.height, msg.width, 3)
    return path if cv2.imwrite(str(path), image) else None


if __name__ == "__main__":
    raise SystemExit(main())
