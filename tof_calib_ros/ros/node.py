"""The calibration node: collects views from a ToF camera's amplitude and depth topics,
calibrates on request, publishes the CameraInfo and commits it to the driver.

    ros2 run tof_calib_ros calibration_node --ros-args \\
        -r amplitude:=/tof/amplitude/image_raw -r depth:=/tof/depth/image_raw \\
        -p board.cols:=5 -p board.rows:=7 -p board.square:=0.03

Threads: subscriptions only pair frames and queue them (``QUEUE_PAIRS`` deep, the oldest dropped),
so the executor never falls behind the camera; one worker thread detects boards and collects views
(a board held still is followed from frame to frame, not searched for anew); services run in
their own callback group, so a calibration never blocks the topics. A kept view's accurate corners
are found in a thread of their own (``_sharpen``), while the worker judges the next frames. The calibration itself runs
in a worker process (``CalibrationWorker``), out of reach of the frames' share of the GIL, while
a thread encodes the views' files. While it runs, the view worker drops the frames (counted as
dropped): the calibration could not use their views, and gets the CPU instead.
"""
from __future__ import annotations

import itertools
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

from .. import Board, CalibrationError, CalibrationResult
from ..collect.board_picture import draw
from ..collect.collector import Outcome, ViewCollector, still_short
from ..collect.replay import Replay, Summary
from ..collect.stamp_sync import StampSync
from ..collect.tracking import BoardTracker, accurate_detect
from ..files.bag_io import BagError, BagFrame, BagSource, stamp_parts
from ..files.calibration_file import EncodedViews, encode_views, monocular_fields
from ..files.image_decode import ImageError, decode_image, depth_to_metres
from ..files.image_folder import is_image_folder, scan
from ..files.output_folder import write_calibration
from ..settings import LINKED, SETTINGS, Setting, calibration_options, collector_config, refusal
from .calibration_worker import CalibrationWorker
from .run import Executor, run

COMMIT_TIMEOUT_S = 5.0
# how a user of the node names the bag's topics, for the errors of bag_io.choose_topics
BAG_FLAGS = {"amplitude": "parameter bag.amplitude_topic", "depth": "parameter bag.depth_topic",
             "camera_info": "tof_calib bag --camera-info-topic (the node takes the bag's only one)"}
WARN_PERIOD_S = 5.0
PICTURE_HZ = 5.0   # ~/board_image at most this often: for a person's eyes, not every frame
# Requests wait here while the executor's threads are busy: with the default depth of 10, a burst
# of calls (300 from 3 clients) lost half of them unanswered. Each one is answered, at worst with
# "already running".
SERVICE_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
# Pairs waiting for the view worker. A search of the whole image for a lost board takes up to a
# quarter of a second at 640x576 (8 frames at 30 Hz) where following it takes 1 ms: the queue
# rides out those, and bounds the lag and the memory (12 MB of 640x576 16-bit pairs) when the
# camera is faster than the search for good. Two deep, it dropped 7 % of 30 Hz 640x576 frames.
QUEUE_PAIRS = 8


def _descriptor(setting: Setting) -> ParameterDescriptor:
    d = ParameterDescriptor(description=setting.text, read_only=setting.read_only)
    if setting.low is not None and isinstance(setting.default, int) and not isinstance(setting.default, bool):
        d.integer_range = [IntegerRange(from_value=int(setting.low), to_value=int(setting.high), step=1)]
    elif setting.low is not None:
        d.floating_point_range = [FloatingPointRange(from_value=float(setting.low), to_value=float(setting.high),
                                                     step=0.0)]
    return d


