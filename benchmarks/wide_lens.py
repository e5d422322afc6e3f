"""Lenses ROS's plumb_bob cannot hold: ours on its defaults against OpenCV on the same views.

The Azure Kinect depth camera's own lens (its factory model is rational_polynomial) in its wide
mode, binned to 512x512 (120 degrees, 250 px of barrel at the corners), and in its narrow mode
at 640x576, where plumb_bob with k3 holds it to about 0.1 px. Views are rendered by the
simulator through the rational model, their corners given with 0.05 px of noise, the depth
with 3 mm (1 m, white) of shot noise and a 10 mm offset. Each calibration's error: fx, cx, cy
against the truth, and how far the pixels the views reached project from where the lens puts
them (median and largest, px); whether it is trusted. Ours on its defaults (which grow the
polynomial presets only, and refuse a lens they do not hold) and asked for the rational lens;
OpenCV twice: ROS camera_calibration's default (k3 fixed) and with CALIB_RATIONAL_MODEL.

    python benchmarks/wide_lens.py [--seeds 1 2 3 4] [--views 16]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from tof_calib_ros import Board, CalibrationError, View, calibrate, sim
from tof_calib_ros.core import camera as cam

# the depth camera's factory calibration (one device's: k1..k6 of its raw model, scaled to each mode)
LENS = (4.7247, 3.2092, 1.2e-4, 5.9e-6, 0.1706, 5.0559, 4.7758, 0.8865)
CAMERAS = {"azure wide 512x512": (np.r_[252.0, 252.0, 256.5, 254.5, LENS], (512, 512), (0.35, 0.9)),
           "azure narrow 640x576": (np.r_[504.0, 504.0, 321.5, 329.0, LENS], (640, 576), (0.6, 1.6))}
BOARD = Board(8, 6, 0.05)
METHODS = {"ours": {}, "ours, rational asked": {"distortion": "rational"},
           "OpenCV (ROS default)": {"method": "traditional"},
           "OpenCV rational": {"method": "traditional", "distortion": "rational"}}


def views(camera: sim.SimCamera, n: int, distance: tuple[float, float], seed: int) -> list[View]:
    rng = np.random.default_rng(seed)
    out = []
    for rvec, tvec in sim.random_poses(camera, BOARD, n, rng, distance=distance):
        f = sim.render(camera, BOARD, rvec, tvec, noise=sim.Noise(depth=0.003, offset=0.01), rng=rng)
        out.append(View(f.depth, f.corners + rng.normal(0, 0.05, f.corners.shape)))
    return out


def scored(camera: sim.SimCamera, vs: list[View], kwargs: dict) -> dict:
    try:
        res = calibrate(vs, BOARD, **kwargs)
    except CalibrationError as exc:
        return {"refused": str(exc)}
    truth = camera.params
    reached = np.concatenate([v.corners for v in vs])
    off = np.linalg.norm(cam.project(cam.rays(reached, truth), cam.pack_intrinsics(res.K, res.D)).pixels - reached,
                         axis=1)
    return {"distortion": res.model.distortion, "trusted": res.ok, "fx_err_px": float(res.K[0, 0] - truth[0]),
            "cx_err_px": float(res.K[0, 2] - truth[2]), "cy_err_px": float(res.K[1, 2] - truth[3]),
            "std_fx": float(res.std.get("fx", np.nan)), "pixel_rms": res.pixel_rms,
            "projection_median_px": float(np.median(off)), "projection_max_px": float(off.max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4])
    ap.add_argument("--views", type=int, default=16)
    ap.add_argument("--output", type=Path, default=Path(__file__).parent / "results" / "wide_lens.json")
    args = ap.parse_args()
    rows = []
    print(f"{'camera':22} {'seed':>4} {'method':22} {'lens':9} {'trusted':7} {'fx err':>7} {'cx err':>7} "
          f"{'cy err':>7} {'proj med':>8} {'proj max':>8}")
    for name, (params, size, distance) in CAMERAS.items():
        camera = sim.SimCamera(params, *size)
        for seed in args.seeds:
            vs = views(camera, args.views, distance, seed)
            for method, kwargs in METHODS.items():
                row = {"camera": name, "seed": seed, "method": method, **scored(camera, vs, kwargs)}
                rows.append(row)
                if "refused" in row:
                    print(f"{name:22} {seed:4d} {method:22} refused: {row['refused'][:60]}")
                    continue
                print(f"{name:22} {seed:4d} {method:22} {row['distortion']:9} {str(row['trusted']):7} "
                      f"{row['fx_err_px']:+7.2f} {row['cx_err_px']:+7.2f} {row['cy_err_px']:+7.2f} "
                      f"{row['projection_median_px']:8.3f} {row['projection_max_px']:8.2f}", flush=True)
    print("\nmedian over seeds: projection error where the views reached (px), |fx error| (px), trusted")
    for name in CAMERAS:
        for method in METHODS:
            got = [r for r in rows if r["camera"] == name and r["method"] == method and "refused" not in r]
            if got:
                print(f"  {name:22} {method:22} {np.median([r['projection_median_px'] for r in got]):7.3f} "
                      f"{np.median([abs(r['fx_err_px']) for r in got]):7.2f}  "
                      f"{sum(r['trusted'] for r in got)} of {len(got)}")
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps({"seeds": args.seeds, "views": args.views, "rows": rows}, indent=1))
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
