"""Reliability figures: the calibration node soaked under load and faults, and the input
decoders fed garbage.

    python benchmarks/reliability.py [--minutes 10] [--seed 0] [--json PATH]

Faults: each kind of fault an adversarial run found in the offline tool and the files, tried
again (``faults``): writes killed at every rename, out of file-size quota, two writers, bad
command lines, hostile files among good stills, calibration files the check would misread,
a recording cut off at ten places in each storage. Counted per kind: inputs tried, refused with a
message, worked, tracebacks, data lost.

Soak: the simulated camera streams at 30 Hz into the calibration node for ``--minutes`` while
this script calls ~/calibrate, ~/reset and ~/commit at random (sometimes two at once) and
publishes bursts of malformed frames of every kind on the same topics. Counted: frames offered,
malformed frames injected per kind, calls made and answered per service, every published
CameraInfo checked for NaN, the files checked after every call (a successful calibration must
leave whole files that pass the verdict; a failed one must leave them byte for byte), the
node's memory over time (the proportional set size of it, its worker and fork server; medians over a
sixth of the run once the views were full and at the end, as one sample swings by tens of MB). Data
lost (must be 0) = calls not answered + files damaged or changed by a failed calibration +
published CameraInfos with NaN + the node dying.

Fuzz: ``decode_image`` and ``read_camera_yaml`` on random inputs: each must work or raise our
own clear error (``CalibrationError``), nothing else.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import re
import tempfile
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
NS = "/soak"
HANG_TIMEOUT_S = 10.0   # the node's calibration.timeout in the soak, which stops its worker once
MALFORMED = ("rgb8 encoding", "unknown encoding", "data shorter than step x height", "step less than a row",
             "mono8 depth", "depth of another size", "NaN float amplitude", "zero-size image")


def _image(encoding: str, width: int, height: int, bpp: int, stamp: float, data: bytes | None = None,
           step: int | None = None):
    from sensor_msgs.msg import Image

    msg = Image(encoding=encoding, width=width, height=height, is_bigendian=0)
    msg.step = width * bpp if step is None else step
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(stamp), int(stamp % 1 * 1e9)
    msg.data = bytes(msg.step * height) if data is None else data
    return msg


def _malformed(kind: str, stamp: float):
    w, h = 200, 200
    good_depth = _image("16UC1", w, h, 2, stamp)
    return {
        "rgb8 encoding": (_image("rgb8", w, h, 3, stamp), good_depth),
        "unknown encoding": (_image("yuv422_garbage", w, h, 2, stamp), good_depth),
        "data shorter than step x height": (_image("mono16", w, h, 2, stamp, data=bytes(w * h)), good_depth),
        "step less than a row": (_image("mono16", w, h, 2, stamp, step=w), good_depth),
        "mono8 depth": (_image("mono16", w, h, 2, stamp), _image("mono8", w, h, 1, stamp)),
        "depth of another size": (_image("mono16", w, h, 2, stamp), _image("16UC1", w + 8, h, 2, stamp)),
        "NaN float amplitude": (_image("32FC1", w, h, 4, stamp, data=np.full(w * h, np.nan, np.float32).tobytes()),
                                good_depth),
        "zero-size image": (_image("mono16", 0, 0, 2, stamp), _image("16UC1", 0, 0, 2, stamp)),
    }[kind]


def _digest(out: Path) -> str:
    """The current calibration set's files (the generation ``current`` points to, resolved once:
    a new set may be made current meanwhile, and the one before it is kept)."""
    while True:
        h = hashlib.sha256()
        try:
            generation = Path(os.path.realpath(out / "current"))
            for path in sorted(generation.rglob("*")):
                if path.is_file():
                    h.update(path.name.encode() + path.read_bytes())
        except FileNotFoundError:   # that generation went two switches ago: take the new one
            continue
        return h.hexdigest()


def _files_whole(out: Path) -> bool:
    from tof_calib_ros.files.calibration_file import CalibrationFileError, read_camera_yaml
    from tof_calib_ros.files.image_folder import load_views

    try:
        K = read_camera_yaml(out / "calibration.yaml").K
        doc = json.loads((out / "calibration.json").read_text())
        load_views(out / "views")
    except (CalibrationFileError, OSError, ValueError):
        return False
    return bool(np.all(np.isfinite(K)) and doc["verdict"]["ok"])


def soak(minutes: float, seed: int = 0, log=print) -> dict:
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image
    from std_srvs.srv import Trigger

    from tof_calib_ros.ros.processes import NodeProcess, Spinner, ros_environment, tree_memory_mb, wait_until
    from tof_calib_ros.ros.processes import answered as is_answered

    rnd = random.Random(seed)
    env = ros_environment()
    work = Path(tempfile.mkdtemp(prefix="tof_calib_soak_"))
    out = work / "out"
    board = ["-p", "board.cols:=5", "-p", "board.rows:=7", "-p", "board.square:=0.03"]
    context = rclpy.Context()
    rclpy.init(context=context)
    sim = NodeProcess("tof_sim_node", ["-r", f"__ns:={NS}", *board, "-p", "rate:=30.0", "-p", f"seed:={seed}",
                                       "-p", f"calibration_file:={work / 'driver.yaml'}"], work, env)
    node = NodeProcess("calibration_node", ["-r", f"__ns:={NS}", *board, "-p", "views.min:=8",
                                            "-p", "views.max:=30", "-p", f"output_dir:={out}",
                                            "-p", f"calibration.timeout:={HANG_TIMEOUT_S}"], work, env)
    procs = (sim, node)
    spinner = Spinner(context, "soak")
    calls = {s: {"made": 0, "answered": 0, "succeeded": 0} for s in ("calibrate", "reset", "commit")}
    injected = dict.fromkeys(MALFORMED, 0)
    infos = {"received": 0, "with_nan": 0}
    damage = {"files damaged after a success": 0, "files changed by a failure": 0}
    memory: list[tuple[float, float]] = []
    latencies: list[float] = []

    def on_info(msg: CameraInfo) -> None:
        infos["received"] += 1
        infos["with_nan"] += int(not np.all(np.isfinite(np.r_[msg.k, msg.d, msg.p])))

    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    spinner.node.create_subscription(CameraInfo, f"{NS}/calibration_node/camera_info", on_info, latched)
    amplitude_pub = spinner.node.create_publisher(Image, f"{NS}/amplitude", qos_profile_sensor_data)
    depth_pub = spinner.node.create_publisher(Image, f"{NS}/depth", qos_profile_sensor_data)
    # Every client of a service receives every answer the service sends and drops the others'
    # (ros2/rmw_fastrtps#559, ros2/rclcpp#2397), keeping the last 10 by default: the 300 answers of
    # a burst from three more clients can push one of the calibrate client's own out of its queue
    # (one call of 676 went unanswered on a loaded machine, 2026-12-06). Each has room for them all.
    deep = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    clients = {s: spinner.node.create_client(Trigger, f"{NS}/calibration_node/{s}", qos_profile=deep)
               for s in calls}
    burst_clients = [spinner.node.create_client(Trigger, f"{NS}/calibration_node/calibrate", qos_profile=deep)
                     for _ in range(3)]
    events = {"burst of 300 calls sent": False, "calibration worker stopped (SIGSTOP)": False}
    try:
        # One answered call per client first, not counted: a client's first answers can be lost
        # to discovery (Spinner.call), which is Fast DDS's, not the node's. Right after a reset
        # the calibration is refused at once (too few views) and nothing is there to commit.
        for s in ("reset", "calibrate", "commit"):
            spinner.call(Trigger, f"{NS}/calibration_node/{s}", timeout=60.0, procs=procs, resend_after=5.0)
        # the launcher execs Python, so the pid is the node's own process
        wait_until(lambda: amplitude_pub.get_subscription_count() > 0, 30.0, "the node's subscriptions", *procs)

        for client in [*clients.values(), *burst_clients]:   # answered once each first, as above
            wait_until(lambda c=client: is_answered(c, 5.0), 60.0, "a client's first answer", *procs)

        def call(service: str, client=None) -> threading.Event:
            """Send one call; the returned event is set when it is answered and checked."""
            calls[service]["made"] += 1
            before = _digest(out) if out.exists() else ""
            done, t0 = threading.Event(), time.monotonic()
            future = (client or clients[service]).call_async(Trigger.Request())

            def answered(_f) -> None:
                resp = future.result()
                calls[service]["answered"] += 1
                calls[service]["succeeded"] += int(resp.success)
                latencies.append(time.monotonic() - t0)
                if service == "calibrate":
                    if resp.success:
                        damage["files damaged after a success"] += int(not _files_whole(out))
                    elif "already running" not in resp.message and out.exists():
                        # another calibration may have finished meanwhile: only count a change
                        # that leaves the files anything but whole and trusted
                        if _digest(out) != before and not _files_whole(out):
                            damage["files changed by a failure"] += 1
                done.set()
            future.add_done_callback(answered)
            return done

        pending: list[threading.Event] = []
        end = time.monotonic() + minutes * 60.0
        next_burst = next_sample = time.monotonic()
        stamp = 1.0e9
        while time.monotonic() < end:
            now = time.monotonic()
            if now >= next_sample:
                memory.append((now, tree_memory_mb(node.proc.pid)))   # the node and its calibration worker
                next_sample = now + 5.0
            if now >= next_burst:
                for _ in range(20):
                    kind = rnd.choice(MALFORMED)
                    stamp += 0.001
                    a, d = _malformed(kind, stamp)
                    amplitude_pub.publish(a)
                    depth_pub.publish(d)
                    injected[kind] += 1
                next_burst = now + rnd.uniform(3.0, 8.0)
            if not events["burst of 300 calls sent"] and now > end - minutes * 40.0:   # a third of the way
                pending.extend(call("calibrate", c) for c in burst_clients for _ in range(100))
                events["burst of 300 calls sent"] = True
            if not events["calibration worker stopped (SIGSTOP)"] and now > end - minutes * 20.0:
                # a stuck worker: the next calibration must time out and the node replace it
                import psutil

                for p in psutil.Process(node.proc.pid).children(recursive=True):
                    if not p.children() and "resource_tracker" not in " ".join(p.cmdline()):
                        p.suspend()
                events["calibration worker stopped (SIGSTOP)"] = True
            service = rnd.choices(["calibrate", "reset", "commit"], weights=[5, 1, 2])[0]
            pending.append(call(service))
            if service == "calibrate" and rnd.random() < 0.2:
                pending.append(call("calibrate"))   # two at once
            time.sleep(rnd.uniform(0.3, 2.0))
            if not node.alive():
                break
        deadline = time.monotonic() + 120.0
        for event in pending:
            event.wait(max(0.0, deadline - time.monotonic()))
        alive = node.alive()
    finally:
        spinner.close()
        for p in procs:
            p.stop()
        rclpy.shutdown(context=context)

    answered = sum(c["answered"] for c in calls.values())
    made = sum(c["made"] for c in calls.values())
    t = np.array([m[0] for m in memory]) - memory[0][0]   # the loop's first step samples
    mb = np.array([m[1] for m in memory])
    full = t >= t[-1] / 3   # after the views are full
    slope = float(np.polyfit(t[full] / 60.0, mb[full], 1)[0]) if full.sum() >= 3 else float("nan")
    # One sample swings by tens of MB as the node decodes frames and the worker calibrates:
    # growth is read between medians over a sixth of the run each.
    early, late = mb[full & (t <= t[-1] / 2)], mb[t >= t[-1] * 5 / 6]
    frames = minutes * 60.0 * 30.0
    return {
        "minutes": minutes, "frames offered (30 Hz)": int(frames), "malformed injected": injected,
        "calls": calls, "calls made": made, "calls answered": answered,
        "answer latency s (median, max)": [float(np.median(latencies)) if latencies else None,
                                           float(np.max(latencies)) if latencies else None],
        "camera_info": infos, "files": damage, "node alive at the end": alive, "events": events,
        "memory MB (first; median once views full, at end)":
            [float(mb[0]), float(np.median(early)), float(np.median(late))],
        "memory slope after views full, MB/min": slope,
        "data lost": (made - answered) + sum(damage.values()) + infos["with_nan"] + int(not alive),
    }


def fuzz(n: int, seed: int = 0) -> dict:
    """Random inputs per kind; outcome counts: worked, our clear error, anything else (a bug)."""
    from tof_calib_ros.core.errors import CalibrationError
    from tof_calib_ros.files.calibration_file import read_camera_yaml
    from tof_calib_ros.files.image_decode import decode_image

    rng = np.random.default_rng(seed)
    encodings = ["mono8", "mono16", "16UC1", "32FC1", "rgb8", "bgr8", "8UC3", "", "garbage"]

    bpp = {"mono8": 1, "mono16": 2, "16UC1": 2, "32FC1": 4}

    def image_msg():
        """Half consistent (any padding, either byte order), half with a random step and length."""
        enc = str(rng.choice(encodings))
        w, h = int(rng.integers(0, 40)), int(rng.integers(0, 40))
        if enc in bpp and rng.random() < 0.5:
            step = w * bpp[enc] + int(rng.integers(0, 8))
            size = step * h
        else:
            step = int(rng.integers(0, 4 * w + 8))
            size = int(rng.integers(0, step * h + 16))
        return SimpleNamespace(width=w, height=h, encoding=enc, is_bigendian=int(rng.integers(0, 2)), step=step,
                               data=rng.integers(0, 256, size, dtype=np.uint8).tobytes())

    def yaml_file():
        path = Path(tempfile.mkstemp(suffix=".yaml")[1])
        good = ("image_width: 640\nimage_height: 480\ncamera_name: c\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
                "  data: [500, 0, 320, 0, 500, 240, 0, 0, 1]\ndistortion_model: plumb_bob\n"
                "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0, 0, 0, 0, 0]\n"
                "rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n"
                "projection_matrix:\n  rows: 3\n  cols: 4\n  data: [500, 0, 320, 0, 0, 500, 240, 0, 0, 0, 1, 0]\n")
        data = bytearray(good.encode())
        for _ in range(int(rng.integers(0, 6))):   # mutate a few bytes, cut, or replace wholesale
            op = int(rng.integers(0, 3))
            if op == 0 and data:
                data[int(rng.integers(0, len(data)))] = int(rng.integers(0, 256))
            elif op == 1:
                data = data[: int(rng.integers(0, len(data) + 1))]
            else:
                data = bytearray(rng.integers(0, 256, int(rng.integers(0, 64)), dtype=np.uint8).tobytes())
        path.write_bytes(bytes(data))
        return path

    outcome = {}
    for kind, make, run in [("image message", image_msg, decode_image),
                            ("camera YAML file", yaml_file, read_camera_yaml)]:
        counts = {"worked": 0, "clear error": 0, "other exception": 0}
        for _ in range(n):
            arg = make()
            try:
                run(arg)
                counts["worked"] += 1
            except CalibrationError:
                counts["clear error"] += 1
            except Exception:  # noqa: BLE001 - counted: this is what the figure is about
                counts["other exception"] += 1
            finally:
                if isinstance(arg, Path):
                    os.unlink(arg)
        outcome[kind] = counts
    return outcome


# -- faults of the offline tool and the files: each kind tried, what it gave --------------------------------
_WRITE = """
import os, signal, sys
import numpy as np
from tof_calib_ros import View
from tof_calib_ros.core.depth_bias import N_BIAS
from tof_calib_ros.core.result import CalibrationResult, ViewReport
from tof_calib_ros.files.output_folder import write_calibration
out, scale, n, kill_at, repeat = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
calls = [0]
def killing(real):
    def call(*a, **k):
        calls[0] += 1
        if calls[0] == kill_at:
            os.kill(os.getpid(), signal.SIGKILL)
        return real(*a, **k)
    return call
