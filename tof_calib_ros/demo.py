"""The no-hardware demo: calibrate a simulated ToF recording and compare with the truth.

    python -m tof_calib_ros.demo [--views 8] [--seed 0]

A PMD-class camera (200x200, f = 284.4, barrel distortion) watches a 8x6-corner board of
40 mm; its depth has shot noise (worse on black squares), a 20 mm offset, invalid pixels and
flying pixels at the board's edge. Corners are detected in the amplitude images, then the
views are calibrated both ways.
"""
from __future__ import annotations

import argparse

import numpy as np

from . import Board, CalibrationError, View, calibrate, sim


def simulate(n_views: int, seed: int) -> tuple[sim.SimCamera, Board, list[View]]:
    rng = np.random.default_rng(seed)
    camera, board = sim.pmd_camera(), Board(8, 6, 0.04)
    noise = sim.Noise(depth=0.004, offset=0.02, invalid_fraction=0.01, amplitude=0.003)
    poses = sim.random_poses(camera, board, n_views, rng, distance=(0.5, 0.9), max_tilt_deg=10)
    views = []
    for rvec, tvec in poses:
        frame = sim.render(camera, board, rvec, tvec, noise=noise, rng=rng, gain=0.2, background=2.0)
        views.append(View(frame.depth, amplitude=frame.amplitude))
    return camera, board, views


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--views", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    camera, board, views = simulate(args.views, args.seed)
    print(f"simulated {len(views)} views of a {board.cols}x{board.rows} board, "
          f"{camera.width}x{camera.height} px, depth offset 20 mm")
    results = {}
    for method in ("traditional", "depth"):
        try:
            results[method] = calibrate(views, board, method=method)
        except CalibrationError as exc:
            print(f"{method}: {exc}")
            results[method] = None
    truth = np.r_[camera.params[:5], 0.02]
    fields = [("fx", lambda r: r.K[0, 0], "fx"), ("fy", lambda r: r.K[1, 1], "fy"),
              ("cx", lambda r: r.K[0, 2], "cx"), ("cy", lambda r: r.K[1, 2], "cy"),
              ("k1", lambda r: r.D[0], "k1"), ("depth offset m", lambda r: r.depth_offset, "depth_offset")]
    print(f"\n{'':14} {'truth':>10} {'traditional (OpenCV)':>24} {'depth-aided (ours)':>24}")
    for (name, value, key), t in zip(fields, truth):
        cells = [f"{name:14}", f"{t:10.4f}"]
        for method in ("traditional", "depth"):
            r = results[method]
            cells.append(f"{'failed':>24}" if r is None else
                         f"{value(r):12.4f} ± {r.std.get(key, 0.0):<9.2g}")
        print(" ".join(cells))
    for method in ("traditional", "depth"):
        r = results[method]
        if r is not None:
            print(f"\n{method}: pixel RMS {r.pixel_rms:.3f} px"
                  + (f", depth RMS {r.depth_rms * 1e3:.2f} mm" if method == "depth" else "")
                  + (", verdict: good" if r.ok else ", verdict: " + "; ".join(r.verdict)))
    return 0 if results["depth"] is not None and results["depth"].ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