# name: (default, descriptor), from the settings tof_calib shares. Read-only ones need a restart.
PARAMETERS = {name: (s.default, _descriptor(s)) for name, s in SETTINGS.items()}


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
        # a folder of images is stills: no motion between them to judge
        stills = bool(p("bag.path")) and is_image_folder(Path(p("bag.path")).expanduser())
        self.collector = ViewCollector(self.board, collector_config(self._values(), stills=stills))
        self.sync = StampSync(p("sync.slop"))
        self._sync_lock = threading.Lock()     # the topics pair frames while ~/reset clears them
        self._warn = _RateLimitedLog(self.get_logger(), WARN_PERIOD_S)
        self._lock = threading.Lock()          # the collector and the counters
        self._frames: deque = deque(maxlen=QUEUE_PAIRS)  # paired frames waiting for the worker
        self._wake = threading.Condition()
        self._calibrating = threading.Lock()
        self._calibrator = CalibrationWorker()
        self._encoder = ThreadPoolExecutor(1, thread_name_prefix="encode_views")
        self._sharpener = ThreadPoolExecutor(1, thread_name_prefix="sharpen_views")
        self._stop = False
        self._generation = 0                   # counts resets: a frame from before one is not collected
        self._tracker = BoardTracker(self.board)   # where to look for the board first (worker thread only)
        self.result: CalibrationResult | None = None
        self.driver_info: CameraInfo | None = None
        self.frame_id = ""
        self.dropped = 0
        self.received = [0, 0]                 # frames that arrived on amplitude and on depth
        self.malformed = 0                     # pairs skipped as undecodable or of mismatched sizes
        self.paired = 0
        self.last_problem = ""
        self.bag_topics: dict[str, str] = {}   # the bag's, when replaying one
        self.calibrating: tuple[float, int, str] | None = None   # (start, views, stage) while a calibration runs

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
        self.picture_pub = self.create_publisher(Image, "~/board_image", 2)
        self._shown = 0.0
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

    def _values(self) -> dict:
        """Every setting's current value."""
        return {name: self._param(name) for name in SETTINGS}

    def _check_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Only checks (it also runs at declaration, before the node is built); a rejected
        value must not touch the node, so ``_apply_parameters`` applies them afterwards."""
        values = {prm.name: prm.value for prm in params if prm.name in SETTINGS}
        for pair in LINKED:   # checked together
            if any(name in values for name in pair):
                for name in pair:
                    if name not in values and self.has_parameter(name):
                        values[name] = self._param(name)
        reason = refusal(values)
        return SetParametersResult(successful=reason is None, reason=reason or "")

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
                self._skip("internal", f"frame skipped: {exc}")

    def _collect(self, amplitude_msg: Image, depth_msg: Image, generation: int, thorough: bool) -> None:
        try:
            amplitude = decode_image(amplitude_msg)
            depth = depth_to_metres(decode_image(depth_msg), depth_msg.encoding, self._param("depth.scale"))
        except ImageError as exc:
            self._skip("decode", f"frame skipped: {exc}")
            return
        if amplitude.shape != depth.shape:
            self._skip("size", f"frame skipped: amplitude {amplitude.shape[1]}x{amplitude.shape[0]} and depth "
                          f"{depth.shape[1]}x{depth.shape[0]} differ in size")
            return
        info = self.driver_info
        if info is not None and (info.width, info.height) not in ((0, 0), (depth.shape[1], depth.shape[0])):
            self._skip("size", f"frame skipped: images are {depth.shape[1]}x{depth.shape[0]} but camera_info says "
                          f"{info.width}x{info.height}")
            return
        self.frame_id = depth_msg.header.frame_id or amplitude_msg.header.frame_id
        stamp = depth_msg.header.stamp.sec + depth_msg.header.stamp.nanosec * 1e-9
        self._judge(amplitude, depth, stamp, generation, thorough)

    def _judge(self, amplitude: np.ndarray, depth: np.ndarray, stamp: float, generation: int,
               thorough: bool) -> None:
        """A decoded pair from the topics to the collector."""
        # A board held still is followed from the last frames (about 1 ms) instead of searched for
        # in the whole image (10 to 90 ms): the difference between keeping up with the camera or not.
        # A lost board is searched for thoroughly only when no frame waits (``thorough``).
        found = self._tracker.locate(amplitude, thorough=thorough)
        with self._lock:
            if generation != self._generation:
                return
            outcome = self.collector.add(amplitude, depth, stamp, located=found)
        if outcome.accepted:
            self._sharpener.submit(self._sharpen)
        self._judged(amplitude, outcome, stamp)

    def _sharpen(self) -> None:
        """The accurate corners of the oldest kept view still without them (tens of ms, nearly all
        in OpenCV, which lets go of the GIL), found while the worker judges the next frames. A view
        the worker swapped out or a reset cleared meanwhile is ignored by ``sharpen``."""
        try:
            with self._lock:
                todo = self.collector.unsharpened()[:1]
            for key, amplitude, quick in todo:
                found = accurate_detect(amplitude, self.board, quick)
                with self._lock:
                    dropped = self.collector.sharpen({key: found})
                for reason in dropped:
                    self._problem("view", reason)
        except Exception as exc:  # noqa: BLE001 - the calibration sharpens what is left itself
            self._problem("internal", f"accurate corners not found: {exc!r}")

    def _judged(self, amplitude: np.ndarray, outcome: Outcome, stamp: float) -> None:
        """What follows a frame's judgement, live or replayed: the log, the diagnostics, the picture."""
        if outcome.accepted:
            self.get_logger().info(outcome.reason)
        else:
            self.last_problem = outcome.reason
        self._show(amplitude, outcome, stamp)

    def _show(self, amplitude: np.ndarray, outcome, stamp: float) -> None:
        """~/board_image, only while someone looks, at most PICTURE_HZ times a second."""
        now = time.monotonic()
        if now - self._shown < 1.0 / PICTURE_HZ or self.picture_pub.get_subscription_count() == 0:
            return
        self._shown = now
        with self._lock:
            progress = self.collector.progress()
        picture = draw(amplitude, outcome, progress)
        msg = Image(height=picture.shape[0], width=picture.shape[1], encoding="bgr8", is_bigendian=0,
                    step=picture.shape[1] * 3, data=picture.tobytes())
        msg.header.stamp.sec, msg.header.stamp.nanosec = stamp_parts(stamp)
        msg.header.frame_id = self.frame_id
        self.picture_pub.publish(msg)

    def _replay(self, path: str) -> None:
        """Feed the collector from a recording or a folder of images, as fast as it reads, through
        tof_calib's own replay (``replay.Replay``), then calibrate as ~/calibrate would."""
        log = self.get_logger()
        p = self._param
        source = Path(path).expanduser()

        def replay(items, size: tuple[int, int] | None) -> Summary:
            def judged(frame, amplitude: np.ndarray, outcome: Outcome) -> None:
                if isinstance(frame, BagFrame):
                    self.frame_id = frame.depth.frame_id or frame.amplitude.frame_id
                self._judged(amplitude, outcome, frame.stamp)

            run = Replay(self.board, self.collector.config, image_size=size, collector=self.collector,
                         lock=self._lock, on_outcome=judged,
                         on_skip=lambda s: self._problem(s.kind, f"skipped ({s.kind}): {s.where}: {s.reason}"))
            return run.run(itertools.takewhile(lambda _item: not self._stop, items))

        try:
            if is_image_folder(source):
                frames, skips = scan(source, p("depth.scale"), self.board.n_corners)
                if not frames:
                    raise BagError(f"{source}: no amplitude/depth pairs (NNNN_ir.png with NNNN_depth.png)")
                log.info(f"reading {source}: {len(frames)} image pairs, each a still")
                summary = replay([*skips, *frames], None)
            else:
                with BagSource(source, amplitude=p("bag.amplitude_topic") or None,
                               depth=p("bag.depth_topic") or None, slop=p("sync.slop"), depth_scale=p("depth.scale"),
                               flags=BAG_FLAGS) as bag:
                    t = bag.topics
                    self.bag_topics = {"amplitude": t.amplitude, "depth": t.depth}
                    log.info(f"replaying {bag.path} ({bag.storage}, {bag.frame_count} amplitude messages): "
                             f"amplitude {t.amplitude} ({t.how['amplitude']}), depth {t.depth} ({t.how['depth']})")
                    size = None if bag.camera_info is None else (bag.camera_info.width, bag.camera_info.height)
                    summary = replay(bag.frames(), size)
        except (BagError, CalibrationError, OSError) as exc:
            self._problem("replay", f"cannot replay the bag: {exc}")
            log.error(f"cannot replay the bag: {exc}")
            return
        except Exception as exc:  # noqa: BLE001 - a damaged bag must not end the node
            self._problem("replay", f"bag replay stopped: {exc!r}")
            log.error(f"bag replay stopped: {exc!r}\n{traceback.format_exc()}")
            return
        if self._stop:
            return
        with self._lock:
            n = len(self.collector)
        log.info(f"replayed {path}: {summary.frames} frame pairs, {sum(summary.skipped.values())} skipped, "
                 f"{n} views kept")
        success, message = self._calibrate()
        (log.info if success else log.error)(f"calibration of the replayed bag: {message}")

    def _problem(self, kind: str, text: str) -> None:
        self.last_problem = text
        self._warn.warn(kind, text)

    def _skip(self, kind: str, text: str) -> None:
        self.malformed += 1
        self._problem(kind, text)

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
                dropped = self.collector.sharpen()   # what the sharpening thread has not reached yet
                views = self.collector.views
            for reason in dropped:
                self._problem("view", reason)
            need = self._param("views.min")
            if len(views) < need:
                return False, self._too_few(len(views), need)
            t0 = time.monotonic()
            encoded = self._encoder.submit(encode_views, views)   # the files, while the worker calibrates
            self.calibrating = (t0, len(views), "starting")
            self.get_logger().info(f"calibrating {len(views)} views")
            try:
                result = self._calibrator.calibrate(views, self.board,
                                                    (views[0].depth.shape[1], views[0].depth.shape[0]),
                                                    timeout=self._param("calibration.timeout"),
                                                    progress=self._on_stage, **calibration_options(self._values()))
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
            message = result.summary(len(views), time.monotonic() - t0)
            self.get_logger().info(message)
            return True, message
        finally:
            self.calibrating = None
            self._calibrating.release()

    def _on_stage(self, stage: str) -> None:
        """A stage the running calibration reached: logged, and shown by the diagnostics."""
        if self.calibrating is not None:
            self.calibrating = (*self.calibrating[:2], stage)
        self.get_logger().info(f"calibrating: {stage}")

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
        with self._lock:
            progress = self.collector.progress()
        return head + (f"{still_short(progress) or 'move the board to new positions'} "
                       f"(last rejection: {self.last_problem or 'none'})")

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

    def camera_info(self, result: CalibrationResult) -> CameraInfo:
        msg = CameraInfo(**monocular_fields(result.K, result.D, result.image_size))
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.frame_id
        return msg

    def _on_reset(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        with self._sync_lock:
            self.sync.clear()
        with self._lock, self._wake:   # frames paired before the reset are not to be collected after it
            self._frames.clear()
            self._generation += 1
            n = len(self.collector)
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
        msg = DiagnosticArray(status=[self.status()])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)

    def status(self) -> DiagnosticStatus:
        """What the diagnostics say: a running calibration's stage, else the last result, else
        how the collection stands; and the counts behind it."""
        with self._lock:
            progress, need = self.collector.progress(), self.collector.config.min_views
        short = still_short(progress)
        # the fully qualified name tells two cameras' calibration nodes apart
        status = DiagnosticStatus(name=f"{self.get_fully_qualified_name()}: view collection",
                                  hardware_id=self.frame_id)
        running = self.calibrating
        if running is not None:
            start, n, stage = running
            status.level = DiagnosticStatus.OK
            status.message = f"calibrating {n} views ({time.monotonic() - start:.0f} s): {stage}"
        elif self.result is not None:
            status.level = DiagnosticStatus.OK
            status.message = (f"calibrated (fx={self.result.K[0, 0]:.2f} fy={self.result.K[1, 1]:.2f}, "
                              f"{len(self.result.views)} views); still collecting")
        else:
            good = progress["good_enough"]
            status.level = DiagnosticStatus.OK if good else DiagnosticStatus.WARN
            status.message = (f"enough views to calibrate ({progress['views']})" if good
                              else f"collecting views ({progress['views']} of at least {need})")
            if short:   # what to do next while collecting; what would still help when enough by their number
                status.message += f"; more would still help: {short}" if good else f": {short}"
        values = {k: v for k, v in progress.items() if not isinstance(v, dict) and k != "last_reason"}
        values["frames received (amplitude, depth)"] = f"{self.received[0]}, {self.received[1]}"
        values.update({f"coverage.{k}": a["progress"] for k, a in progress["axes"].items()})
        values["frames dropped (worker busy)"] = self.dropped
        values["frames skipped (malformed)"] = self.malformed
        values["last rejection"] = self.last_problem
        status.values = [KeyValue(key=str(k), value=f"{v:.2f}" if isinstance(v, float) else str(v))
                         for k, v in values.items()]
        return status

    def destroy_node(self) -> None:
        with self._wake:
            self._stop = True
            self._wake.notify()
        self._worker.join(timeout=2.0)
        self._calibrator.close()
        self._encoder.shutdown(wait=False, cancel_futures=True)
        self._sharpener.shutdown(wait=False, cancel_futures=True)
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    usage = {name: (s.default, s.text) for name, s in SETTINGS.items()}
    return run("calibration_node", CalibrationNode, __doc__, usage, args, executor=lambda: Executor(num_threads=4))


if __name__ == "__main__":
    raise SystemExit(main())
