"""Bag replay speed and memory: frame pairs per second through the view collector, with one and
two worker processes, and the resident memory of a short and a long recording.

The recordings are simulated (``sim.recording``: the board held still at a pose for 8 frames,
moved to the next over 8) at 200x200 (PMD class) and 640x576 (Azure Kinect class); a cycle of
rendered frames is repeated to make long bags, with fresh stamps. Each measurement runs in its
own process: the bag is opened, every frame decoded, its board found and judged by the
collector (what ``tof_calib bag`` does before calibrating); the worker processes' start is
included. Memory and CPU time are sampled every 0.1 s over the process and its workers. The
machine is shared: medians over the runs, the load average beside them, and the CPU time per
pair, which other processes on the machine do not inflate as they do the wall-clock rate.

    python benchmarks/bag_replay.py [--runs 3] [--workdir /tmp/bag_replay] [--azure-long]
"""
from __future__ import annotations

import argparse
import itertools
import json
import os
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

CAMERAS = {"pmd": "200x200", "azure": "640x576"}
CYCLE_POSES = {"pmd": 30, "azure": 16}   # distinct poses before the frames repeat
SHORT, LONG = 1000, 10000


def make_bag(path: Path, camera: str, frames: int) -> None:
    from tof_calib_ros.sim.recording import Scene, render_frames, write_recording

    scene = Scene(camera=camera, frames=CYCLE_POSES[camera] * 16, hold=8, transit=8, seed=5)
    cycle = list(render_frames(scene))
    write_recording(path, Scene(camera=camera, frames=frames, hold=8, transit=8, seed=5), "sqlite3",
                    frames=itertools.islice(itertools.cycle(cycle), frames))


def measure(bag: Path, workers: int) -> dict:
    """One replay, in this process (run by ``main`` as a subprocess)."""
    import psutil

    from tof_calib_ros import Board
    from tof_calib_ros.collect.replay import Replay
    from tof_calib_ros.files.bag_io import BagSource
    from tof_calib_ros.ros.processes import tree_memory_mb
    from tof_calib_ros.settings import collector_config, defaults

    me = psutil.Process()
    peak = {"main": 0, "total": 0}
    cpu: dict[int, float] = {}   # CPU seconds of each worker process, as last seen
    done = threading.Event()

    def sample() -> None:
        while not done.wait(0.1):
            try:
                children = me.children(recursive=True)
                main_rss = me.memory_info().rss
                total = tree_memory_mb(me.pid) * 2**20
                for c in children:
                    t = c.cpu_times()
                    cpu[c.pid] = t.user + t.system
            except psutil.Error:
                continue
            peak["main"], peak["total"] = max(peak["main"], main_rss), max(peak["total"], total)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    t0, cpu0 = time.perf_counter(), sum(me.cpu_times()[:2])
    with BagSource(bag) as source:
        info = source.camera_info
        replay = Replay(Board(5, 7, 0.03), collector_config(defaults()), workers=workers,
                        image_size=(info.width, info.height))
        summary = replay.run(source.frames())
    seconds = time.perf_counter() - t0
    done.set()
    sampler.join()
    main_cpu = sum(me.cpu_times()[:2]) - cpu0
    return {"pairs": summary.frames, "seconds": seconds, "pairs_per_s": summary.frames / seconds,
            "views": len(replay.collector.views), "rss_main_mb": peak["main"] / 2**20,
            "pss_total_mb": peak["total"] / 2**20, "cpu_ms_per_pair": 1e3 * (main_cpu + sum(cpu.values()))
            / summary.frames, "main_cpu_ms_per_pair": 1e3 * main_cpu / summary.frames}


def run_measure(bag: Path, workers: int) -> dict:
    load = os.getloadavg()[0]
    done = subprocess.run([sys.executable, __file__, "--measure", str(bag), "--workers", str(workers)],
                          capture_output=True, text=True, check=True)
    return {**json.loads(done.stdout.strip().splitlines()[-1]), "load_before": load}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="runs of each short-bag measurement (median)")
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/bag_replay_benchmark"))
    ap.add_argument("--azure-long", action="store_true",
                    help="also a 10,000-frame 640x576 bag (15 GB of disk)")
    ap.add_argument("--json", type=Path, default=Path(__file__).parent / "results" / "bag_replay.json")
    ap.add_argument("--measure", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--workers", type=int, default=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.measure:
        print(json.dumps(measure(args.measure, args.workers)))
        return

    args.workdir.mkdir(parents=True, exist_ok=True)
    plan = [("pmd", SHORT, args.runs), ("pmd", LONG, 1), ("azure", SHORT, args.runs)]
    if args.azure_long:
        plan.append(("azure", LONG, 1))
    rows = []
    for camera, frames, runs in plan:
        bag = args.workdir / f"{camera}_{frames}"
        if not bag.exists():
            print(f"writing {bag} ...", flush=True)
            make_bag(bag, camera, frames)
        row = {"camera": camera, "size": CAMERAS[camera], "frames": frames, "runs": runs,
               "bag_mb": sum(f.stat().st_size for f in bag.iterdir()) / 2**20}
        for workers in (1, 2):
            results = [run_measure(bag, workers) for _ in range(runs)]
            row[f"workers_{workers}"] = {
                **{key: statistics.median(r[key] for r in results)
                   for key in ("pairs_per_s", "rss_main_mb", "pss_total_mb", "cpu_ms_per_pair",
                               "main_cpu_ms_per_pair")},
                "views": results[0]["views"], "load_before": [r["load_before"] for r in results],
                "runs": results}
            print(f"  {camera} {frames} frames, {workers} worker(s): "
                  f"{row[f'workers_{workers}']['pairs_per_s']:.0f} pairs/s", flush=True)
        rows.append(row)

    print(f"\n{'size':>8} {'frames':>6} {'bag MB':>7} | {'pairs/s: 1 worker':>17} {'2 workers':>9} | "
          f"{'CPU ms/pair (main)':>18} {'2 workers':>15} | {'RSS MB main':>11} {'PSS MB all':>10} | load avg")
    for r in rows:
        w1, w2 = r["workers_1"], r["workers_2"]
        loads = w1["load_before"] + w2["load_before"]
        print(f"{r['size']:>8} {r['frames']:>6} {r['bag_mb']:>7.0f} | {w1['pairs_per_s']:>17.0f} "
              f"{w2['pairs_per_s']:>9.0f} | {w1['cpu_ms_per_pair']:>10.1f} ({w1['main_cpu_ms_per_pair']:4.1f}) "
              f"{w2['cpu_ms_per_pair']:>8.1f} ({w2['main_cpu_ms_per_pair']:4.1f}) | "
              f"{w1['rss_main_mb']:>4.0f} / {w2['rss_main_mb']:<4.0f} {w1['pss_total_mb']:>4.0f} / "
              f"{w2['pss_total_mb']:<4.0f} | {min(loads):.1f}-{max(loads):.1f}")
    print("(RSS of the main process and PSS of all processes: 1 worker / 2 workers)")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"rows": rows, "cpus": os.cpu_count()}, indent=1))
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
