"""Runtime of the whole depth-aided pipeline against cv2.calibrateCamera on the same views.

Views are rendered (200x200 PMD-class camera, a 10x7-corner board: 70 corners a view) with
their corners given, so both sides start from the same corners; ours also planarizes every
view's depth image. Medians over several runs, measured side by side in one process.

    python benchmarks/runtime.py [--runs 3]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from tof_calib_ros import Board, View, calibrate, sim
from tof_calib_ros.core.traditional import calibrate_opencv

BOARD = Board(10, 7, 0.03)
COUNTS = (7, 50, 200)


def scene(n: int, seed: int) -> list[View]:
    rng = np.random.default_rng(seed)
    cam = sim.pmd_camera()
    poses = sim.random_poses(cam, BOARD, n, rng, distance=(0.5, 0.9), max_tilt_deg=40)
    views = []
    for r, t in poses:
        f = sim.render(cam, BOARD, r, t, noise=sim.Noise(depth=0.005), rng=rng)
        views.append(View(f.depth, f.corners + rng.normal(0, 0.05, f.corners.shape)))
    return views


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--output", type=Path, default=Path(__file__).parent / "results" / "runtime.json")
    args = ap.parse_args()
    rows = []
    print(f"{'views':>5} {'ours (s)':>9} {'OpenCV (s)':>10} {'ratio':>6}")
    for n in COUNTS:
        views = scene(n, n)
        obj = [BOARD.object_points()] * n
        ours, cv = [], []
        for _ in range(args.runs):
            t0 = time.perf_counter()
            calibrate(views, BOARD)
            ours.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            calibrate_opencv(obj, [v.corners for v in views], (200, 200))
            cv.append(time.perf_counter() - t0)
        row = {"views": n, "corners_per_view": BOARD.n_corners, "ours_s": float(np.median(ours)),
               "opencv_s": float(np.median(cv))}
        row["ratio"] = row["ours_s"] / row["opencv_s"]
        rows.append(row)
        print(f"{n:5d} {row['ours_s']:9.3f} {row['opencv_s']:10.3f} {row['ratio']:6.1f}")
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps({"runs": args.runs, "rows": rows}, indent=1))
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
