"""The calibration node: collects views from a ToF camera's amplitude and depth topics,
calibrates on request, publishes the CameraInfo and commits it to the driver.

    ros2 run tof_calib_ros calibration_node --ros-args \\
        -r amplitude:=/tof/amplitude/image_raw -r depth:=/tof/depth/image_raw \\
        -p board.cols:=5 -p board.rows:=7 -p board.square:=0.03

Threads: subscriptions only pair frames and queue them (``QUEUE_PAIRS`` deep, the oldest dropped),
so the executor never falls behind the camera; one worker thread detects boards and collects views
(a board held still is followed from frame to frame, not searched for anew); services run in
their own callback group, so a calibration never blocks the topics. The calibration itself runs
in a worker process (``CalibrationWorker``), out of reach of the frames' share of the GIL, while
a thread encodes the views' files. While it runs, the view worker drops the frames (counted as
dropped): the calibration could not use their views, and gets the CPU instead.
"""
from __future__ import annotations

import re
import threading
import time
import traceback
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image
from sensor_msgs.srv import SetCameraInfo
from std_srvs.srv import Trigger

from . import Board, CalibrationError, CalibrationResult
from .bag_io import BagError, BagSource
from .calibration_file import EncodedViews, encode_views
from .calibration_worker import CalibrationWorker
from .collector import CollectorConfig, ViewCollector
from .image_decode import ImageError, decode_image, depth_to_metres
from .output_folder import write_calibration
from .replay import FrameError, Skip, decode_sized
from .ros_run import Executor, run
from .stamp_sync import StampSync
from .tracking import BoardTracker

COMMIT_TIMEOUT_S = 5.0
# how a user of the node names the bag's topics, for the errors of bag_io.choose_topics
BAG_FLAGS = {"amplitude": "parameter bag.amplitude_topic", "depth": "parameter bag.depth_topic",
             "camera_info": "tof_calib bag --camera-info-topic (the node takes the bag's only one)"}
WARN_PERIOD_S = 5.0
# Requests wait here while the executor's threads are busy: with the default depth of 10, a burst
# of calls (300 from 3 clients) lost half of them unanswered. Each one is answered, at worst with
# "already running".
SERVICE_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
# Pairs waiting for the view worker. A search of the whole image for a lost board takes up to a
# quarter of a second at 640x576 (8 frames at 30 Hz) where following it takes 1 ms: the queue
# rides out those, and bounds the lag and the memory (12 MB of 640x576 16-bit pairs) when the
# camera is faster than the search for good. Two deep, it dropped 7 % of 30 Hz 640x576 frames.
QUEUE_PAIRS = 8
# camera_info_manager (and so write_camera_yaml) accepts no other camera name
CAMERA_NAME = re.compile(r"[A-Za-z0-9_]+")


def _descriptor(text: str, read_only: bool = False, ints: tuple[int, int] | None = None,
                floats: tuple[float, float] | None = None) -> ParameterDescriptor:
    d = ParameterDescriptor(description=text, read_only=read_only)
    if ints:
        d.integer_range = [IntegerRange(from_value=ints[0], to_value=ints[1], step=1)]
    if floats:
        d.floating_point_range = [FloatingPointRange(from_value=floats[0], to_value=floats[1], step=0.0)]
    return d