os.rename, os.replace = killing(os.rename), killing(os.replace)
K = np.array([[500.0 * scale, 0, 320], [0, 500.0 * scale, 240], [0, 0, 1]])
view = ViewReport(index=0, rvec=np.zeros(3), tvec=np.array([0, 0, 1.0]), pixel_rms=0.2, depth_rms=0.001,
                  pixel_residuals=np.zeros((4, 2)), depth_residuals=np.zeros(4))
result = CalibrationResult(method="depth", image_size=(640, 480), K=K, D=np.zeros(5),
                           depth_bias=np.zeros(N_BIAS), std={"fx": 0.5, "fy": 0.5, "cx": 1.0, "cy": 1.0}, views=[view])
views = [View(depth=np.full((48, 64), 1000 + i, np.uint16), amplitude=np.full((48, 64), 7, np.uint16))
         for i in range(n)]
for _ in range(repeat):
    write_calibration(out, result, views, "tof", {"n_views": n, "pad": "x" * int(sys.argv[6])})
"""


def _set_seen(out: Path) -> tuple[float, int] | None:
    """fx and view count of the set a reader sees, or None when its files do not belong together."""
    from tof_calib_ros.files.calibration_file import read_camera_yaml

    gen = Path(os.path.realpath(out / "current"))
    try:
        fx = read_camera_yaml(gen / "calibration.yaml").K[0, 0]
        doc = json.loads((gen / "calibration.json").read_text())
        n = len(list((gen / "views").glob("*_ir.png")))
    except Exception:  # noqa: BLE001 - anything unreadable is a damaged set
        return None
    return (fx, n) if doc["camera_matrix"][0][0] == fx and doc["n_views"] == n else None


def _writer(out: Path, scale: float, n: int, kill_at: int = 0, repeat: int = 1, pad: int = 0,
            fsize: int | None = None, wait: bool = True):
    import resource
    import subprocess
    import sys

    def limit() -> None:
        if fsize is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    args = [sys.executable, "-c", _WRITE, str(out), str(scale), str(n), str(kill_at), str(repeat), str(pad)]
    proc = subprocess.Popen(args, stderr=subprocess.PIPE, text=True, preexec_fn=limit)
    if wait:
        proc.err = proc.communicate(timeout=300)[1]
    return proc


def _cli(*argv: str, timeout: float = 600.0) -> tuple[int, str, float]:
    import subprocess
    import sys

    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "tof_calib_ros.offline.cli", *map(str, argv)], capture_output=True,
                          text=True, timeout=timeout)
    return proc.returncode, proc.stdout + proc.stderr, time.monotonic() - t0


def faults(log=print) -> dict:
    """Each kind of fault the adversarial run of issue 13 found, tried again: how many inputs, how
    many ended in a one-line refusal or worked, tracebacks, and data lost (a reader seeing a mixed
    or damaged calibration set, a good set changed by a failed run, a frame lost that was readable)."""
    from tof_calib_ros import Board, sim
    from tof_calib_ros.core.inputs import View
    from tof_calib_ros.files.calibration_file import save_views

    rows: dict[str, dict] = {}
    work = Path(tempfile.mkdtemp(prefix="tof_calib_faults_"))

    def row(kind: str, tried: int, refused: int, worked: int, tracebacks: int, lost: int, note: str = "") -> None:
        rows[kind] = {"tried": tried, "refused with a message": refused, "worked": worked,
                      "tracebacks": tracebacks, "data lost": lost, "note": note}
        log(f"{kind}: {rows[kind]}")

    old, new = (500.0, 5), (1000.0, 3)
    # a write killed at every rename, in turn, until one runs through
    seen, lost, kills = [], 0, 0
    for n in range(1, 80):
        out = work / f"kill{n}"
        _writer(out, 1, 5)
        proc = _writer(out, 2, 3, kill_at=n)
        seen.append(_set_seen(out))
        lost += int(seen[-1] not in (old, new))
        if proc.returncode == 0:
            break
        kills += 1
    row("calibration write killed at a rename", kills + 1, 0, kills + 1, 0, lost,
        f"killed at each of {kills} renames: the old set {seen.count(old)} times, the new {seen.count(new)}")
    # out of file-size quota (ulimit -f) at several sizes
    tried = lost = refused = tracebacks = 0
    for fsize in (2_000, 20_000, 60_000, 150_000):
        out = work / f"quota{fsize}"
        _writer(out, 1, 5)
        proc = _writer(out, 2, 3, pad=200_000, fsize=fsize)
        tried += 1
        refused += int(proc.returncode != 0 and "File too large" in proc.err)
        tracebacks += int("Traceback" in proc.err and "CalibrationFileError" not in proc.err)
        lost += int(_set_seen(out) != old)
    row("calibration write out of file-size quota", tried, refused, 0, tracebacks, lost)
    # two writers at once, a reader beside them
    out = work / "two"
    _writer(out, 1, 5)
    writers = [_writer(out, scale, int(scale) + 1, repeat=15, wait=False) for scale in (2, 3)]
    mixed = reads = 0
    while any(w.poll() is None for w in writers):
        reads += 1
        mixed += int(_set_seen(out) is None and (out / "current").exists())
    errors = [w.communicate()[1] for w in writers]
    row("two writers on one output folder", 30, 0, sum(w.returncode == 0 for w in writers) * 15,
        sum("Traceback" in e for e in errors), mixed + int(_set_seen(out) is None),
        f"{reads} reads while they wrote, {mixed} saw a mixed set")

    # bad command lines: exit 2 before any frame is read
    board = ["--size", "5x7", "--square", "0.03"]
    bad = [["--size", "2x5"], ["--size", "0x0"], ["--size", "1x1"], ["--slop", "-1"], ["--depth-scale", "1e300"],
           ["--depth-bias", "offset+wobble"], ["--square", "30"]]
    results = [_cli("bag", work / "never_read", *board, "--output", work / "o", *b) for b in bad]
    row("bad command line values", len(bad), sum(code == 2 for code, _, _ in results), 0,
        sum("Traceback" in text for _, text, _ in results), 0)

    # a folder of good stills with hostile files among them
    cam, b = sim.pmd_camera(), Board(5, 7, 0.03)
    folder = work / "stills"
    views = []
    for i, (rvec, tvec) in enumerate(sim.random_poses(cam, b, 16, 7, distance=(0.4, 1.0))):
        f = sim.render(cam, b, rvec, tvec, noise=sim.Noise(depth=0.002, amplitude=0.002), rng=i)
        views.append(View(f.depth, amplitude=f.amplitude))
    save_views(folder, views)
    with open(folder / "0100_ir.npy", "wb") as f:   # a header claiming 10^6 x 10^6
        np.lib.format.write_array_header_1_0(f, {"descr": "<u2", "fortran_order": False, "shape": (10**6, 10**6)})
    np.save(folder / "0100_depth.npy", np.ones((200, 200), np.uint16))
    import cv2
    big = cv2.imencode(".png", np.zeros((20000, 20000), np.uint8))[1].tobytes()   # about 400 kB
    (folder / "0101_ir.png").write_bytes(big)
    (folder / "0101_depth.png").write_bytes(big)
    np.save(folder / "0102_ir.npy", views[0].amplitude)
    np.save(folder / "0102_depth.npy", np.full((200, 200), 1e300))   # float64 depth beyond any range
    code, text, seconds = _cli("images", folder, *board, "--output", work / "stills_out")
    skipped = re.search(r"(\d+) too_large", text)
    too_large = int(skipped[1]) if skipped else 0
    used = re.search(r"(\d+) of (\d+) views used", text)
    row("hostile files among 16 stills", 3, too_large, int(code == 0), int("Traceback" in text), int(code != 0),
        f"exit {code} in {seconds:.1f} s; {too_large} pairs too large skipped, the 1e300 depth read as invalid; "
        f"views used: {used[1] if used else 0} of {used[2] if used else 0}")

    # calibration files the check would misread, and a YAML alias bomb
    good = ("image_width: 200\nimage_height: 200\ncamera_name: tof\n"
            "camera_matrix: {rows: 3, cols: 3, data: [284.4, 0.0, 100.0, 0.0, 284.4, 100.0, 0.0, 0.0, 1.0]}\n"
            "distortion_model: plumb_bob\ndistortion_coefficients: {rows: 1, cols: 5, data: [-0.1, 0.02, 0, 0, 0]}\n"
            "rectification_matrix: {rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}\n"
            "projection_matrix: {rows: 3, cols: 4, data: [284.4, 0, 100, 0, 0, 284.4, 100, 0, 0, 0, 1, 0]}\n")
    edits = [("[284.4, 0.0, 100.0, 0.0, 284.4", "[-284.4, 0.0, 100.0, 0.0, 284.4"),
             ("0.0, 0.0, 1.0]}", "0.0, 0.0, 0.0]}"), ("0.0, 0.0, 1.0]}", "0.0, 0.0, 2.0]}"),
             ("[284.4, 0.0, 100.0, 0.0, 284.4", "[284.4, 150.0, 100.0, 0.0, 284.4"),
             ("plumb_bob", "equidistant"),
             ("plumb_bob\ndistortion_coefficients: {rows: 1, cols: 5, data: [-0.1, 0.02, 0, 0, 0]}",
              "rational_polynomial\ndistortion_coefficients: {rows: 1, cols: 14, data: [" + ", ".join(["0"] * 14)
              + "]}")]
    anchors = "a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n" + "".join(
        f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]\n" for i in range(1, 9))
    files = [good.replace(a, z, 1) for a, z in edits] + [anchors + good.replace("data: [-0.1, 0.02, 0, 0, 0]",
                                                                                 "data: *a8")]
    results = []
    for i, text in enumerate(files):
        path = work / f"misread{i}.yaml"
        path.write_text(text)
        results.append(_cli("check", path, folder, *board, timeout=60))
    row("calibration files check would misread (and an alias bomb)", len(files),
        sum(code == 1 and ("cannot be checked" in t or "aliases" in t) for code, t, _ in results),
        sum(code == 0 for code, _, _ in results), sum("Traceback" in t for _, t, _ in results),
        sum(code == 0 for code, _, _ in results), f"slowest {max(s for _, _, s in results):.1f} s")

    # a recording cut off at ten places (a recorder killed), in each storage: frames before the cut
    for storage, suffix in (("mcap", ".mcap"), ("sqlite3", ".db3")):
        _cut_recording(work, storage, suffix, views, board, row)
    return rows


def _cut_recording(work: Path, storage: str, suffix: str, views: list, board: list[str], row) -> None:
    from tof_calib_ros.files.bag_io import BagWriter

    bag = work / f"rec_{storage}"
    with BagWriter(bag, storage) as w:
        for i, view in enumerate(v for v in views for _ in range(3)):   # each pose held for 3 frames
            stamp = 100.0 + 0.1 * i
            w.write("/tof/amplitude/image_raw", w.image_message(view.amplitude, "mono16", stamp, "tof"), stamp)
            w.write("/tof/depth/image_raw", w.image_message(np.rint(view.depth * 1000).astype(np.uint16), "16UC1",
                                                            stamp, "tof"), stamp)
    file = next(bag.glob(f"*{suffix}"))
    whole = file.read_bytes()
    (bag / "metadata.yaml").unlink()   # killed before it closed the bag
    recovered, results = [], []
    for fraction in np.linspace(0.1, 0.95, 10):
        file.write_bytes(whole[:int(len(whole) * fraction)])
        code, text, _ = _cli("bag", bag, *board, "--output", work / f"cut_out_{storage}", "--views-min", "3")
        results.append((code, text))
        judged = [int(line.split()[1]) for line in text.splitlines() if line.startswith("frames:")]
        recovered.append(judged[0] if judged else 0)
    row(f"{storage} recording cut off (no metadata.yaml)", 10,
        sum(code != 0 for code, _ in results), sum(code == 0 for code, _ in results),
        sum("Traceback" in t for _, t in results), int(recovered != sorted(recovered) or recovered[-1] < 40),
        f"frame pairs read at 10 % to 95 % of the file: {recovered} of {len(views) * 3}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="length of the node's soak (0: none)")
    ap.add_argument("--no-faults", action="store_true", help="skip the offline tool's and the files' faults")
    ap.add_argument("--fuzz", type=int, default=5000, help="random inputs per kind")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=RESULTS / "reliability.json")
    args = ap.parse_args()
    faulted = {} if args.no_faults else faults(log=lambda s: None)
    print(f"{'fault':<58}{'tried':>6}{'refused':>8}{'worked':>7}{'tracebacks':>11}{'lost':>5}")
    for kind, r in faulted.items():
        print(f"{kind:<58}{r['tried']:>6}{r['refused with a message']:>8}{r['worked']:>7}{r['tracebacks']:>11}"
              f"{r['data lost']:>5}  {r['note']}")
    fuzzed = fuzz(args.fuzz, args.seed)
    print(f"{'fuzzed input':<22}{'tried':>8}{'worked':>8}{'clear error':>13}{'other':>7}")
    for kind, c in fuzzed.items():
        print(f"{kind:<22}{sum(c.values()):>8}{c['worked']:>8}{c['clear error']:>13}{c['other exception']:>7}")
    soaked = {"data lost": 0}
    if args.minutes > 0:
        print(f"\nsoak: {args.minutes:g} min of 30 Hz frames, random calibrate/reset/commit, malformed bursts ...",
              flush=True)
        soaked = soak(args.minutes, args.seed)
        print(f"{'malformed kind':<34}{'injected':>9}")
        for kind, n in soaked["malformed injected"].items():
            print(f"{kind:<34}{n:>9}")
        print(f"\n{'service':<12}{'made':>6}{'answered':>10}{'succeeded':>11}")
        for s, c in soaked["calls"].items():
            print(f"{s:<12}{c['made']:>6}{c['answered']:>10}{c['succeeded']:>11}")
        for key in ("events", "answer latency s (median, max)", "camera_info", "files", "node alive at the end",
                    "memory MB (first; median once views full, at end)", "memory slope after views full, MB/min",
                    "data lost"):
            print(f"{key}: {soaked[key]}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"faults": faulted, "fuzz": fuzzed, "soak": soaked, "load": os.getloadavg()},
                                    indent=2))
    bad = soaked["data lost"] + sum(c["other exception"] for c in fuzzed.values()) + sum(
        r["data lost"] + r["tracebacks"] for r in faulted.values())
    return 0 if bad == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
