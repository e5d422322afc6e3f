"""Views collected from recordings unlike the ones the product was tuned on, offline and live.

    python benchmarks/collection.py [--seeds 1 2] [--seconds 16] [--cameras pmd azure] [--no-live] [--json PATH]

Recordings made with the simulator (``tof_calib simulate``'s scenes): a board that never stops
(``motion=continuous``: it enters from the side after half a second without a board, then sweeps
from pose to pose, blurred where it moves fast, its depth smeared as a multi-phase ToF camera
smears it) at 5, 10 and 30 frames/s, on a 200x200 PMD-class and a 640x576 Azure-class camera,
and beside them the held-still recordings (``motion=hold``) the product was first made for.
Every seed draws other poses, another exposure (5, 10 or 20 ms: the product's default is 5 ms)
and another speed (a pose every 1.2 or 1.8 s).

- Offline: ``tof_calib bag``'s path (``Replay`` with the CLI's collector rules, 2 workers), then
  ``calibrate`` with the defaults. Live (unless ``--no-live``): a calibration_node process, as
  ``ros2 run`` starts it, fed the recording's frames on its topics at the recording's rate,
  then ``~/calibrate`` (Fast DDS tuned for large frames, as ``node_throughput.py`` and the
  README's "Large images" do: with its defaults, 640x576 frames are lost in transport).
- Truth per frame: whether the whole board is in view (the collector's margin) and how far its
  corners moved during the exposure; "sharp" is at most the default ``max_blur_px`` (1.5 px).
- Figures: sharp frames; of them, the share the collector took when it judged them (offline);
  views in the calibration against min(sharp frames, ``views.max`` = 60); blurred frames taken;
  the largest error of fx, fy, cx, cy against the truth, in percent, ours and OpenCV's
  (``calibrate(method="traditional")``) on the same views. Targets: views >= 80 % and errors
  <= 0.5 %, medians over the seeds.

Two shared cores: the live runs publish in real time from this process while the node works.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from tof_calib_ros import Board, calibrate
from tof_calib_ros.collect.collector import CollectorConfig
from tof_calib_ros.collect.replay import Replay, default_workers
from tof_calib_ros.files.bag_io import BagSource
from tof_calib_ros.settings import SETTINGS, collector_config, defaults
from tof_calib_ros.sim.recording import Scene, truth_path, write_recording

BOARD = Board(5, 7, 0.03)
VIEWS_MAX = SETTINGS["views.max"].default
RATES = (5.0, 10.0, 30.0)
CAMERAS = ("pmd", "azure")
EXPOSURES = (0.005, 0.01, 0.02)
SEGMENTS = (1.2, 1.8)
SHARP_PX = CollectorConfig.max_blur_px
TARGET_VIEWS, TARGET_ERROR = 0.8, 0.5


def scenes(seeds: list[int], seconds: float, cameras: tuple[str, ...] = CAMERAS) -> list[Scene]:
    out = []
    for camera in cameras:
        for rate in RATES:
            for seed in seeds:
                out.append(Scene(camera=camera, motion="continuous", rate=rate, frames=int(seconds * rate),
                                 lead_in=int(rate / 2), exposure=EXPOSURES[seed % 3], segment=SEGMENTS[seed % 2],
                                 camera_info="none", seed=seed))
        for seed in seeds:   # the held-still reference: 8 frames at each pose, 8 on the way, at 15 frames/s
            out.append(Scene(camera=camera, motion="hold", rate=15.0, frames=int(seconds * 15), hold=8, transit=8,
                             camera_info="none", seed=seed))
    return out


def _errors(K: np.ndarray, truth: np.ndarray) -> float:
    """The largest relative error of fx, fy, cx, cy, percent."""
    pick = [(0, 0), (1, 1), (0, 2), (1, 2)]
    return max(abs(K[i] / truth[i] - 1) * 100 for i in pick)


def offline(bag: Path, per_frame: list[dict]) -> dict:
    with BagSource(bag) as source:
        replay = Replay(BOARD, collector_config(defaults()), workers=default_workers())
        taken: list[bool] = []
        add = replay.collector.add

        def judged(*args, **kwargs):
            outcome = add(*args, **kwargs)
            taken.append(outcome.accepted)
            return outcome

        replay.collector.add = judged
        summary = replay.run(source.frames())
    views = replay.collector.views
    sharp = [f["board"] == "whole" and f["blur_px"] <= SHARP_PX for f in per_frame]
    blurred = [f["board"] == "whole" and f["blur_px"] > SHARP_PX for f in per_frame]
    out = {"frames": summary.frames, "sharp": sum(sharp), "sharp_taken": sum(s and t for s, t in zip(sharp, taken)),
           "blurred": sum(blurred), "blurred_taken": sum(b and t for b, t in zip(blurred, taken)),
           "views": len(views), "rejections": dict(summary.rejections.most_common(5))}
    for key, method in (("K", "depth"), ("K_opencv", "traditional")):
        try:
            result = calibrate(views, BOARD, summary.image_size, method=method)
            out[key] = result.K.tolist()
            if method == "depth":
                out["trusted"] = bool(result.ok)
        except Exception as exc:  # noqa: BLE001 - a failed calibration is a figure of the table
            out[f"{key}_error"] = str(exc)
    return out


def live(bag: Path, rate: float, workdir: Path, spinner, env: dict, ns: str) -> dict:
    """A calibration_node fed the recording at its rate; ~/calibrate; its calibration.json."""
    from std_srvs.srv import Trigger

    from tof_calib_ros.ros.processes import NodeProcess, play

    out = workdir / ns.strip("/")
    proc = NodeProcess("calibration_node", ["-r", f"__ns:={ns}", "-p", f"output_dir:={out}"], workdir, env)
    try:
        play(spinner.node, ns, bag, rate, (proc,))
        resp = spinner.call(Trigger, f"{ns}/calibration_node/calibrate", timeout=120.0, procs=(proc,))
        doc = json.loads((out / "calibration.json").read_text()) if resp.success else None
        return {"message": resp.message[:200], "views": None if doc is None else len(doc["views"]),
                "K": None if doc is None else doc["camera_matrix"]}
    finally:
        proc.stop()


def run(seeds: list[int], seconds: float, with_live: bool, cameras: tuple[str, ...] = CAMERAS, log=print) -> dict:
    rows = []
    spinner = env = context = None
    if with_live:
        import rclpy

        # as the README's "Large images" says: Fast DDS tuned for 640x576 frames (node_throughput's)
        from node_throughput import use_tuned_fast_dds

        from tof_calib_ros.ros.processes import Spinner, ros_environment

        use_tuned_fast_dds(Path(tempfile.mkdtemp(prefix="tof_collection_dds_")))
        env = ros_environment()
        context = rclpy.Context()
        rclpy.init(context=context)
        spinner = Spinner(context, "collection_benchmark")
    try:
        with tempfile.TemporaryDirectory(prefix="tof_collection_") as tmp:
            tmp = Path(tmp)
            for i, scene in enumerate(scenes(seeds, seconds, cameras)):
                bag = tmp / f"rec{i}"
                t0 = time.monotonic()
                write_recording(bag, scene)
                truth = json.loads(truth_path(bag).read_text())
                K_true = np.array(truth["camera_matrix"])
                row = {"camera": scene.camera, "motion": scene.motion, "rate": scene.rate, "seed": scene.seed,
                       "exposure_s": scene.exposure if scene.motion == "continuous" else 0.0,
                       "segment_s": scene.segment, "frames": scene.frames, "render_s": time.monotonic() - t0}
                row["offline"] = off = offline(bag, truth["per_frame"])
                off["error_pct"] = _errors(np.array(off["K"]), K_true) if "K" in off else None
                off["opencv_error_pct"] = _errors(np.array(off["K_opencv"]), K_true) if "K_opencv" in off else None
                if with_live:
                    row["live"] = on = live(bag, scene.rate, tmp, spinner, env, f"/bench{i}")
                    on["error_pct"] = None if on["K"] is None else _errors(np.array(on["K"]), K_true)
                rows.append(row)
                log(_line(row))
    finally:
        if spinner is not None:
            import rclpy

            spinner.close()
            rclpy.shutdown(context=context)
    return {"rows": rows, "seeds": seeds, "seconds": seconds, "views_max": VIEWS_MAX, "sharp_px": SHARP_PX,
            "summary": summarise(rows), "load_average": os.getloadavg()}


def _share(n: int, d: int) -> float:
    return n / d if d else float("nan")


def _line(row: dict) -> str:
    off = row["offline"]
    text = (f"{row['camera']:5} {row['motion']:10} {row['rate']:4.0f}/s seed {row['seed']} "
            f"exp {row['exposure_s'] * 1e3:4.0f} ms"
            f" | sharp {off['sharp']:3} taken {_share(off['sharp_taken'], off['sharp']):4.0%} views {off['views']:2}"
            f" blurred taken {off['blurred_taken']}/{off['blurred']} err {_pct(off['error_pct'])}"
            f" (OpenCV {_pct(off['opencv_error_pct'])})")
    if "live" in row:
        text += f" | live views {row['live']['views']} err {_pct(row['live']['error_pct'])}"
    return text


def _pct(value) -> str:
    return "  fail" if value is None else f"{value:5.2f}%"


def summarise(rows: list[dict]) -> list[dict]:
    """Medians over the seeds per camera, motion and rate."""
    groups: dict[tuple, list[dict]] = {}
    for row in rows:
        groups.setdefault((row["camera"], row["motion"], row["rate"]), []).append(row)
    out = []
    for (camera, motion, rate), group in groups.items():
        def med(values):
            values = [v for v in values if v is not None and v == v]
            return statistics.median(values) if values else None

        views = [_share(min(r["offline"]["views"], r["offline"]["sharp"]), min(r["offline"]["sharp"], VIEWS_MAX))
                 for r in group]
        entry = {"camera": camera, "motion": motion, "rate": rate, "runs": len(group),
                 "sharp": med([r["offline"]["sharp"] for r in group]),
                 "sharp_taken": med([_share(r["offline"]["sharp_taken"], r["offline"]["sharp"]) for r in group]),
                 "views_share": med(views),
                 "blurred_taken": med([_share(r["offline"]["blurred_taken"], r["offline"]["blurred"])
                                       for r in group]),
                 "error_pct": med([r["offline"]["error_pct"] if r["offline"]["error_pct"] is not None else 100.0
                                   for r in group]),
                 "opencv_error_pct": med([r["offline"]["opencv_error_pct"]
                                          if r["offline"]["opencv_error_pct"] is not None else 100.0 for r in group])}
        if all("live" in r for r in group):
            entry["live_views_share"] = med([_share(min(r["live"]["views"] or 0, r["offline"]["sharp"]),
                                                    min(r["offline"]["sharp"], VIEWS_MAX)) for r in group])
            entry["live_error_pct"] = med([r["live"]["error_pct"] if r["live"]["error_pct"] is not None else 100.0
                                           for r in group])
        out.append(entry)
    return out


def print_table(report: dict) -> None:
    live = any("live_error_pct" in e for e in report["summary"])
    print(f"\nmedians over seeds {report['seeds']} ({report['seconds']:g} s recordings; sharp = whole board, "
          f"blur <= {report['sharp_px']:g} px; targets: views >= {TARGET_VIEWS:.0%} of min(sharp, "
          f"{report['views_max']}), fx fy cx cy within {TARGET_ERROR:g} %)")
    head = (f"{'camera':6} {'motion':10} {'rate':>5} {'sharp':>5} {'taken':>6} {'views':>6} {'blurred taken':>13} "
            f"{'err %':>6} {'OpenCV err %':>12}")
    print(head + (f" {'live views':>10} {'live err %':>10}" if live else ""))
    def f(value, spec: str, width: int) -> str:
        return f"{'-':>{width}}" if value is None else f"{value:{width}{spec}}"

    for e in report["summary"]:
        line = (f"{e['camera']:6} {e['motion']:10} {e['rate']:5.0f} {f(e['sharp'], '.0f', 5)} "
                f"{f(e['sharp_taken'], '.0%', 6)} {f(e['views_share'], '.0%', 6)} {f(e['blurred_taken'], '.0%', 13)} "
                f"{f(e['error_pct'], '.2f', 6)} {f(e['opencv_error_pct'], '.2f', 12)}")
        if live:
            line += f" {f(e.get('live_views_share'), '.0%', 10)} {f(e.get('live_error_pct'), '.2f', 10)}"
        print(line)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--seconds", type=float, default=16.0, help="length of each recording")
    parser.add_argument("--cameras", nargs="+", choices=CAMERAS, default=list(CAMERAS))
    parser.add_argument("--no-live", action="store_true", help="offline only (no ROS node)")
    parser.add_argument("--json", type=Path, default=Path(__file__).parent / "results" / "collection.json")
    args = parser.parse_args()
    report = run(args.seeds, args.seconds, not args.no_live, tuple(args.cameras),
                 log=lambda s: print(s, file=sys.stderr, flush=True))
    print_table(report)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