# name: (default, descriptor). Board and QoS changes need a restart: they are read-only.
PARAMETERS = {
    "board.cols": (5, _descriptor("interior corners per row (as camera_calibration counts them)", True, (3, 100))),
    "board.rows": (7, _descriptor("interior corners per column", True, (3, 100))),
    "board.square": (0.03, _descriptor("square size, metres", True, floats=(0.001, 1.0))),
    "depth.convention": ("z", _descriptor("'z' (REP 118, along the optical axis) or 'radial' (raw PMD)")),
    "depth.scale": (0.001, _descriptor("metres per unit of 16UC1 depth (0.001: millimetres)",
                                       floats=(1e-6, 10.0))),
    "sync.slop": (0.02, _descriptor("largest stamp difference of a paired amplitude and depth frame, s",
                                    floats=(0.0, 1.0))),
    "views.min": (8, _descriptor("views needed before calibrating", ints=(3, 1000))),
    "views.max": (60, _descriptor("views kept at most (memory stays bounded)", True, (3, 1000))),
    "motion.exposure": (CollectorConfig.exposure_s, _descriptor(
        "how long a frame is exposed (all its phases), s: the board's speed times this is its blur", True,
        floats=(1e-5, 1.0))),
    "motion.max_blur_px": (CollectorConfig.max_blur_px, _descriptor(
        "a frame whose board moved farther than this while it was exposed is not a view, px", True,
        floats=(0.1, 100.0))),
    "calibration.timeout": (120.0, _descriptor(
        "seconds a calibration may take before its worker process is taken for stuck, killed and replaced",
        floats=(1.0, 3600.0))),
    "camera_name": ("tof_camera", _descriptor("camera_name written into the calibration file")),
    "output_dir": ("~/.ros/tof_calib", _descriptor("where calibration.yaml, calibration.json and views/ go")),
    "set_camera_info_service": ("set_camera_info", _descriptor("the driver's sensor_msgs/SetCameraInfo service",
                                                               True)),
    "qos.reliable": (False, _descriptor("subscribe reliably instead of best effort (sensor data)", True)),
    "bag.path": ("", _descriptor("a recording (rosbag2 folder, sqlite3 or mcap, or ROS 1 .bag) to collect views "
                                 "from instead of the topics; calibrated once replayed", True)),
    "bag.amplitude_topic": ("", _descriptor("the bag's amplitude topic; empty: found by type and name", True)),
    "bag.depth_topic": ("", _descriptor("the bag's depth topic; empty: found by type and name", True)),
}


class _RateLimitedLog:
    """One warning per kind of problem per period, saying how many like it were held back: a
    bad stream must not flood the log, and frames that each fail differently (their sizes, their
    stamps) are one problem. The kinds are the node's own few, so memory stays bounded."""

    def __init__(self, logger, period: float):
        self._logger, self._period = logger, period
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}

    def warn(self, kind: str, text: str) -> None:
        now = time.monotonic()
        if now - self._last.get(kind, -1e9) < self._period:
            self._held[kind] = self._held.get(kind, 0) + 1
            return
        held = self._held.pop(kind, 0)
        self._last[kind] = now
        self._logger.warning(text + (f" ({held} more like it in the last {self._period:g} s)" if held else ""))


class CalibrationNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("calibration_node", **kwargs)
        # Registered first, so a bad -p override fails at declaration with the same reason a
        # bad set_parameters call gets, instead of at the first calibration.
        self.add_on_set_parameters_callback(self._check_parameters)
        for name, (default, desc) in PARAMETERS.items():
            self.declare_parameter(name, default, desc)
        p = self._param
        self.board = Board(p("board.cols"), p("board.rows"), p("board.square"))
        self.collector = ViewCollector(self.board, CollectorConfig(max_views=p("views.max"), min_views=p("views.min"),
                                                                   exposure_s=p("motion.exposure"),
                                                                   max_blur_px=p("motion.max_blur_px")))
        self.sync = StampSync(p("sync.slop"))
        self._sync_lock = threading.Lock()     # the topics pair frames while ~/reset clears them
        self._warn = _RateLimitedLog(self.get_logger(), WARN_PERIOD_S)
        self._lock = threading.Lock()          # the collector and the counters
        self._frames: deque = deque(maxlen=QUEUE_PAIRS)  # paired frames waiting for the worker
        self._wake = threading.Condition()
        self._calibrating = threading.Lock()
        self._calibrator = CalibrationWorker()
        self._encoder = ThreadPoolExecutor(1, thread_name_prefix="encode_views")
        self._stop = False
        self._generation = 0                   # counts resets: a frame from before one is not collected
        self._tracker = BoardTracker(self.board)   # where to look for the board first (worker thread only)
        self.result: CalibrationResult | None = None
        self.driver_info: CameraInfo | None = None
        self.frame_id = ""
        self.dropped = 0
        self.received = [0, 0]                 # frames that arrived on amplitude and on depth
        self.paired = 0
        self.last_problem = ""
        self.bag_topics: dict[str, str] = {}   # the bag's, when replaying one

        qos = qos_profile_sensor_data
        if p("qos.reliable"):
            qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE)
        topics = MutuallyExclusiveCallbackGroup()
        bag = p("bag.path")
        if not bag:
            self.create_subscription(Image, "amplitude", lambda m: self._on_image(0, m), qos, callback_group=topics)
            self.create_subscription(Image, "depth", lambda m: self._on_image(1, m), qos, callback_group=topics)
            self.create_subscription(CameraInfo, "camera_info", self._on_camera_info, qos, callback_group=topics)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.info_pub = self.create_publisher(CameraInfo, "~/camera_info", latched)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        services = ReentrantCallbackGroup()
        for name, callback in (("~/calibrate", self._on_calibrate), ("~/reset", self._on_reset),
                               ("~/commit", self._on_commit)):
            self.create_service(Trigger, name, callback, qos_profile=SERVICE_QOS, callback_group=services)
        self.driver = self.create_client(SetCameraInfo, p("set_camera_info_service"), callback_group=services)
        self.create_timer(1.0, self._publish_diagnostics, callback_group=topics)
        self.add_post_set_parameters_callback(self._apply_parameters)
        if bag:
            self._worker = threading.Thread(target=self._replay, args=(bag,), name="bag_replay", daemon=True)
            source = f"the recording {bag}"
        else:
            self._worker = threading.Thread(target=self._work, name="view_collector", daemon=True)
            source = f"'{self.resolve_topic_name('amplitude')}' and '{self.resolve_topic_name('depth')}'"
        self.get_logger().info(f"collecting views of a {self.board.cols}x{self.board.rows} board "
                               f"({self.board.square * 1e3:g} mm) from {source}")
        self._worker.start()

    def _param(self, name: str):
        return self.get_parameter(name).value

    def _check_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Only checks (it also runs at declaration, before the node is built); a rejected
        value must not touch the node, so ``_apply_parameters`` applies them afterwards."""
        new = {prm.name: prm.value for prm in params}

        def value(name: str):
            return new[name] if name in new else self.get_parameter_or(name).value

        for name, v in new.items():
            reason = None
            if name == "depth.convention" and v not in ("z", "radial"):
                reason = f"depth.convention must be 'z' or 'radial', not {v!r}"
            elif name == "camera_name" and not (isinstance(v, str) and CAMERA_NAME.fullmatch(v)):
                reason = (f"camera_name must be letters, digits and '_' (camera_info_manager refuses "
                          f"anything else), not {v!r}")
            elif name == "output_dir" and not str(v).strip():
                reason = "output_dir must not be empty"
            elif name in ("views.min", "views.max"):
                lo, hi = value("views.min"), value("views.max")
                if lo is not None and hi is not None and lo > hi:
                    reason = f"views.min ({lo}) must not exceed views.max ({hi}): calibration could never start"
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params: list[Parameter]) -> None:
        """What changes take effect beyond being read when used (the others are read per frame
        or per calibration)."""
        for prm in params:
            if prm.name == "sync.slop":
                with self._sync_lock:
                    self.sync.slop = float(prm.value)
            elif prm.name == "views.min":
                with self._lock:   # the diagnostics' good_enough follows it
                    self.collector.config = replace(self.collector.config, min_views=int(prm.value))

    # -- topics ------------------------------------------------------------------------------
    def _on_image(self, stream: int, msg: Image) -> None:
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        with self._sync_lock:
            self.received[stream] += 1
            pair = self.sync.add(stream, stamp, msg)
        if pair is None:
            return
        self.paired += 1
        with self._wake:
            if len(self._frames) == self._frames.maxlen:
                self.dropped += 1
            self._frames.append(pair)
            self._wake.notify()

    def _on_camera_info(self, msg: CameraInfo) -> None:
        self.driver_info = msg

    def _work(self) -> None:
        while True:
            with self._wake:
                while not self._frames and not self._stop:
                    self._wake.wait()
                if self._stop:
                    return
                amplitude_msg, depth_msg = self._frames.popleft()
                generation = self._generation
                idle = not self._frames   # no frame waiting: time to search the whole image for a lost board
                if self._calibrating.locked():
                    # the running calibration cannot use a new view: leave it the CPU (and the GIL)
                    self.dropped += 1
                    continue
            try:
                self._collect(amplitude_msg, depth_msg, generation, idle)
            except Exception as exc:  # noqa: BLE001 - a bad frame must never end the worker
                self._problem("internal", f"frame skipped: {exc}")

    def _collect(self, amplitude_msg: Image, depth_msg: Image, generation: int, thorough: bool) -> None:
        try:
            amplitude = decode_image(amplitude_msg)
            depth = depth_to_metres(decode_image(depth_msg), depth_msg.encoding, self._param("depth.scale"))
        except ImageError as exc:
            self._problem("decode", f"frame skipped: {exc}")
            return
        if amplitude.shape != depth.shape:
            self._problem("size", f"frame skipped: amplitude {amplitude.shape[1]}x{amplitude.shape[0]} and depth "
                          f"{depth.shape[1]}x{depth.shape[0]} differ in size")
            return
        info = self.driver_info
        if info is not None and (info.width, info.height) not in ((0, 0), (depth.shape[1], depth.shape[0])):
            self._problem("size", f"frame skipped: images are {depth.shape[1]}x{depth.shape[0]} but camera_info says "
                          f"{info.width}x{info.height}")
            return
        self.frame_id = depth_msg.header.frame_id or amplitude_msg.header.frame_id
        stamp = depth_msg.header.stamp.sec + depth_msg.header.stamp.nanosec * 1e-9
        self._judge(amplitude, depth, stamp, generation, thorough)

    def _judge(self, amplitude: np.ndarray, depth: np.ndarray, stamp: float, generation: int,
               thorough: bool) -> None:
        """A decoded pair, live or replayed, to the collector."""
        # A board held still is followed from the last frames (about 1 ms) instead of searched for
        # in the whole image (10 to 90 ms): the difference between keeping up with the camera or not.
        # A lost board is searched for thoroughly only when no frame waits (``thorough``).
        found = self._tracker.locate(amplitude, thorough=thorough)
        with self._lock:
            if generation != self._generation:
                return
            outcome = self.collector.add(amplitude, depth, stamp, located=found)
        if outcome.accepted:
            self.get_logger().info(outcome.reason)
        else:
            self.last_problem = outcome.reason

    def _replay(self, path: str) -> None:
        """Feed the collector from a bag, as fast as it reads, then calibrate as ~/calibrate would."""
        log = self.get_logger()
        p = self._param
        frames = skipped = 0
        try:
            with BagSource(Path(path).expanduser(), amplitude=p("bag.amplitude_topic") or None,
                           depth=p("bag.depth_topic") or None, slop=p("sync.slop"), depth_scale=p("depth.scale"),
                           flags=BAG_FLAGS) as bag:
                t = bag.topics
                self.bag_topics = {"amplitude": t.amplitude, "depth": t.depth}
                log.info(f"replaying {bag.path} ({bag.storage}, {bag.frame_count} amplitude messages): "
                         f"amplitude {t.amplitude} ({t.how['amplitude']}), depth {t.depth} ({t.how['depth']})")
                size = None if bag.camera_info is None else (bag.camera_info.width, bag.camera_info.height)
                for item in bag.frames():
                    if self._stop:
                        return
                    if isinstance(item, Skip):
                        skipped += 1
                        self._problem(item.kind, f"message skipped ({item.kind}): {item.where}: {item.reason}")
                        continue
                    try:
                        amplitude, depth = decode_sized(item, size)
                    except (FrameError, ImageError) as exc:
                        skipped += 1
                        self._problem(getattr(exc, "kind", "decode"), f"frame skipped: {item.where}: {exc}")
                        continue
                    self.frame_id = item.depth.frame_id or item.amplitude.frame_id
                    frames += 1
                    self._judge(amplitude, depth, item.stamp, self._generation, thorough=True)
        except BagError as exc:
            self._problem("replay", f"cannot replay the bag: {exc}")
            log.error(f"cannot replay the bag: {exc}")
            return
        except Exception as exc:  # noqa: BLE001 - a damaged bag must not end the node
            self._problem("replay", f"bag replay stopped: {exc!r}")
            log.error(f"bag replay stopped: {exc!r}\n{traceback.format_exc()}")
            return
        with self._lock:
            n = len(self.collector.views)
        log.info(f"replayed {path}: {frames} frame pairs, {skipped} skipped, {n} views kept")
        success, message = self._calibrate()
        (log.info if success else log.error)(f"calibration of the replayed bag: {message}")

    def _problem(self, kind: str, text: str) -> None:
        self.last_problem = text
        self._warn.warn(kind, text)

    # -- services ----------------------------------------------------------------------------
    def _on_calibrate(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        resp.success, resp.message = self._calibrate()
        return resp

    def _calibrate(self) -> tuple[bool, str]:
        """Calibrate on the views collected; publish and write only a trusted result."""
        if not self._calibrating.acquire(blocking=False):
            return False, "a calibration is already running; call again when it is done"
        try:
            with self._lock:
                views = list(self.collector.views)
            need = self._param("views.min")
            if len(views) < need:
                return False, self._too_few(len(views), need)
            t0 = time.monotonic()
            encoded = self._encoder.submit(encode_views, views)   # the files, while the worker calibrates
            try:
                result = self._calibrator.calibrate(views, self.board,
                                                    (views[0].depth.shape[1], views[0].depth.shape[0]),
                                                    self._param("depth.convention"),
                                                    timeout=self._param("calibration.timeout"))
            except CalibrationError as exc:
                return False, f"calibration failed: {exc}"
            except Exception as exc:  # noqa: BLE001 - an exception here would end the node and its views
                self.get_logger().error(f"calibration raised {exc!r}:\n{traceback.format_exc()}")
                return False, f"calibration failed (internal error): {exc!r}"
            if not result.ok:
                return False, "calibration not trusted, nothing published or written: " + "; ".join(result.verdict)
            try:
                self._write(result, encoded.result())
            except (CalibrationError, OSError) as exc:   # output_dir unwritable or not a directory, disk full
                return False, f"calibrated but not saved, nothing published: {exc}"
            self.result = result
            self.info_pub.publish(self.camera_info(result))
            message = self._summary(result, len(views), time.monotonic() - t0)
            self.get_logger().info(message)
            return True, message
        finally:
            self._calibrating.release()

    def _too_few(self, n: int, need: int) -> str:
        """Why there are too few views, starting from the first thing missing."""
        head = f"only {n} views collected, need {need}: "
        if not self._param("bag.path"):
            topics = [self.resolve_topic_name(t) for t in ("amplitude", "depth")]
            missing = [t for t, count in zip(topics, self.received) if count == 0]
            if missing:
                return head + (f"no frame has arrived on {' or '.join(map(repr, missing))}"
                               + (f" (frames do arrive on {[t for t in topics if t not in missing][0]!r})"
                                  if len(missing) == 1 else "")
                               + ": check the remaps (--ros-args -r amplitude:=... -r depth:=...) and that the "
                               "camera publishes")
            if self.paired == 0:
                return head + (f"{self.received[0]} amplitude and {self.received[1]} depth frames arrived but none "
                               f"pair: their header stamps differ by more than sync.slop "
                               f"({self._param('sync.slop'):g} s)")
        return head + ("move the board to new positions, distances and tilts (last rejection: "
                       f"{self.last_problem or 'none'})")

    def _write(self, result: CalibrationResult, views: EncodedViews) -> None:
        # what it takes to recalibrate from views/ or to trace the result back to its source
        b = self.board
        extra = {"board": {"cols": b.cols, "rows": b.rows, "square_m": b.square},
                 "camera_name": self._param("camera_name"), "frame_id": self.frame_id,
                 "topics": {"amplitude": self.resolve_topic_name("amplitude"),
                            "depth": self.resolve_topic_name("depth")}}
        if self._param("bag.path"):
            extra["topics"] = {"bag": self._param("bag.path"), **self.bag_topics}
        write_calibration(str(self._param("output_dir")), result, views, self._param("camera_name"), extra)

    @staticmethod
    def _summary(result: CalibrationResult, n_views: int, seconds: float) -> str:
        s = result.std
        return (f"fx={result.K[0, 0]:.2f}±{s['fx']:.2f} fy={result.K[1, 1]:.2f}±{s['fy']:.2f} "
                f"cx={result.K[0, 2]:.2f}±{s['cx']:.2f} cy={result.K[1, 2]:.2f}±{s['cy']:.2f} px; "
                f"pixel RMS {result.pixel_rms:.3f} px, depth RMS {result.depth_rms * 1e3:.2f} mm, "
                f"depth offset {result.depth_offset * 1e3:.1f} mm; {len(result.views)} of {n_views} views "
                f"used; {seconds:.1f} s")

    def camera_info(self, result: CalibrationResult) -> CameraInfo:
        msg = CameraInfo()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.frame_id
        msg.width, msg.height = int(result.image_size[0]), int(result.image_size[1])
        msg.distortion_model = "plumb_bob"
        msg.d = [float(x) for x in result.D]
        msg.k = [float(x) for x in result.K.ravel()]
        msg.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        msg.p = [float(x) for x in np.hstack([result.K, np.zeros((3, 1))]).ravel()]
        return msg

    def _on_reset(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        with self._sync_lock:
            self.sync.clear()
        with self._lock, self._wake:   # frames paired before the reset are not to be collected after it
            self._frames.clear()
            self._generation += 1
            n = len(self.collector.views)
            self.collector.reset()
        self.last_problem = ""
        resp.success, resp.message = True, f"cleared {n} views"
        return resp

    def _on_commit(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        if self.result is None:
            resp.success, resp.message = False, "nothing to commit: call ~/calibrate first"
            return resp
        name = self.driver.srv_name
        if not self.driver.wait_for_service(timeout_sec=2.0):
            resp.success, resp.message = False, f"the driver's service {name} is not available"
            return resp
        done = threading.Event()
        future = self.driver.call_async(SetCameraInfo.Request(camera_info=self.camera_info(self.result)))
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(COMMIT_TIMEOUT_S):
            future.cancel()
            resp.success, resp.message = False, f"{name} did not answer within {COMMIT_TIMEOUT_S:g} s"
            return resp
        reply = future.result()
        resp.success = bool(reply.success)
        resp.message = f"{name}: {reply.status_message}"
        return resp

    # -- progress ----------------------------------------------------------------------------
    def _publish_diagnostics(self) -> None:
        with self._lock:
            progress = self.collector.progress()
        # the fully qualified name tells two cameras' calibration nodes apart
        status = DiagnosticStatus(name=f"{self.get_fully_qualified_name()}: view collection",
                                  hardware_id=self.frame_id)
        if self.result is not None:
            status.level = DiagnosticStatus.OK
            status.message = (f"calibrated (fx={self.result.K[0, 0]:.2f} fy={self.result.K[1, 1]:.2f}, "
                              f"{len(self.result.views)} views); still collecting")
        else:
            status.level = DiagnosticStatus.OK if progress["good_enough"] else DiagnosticStatus.WARN
            status.message = "enough views to calibrate" if progress["good_enough"] else "collecting views"
        values = {k: v for k, v in progress.items() if not isinstance(v, dict) and k != "last_reason"}
        values["frames received (amplitude, depth)"] = f"{self.received[0]}, {self.received[1]}"
        values.update({f"coverage.{k}": a["progress"] for k, a in progress["axes"].items()})
        values["frames dropped (worker busy)"] = self.dropped
        values["last rejection"] = self.last_problem
        status.values = [KeyValue(key=str(k), value=f"{v:.2f}" if isinstance(v, float) else str(v))
                         for k, v in values.items()]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)

    def destroy_node(self) -> None:
        with self._wake:
            self._stop = True
            self._wake.notify()
        self._worker.join(timeout=2.0)
        self._calibrator.close()
        self._encoder.shutdown(wait=False, cancel_futures=True)
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run("calibration_node", CalibrationNode, __doc__,
               {name: (default, desc.description) for name, (default, desc) in PARAMETERS.items()}, args,
               executor=lambda: Executor(num_threads=4))


if __name__ == "__main__":
    raise SystemExit(main())
