"""Reliability figures: the calibration node soaked under load and faults, and the input
decoders fed garbage.

    python benchmarks/reliability.py [--minutes 10] [--seed 0] [--json PATH]

Soak: the simulated camera streams at 30 Hz into the calibration node for ``--minutes`` while
this script calls ~/calibrate, ~/reset and ~/commit at random (sometimes two at once) and
publishes bursts of malformed frames of every kind on the same topics. Counted: frames offered,
malformed frames injected per kind, calls made and answered per service, every published
CameraInfo checked for NaN, the files checked after every call (a successful calibration must
leave whole files that pass the verdict; a failed one must leave them byte for byte), the
node's resident memory over time. Data lost (must be 0) = calls not answered + files damaged or
changed by a failed calibration + published CameraInfos with NaN + the node dying.

Fuzz: ``decode_image`` and ``read_camera_yaml`` on random inputs: each must work or raise our
own clear error (``CalibrationError``), nothing else.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import tempfile
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
NS = "/soak"
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
    """The published files (not the node's hidden staging folders). A file may vanish while the
    node swaps views/ in (two renames): then the digest is taken again."""
    while True:
        h = hashlib.sha256()
        try:
            for path in sorted(out.rglob("*")):
                if path.is_file() and not any(part.startswith(".") for part in path.relative_to(out).parts):
                    h.update(path.name.encode() + path.read_bytes())
        except FileNotFoundError:
            continue
        return h.hexdigest()


def _files_whole(out: Path) -> bool:
    from tof_calib_ros.calibration_file import CalibrationFileError, load_views, read_camera_yaml

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

    from tof_calib_ros.ros_processes import NodeProcess, Spinner, ros_environment, tree_rss_mb, wait_until

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
                                            "-p", "views.max:=30", "-p", f"output_dir:={out}"], work, env)
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
    clients = {s: spinner.client(Trigger, f"{NS}/calibration_node/{s}") for s in calls}
    try:
        # One answered call per client first, not counted: a client's first answers can be lost
        # to discovery (Spinner.call), which is Fast DDS's, not the node's. Right after a reset
        # the calibration is refused at once (too few views) and nothing is there to commit.
        for s in ("reset", "calibrate", "commit"):
            spinner.call(Trigger, f"{NS}/calibration_node/{s}", timeout=60.0, procs=procs, resend_after=5.0)
        # the launcher execs Python, so the pid is the node's own process
        wait_until(lambda: amplitude_pub.get_subscription_count() > 0, 30.0, "the node's subscriptions", *procs)

        def call(service: str) -> threading.Event:
            """Send one call; the returned event is set when it is answered and checked."""
            calls[service]["made"] += 1
            before = _digest(out) if out.exists() else ""
            done, t0 = threading.Event(), time.monotonic()
            future = clients[service].call_async(Trigger.Request())

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
                memory.append((now, tree_rss_mb(node.proc.pid)))   # the node and its calibration worker
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
    t = np.array([m[0] for m in memory]) - (memory[0][0] if memory else 0.0)
    rss = np.array([m[1] for m in memory])
    half = rss[t >= t[-1] / 3] if len(rss) else rss   # after the views are full
    slope = float(np.polyfit(t[t >= t[-1] / 3] / 60.0, half, 1)[0]) if len(half) >= 3 else float("nan")
    frames = minutes * 60.0 * 30.0
    return {
        "minutes": minutes, "frames offered (30 Hz)": int(frames), "malformed injected": injected,
        "calls": calls, "calls made": made, "calls answered": answered,
        "answer latency s (median, max)": [float(np.median(latencies)) if latencies else None,
                                           float(np.max(latencies)) if latencies else None],
        "camera_info": infos, "files": damage, "node alive at the end": alive,
        "rss MB (first, after views full, end)": [float(rss[0]), float(half[0]), float(rss[-1])] if len(rss) else [],
        "rss slope after views full, MB/min": slope,
        "data lost": (made - answered) + sum(damage.values()) + infos["with_nan"] + int(not alive),
    }


def fuzz(n: int, seed: int = 0) -> dict:
    """Random inputs per kind; outcome counts: worked, our clear error, anything else (a bug)."""
    from tof_calib_ros.calibration_file import read_camera_yaml
    from tof_calib_ros.core.errors import CalibrationError
    from tof_calib_ros.image_decode import decode_image

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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--fuzz", type=int, default=5000, help="random inputs per kind")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=RESULTS / "reliability.json")
    args = ap.parse_args()
    fuzzed = fuzz(args.fuzz, args.seed)
    print(f"{'fuzzed input':<22}{'tried':>8}{'worked':>8}{'clear error':>13}{'other':>7}")
    for kind, c in fuzzed.items():
        print(f"{kind:<22}{sum(c.values()):>8}{c['worked']:>8}{c['clear error']:>13}{c['other exception']:>7}")
    print(f"\nsoak: {args.minutes:g} min of 30 Hz frames, random calibrate/reset/commit, malformed bursts ...",
          flush=True)
    soaked = soak(args.minutes, args.seed)
    print(f"{'malformed kind':<34}{'injected':>9}")
    for kind, n in soaked["malformed injected"].items():
        print(f"{kind:<34}{n:>9}")
    print(f"\n{'service':<12}{'made':>6}{'answered':>10}{'succeeded':>11}")
    for s, c in soaked["calls"].items():
        print(f"{s:<12}{c['made']:>6}{c['answered']:>10}{c['succeeded']:>11}")
    for key in ("answer latency s (median, max)", "camera_info", "files", "node alive at the end",
                "rss MB (first, after views full, end)", "rss slope after views full, MB/min", "data lost"):
        print(f"{key}: {soaked[key]}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"fuzz": fuzzed, "soak": soaked, "load": os.getloadavg()}, indent=2))
    bad = soaked["data lost"] + sum(c["other exception"] for c in fuzzed.values())
    return 0 if bad == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
