"""How well the result's map of each pixel's projection uncertainty (the runs' spread, ``core.coverage``)
matches the true projection error, where the views reached and where they did not.

Simulated cameras with a strong lens (k1 = -0.3, k2 = 0.1, p1 = p2 = 1e-3), ToF depth noise and
0.05 px corner noise; 20 views either over the whole image or with every corner in its right
half. Ours on its defaults; the true error is the projection difference of the truth and the
estimate, aligned as the maps are. Per case, over seeds: the true error and the spread (median
where the views reached, worst beyond), their ratio, the share of pixels beyond the views whose
true error lies within 3 spreads, and how often the result notes the unreached image.

    python benchmarks/projection_uncertainty.py [--seeds 8]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from tof_calib_ros import Board, View, calibrate, sim
from tof_calib_ros.core.camera import pack_intrinsics
from tof_calib_ros.core.coverage import reach
from tof_calib_ros.core.projection_diff import projection_difference

BOARD = Board(8, 6, 0.04)
LENS = [-0.3, 0.1, 1e-3, 1e-3, 0.0]
CAMERAS = {"pmd": sim.SimCamera(np.array([284.4, 284.4, 100.0, 100.0, *LENS]), 200, 200),
           "azure": sim.SimCamera(np.array([504.0, 504.0, 320.0, 288.0, *LENS]), 640, 576)}
DISTANCE = {"pmd": (0.9, 1.6), "azure": (1.2, 2.2)}   # the board fits in half the image
N_VIEWS = 20


def scene(camera: str, half: bool, seed: int) -> list[View]:
    cam, rng = CAMERAS[camera], np.random.default_rng(seed)
    views = []
    while len(views) < N_VIEWS:
        (r, t), = sim.random_poses(cam, BOARD, 1, rng, distance=DISTANCE[camera], max_tilt_deg=40)
        frame = sim.render(cam, BOARD, r, t, noise=sim.Noise(depth=0.005, offset=0.02), rng=rng)
        if not half or frame.corners[:, 0].min() >= cam.width / 2:
            views.append(View(frame.depth, frame.corners + rng.normal(0, 0.05, frame.corners.shape)))
    return views


def trial(camera: str, half: bool, seed: int) -> dict:
    views = scene(camera, half, seed)
    result = calibrate(views, BOARD)
    estimate = pack_intrinsics(result.K, result.D)
    corners = np.concatenate([views[v.index].corners for v in result.views])
    known = reach(estimate, result.run_intrinsics, corners, result.image_size)
    error = projection_difference(CAMERAS[camera].params, estimate, result.image_size, corners).diff
    inside, beyond = known.inside & np.isfinite(error), ~known.inside & np.isfinite(error)
    row = {"camera": camera, "views": "right half" if half else "whole image", "seed": seed, "trusted": result.ok,
           "cells": known.cells, "noted": result.extrapolated is not None,
           "error_inside_px": float(np.median(error[inside])), "spread_inside_px": float(np.median(known.known)),
           "ratio_median": float(np.nanmedian(error / known.spread))}
    if beyond.any():
        row.update(error_beyond_px=float(error[beyond].max()), spread_beyond_px=float(known.beyond.max()),
                   within_3_beyond=float(np.mean(error[beyond] <= 3 * known.spread[beyond])))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--output", type=Path, default=Path(__file__).parent / "results" / "projection_uncertainty.json")
    args = ap.parse_args()
    rows = []
    print(f"{'camera':6} {'views':11} {'cells':>5} {'err in':>7} {'spread in':>9} {'err beyond':>10} "
          f"{'spread beyond':>13} {'err/spread':>10} {'within 3x':>9} {'noted':>5}")
    for camera, half in (("pmd", False), ("pmd", True), ("azure", True)):
        for seed in range(args.seeds):
            row = trial(camera, half, seed)
            rows.append(row)
            print(f"{camera:6} {row['views']:11} {row['cells']:5d} {row['error_inside_px']:7.3f} "
                  f"{row['spread_inside_px']:9.3f} {row.get('error_beyond_px', np.nan):10.3f} "
                  f"{row.get('spread_beyond_px', np.nan):13.3f} {row['ratio_median']:10.2f} "
                  f"{row.get('within_3_beyond', np.nan):9.2f} {'yes' if row['noted'] else 'no':>5}", flush=True)
    print("\nper case, over seeds: the median of (true error / spread) over the image, its range; the share of pixels "
          "beyond the views within 3 spreads, median and lowest")
    summary = []
    for camera, views in sorted({(r["camera"], r["views"]) for r in rows}):
        case = [r for r in rows if r["camera"] == camera and r["views"] == views]
        ratios = [r["ratio_median"] for r in case]
        within = [r["within_3_beyond"] for r in case if "within_3_beyond" in r]
        summary.append({"camera": camera, "views": views, "ratio_median": float(np.median(ratios)),
                        "ratio_range": [float(min(ratios)), float(max(ratios))],
                        "within_3_beyond_median": float(np.median(within)) if within else None,
                        "within_3_beyond_lowest": float(min(within)) if within else None,
                        "noted": sum(r["noted"] for r in case), "trials": len(case)})
        s = summary[-1]
        print(f"  {camera:6} {views:11}: {s['ratio_median']:.2f} ({s['ratio_range'][0]:.2f}-{s['ratio_range'][1]:.2f})"
              + (f"; within 3x {s['within_3_beyond_median']:.2f}, lowest {s['within_3_beyond_lowest']:.2f}"
                 if within else "") + f"; noted {s['noted']} of {s['trials']}")
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps({"seeds": args.seeds, "rows": rows, "summary": summary}, indent=1))


if __name__ == "__main__":
    main()
