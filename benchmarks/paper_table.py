"""The paper's synthetic protocol (Table 1), on sensors and lenses unlike the paper's: OpenCV
against ours on its defaults, side by side on the same views.

A 12x12-square board of 50 mm (121 interior corners) seen by a 200x200 camera with f = 284.4;
3 to 7 images, each using a 2x2 ... 6x6 sub-grid of corners spread over the board; 0.01 px
corner noise. Each calibration is scored on all 121 corners with the paper's mean 3D error:
back-project with the estimated calibration, scale to the true depth, map to the board with
the estimated pose. Sensors (``SENSORS``): the paper's own (no lens distortion, 10 mm white
depth noise) and ToF sensors with a real lens (k1 = -0.3, k2 = 0.1, p1 = p2 = 1e-3) and depth
noise that grows as the amplitude falls, with and without a range offset and black squares
read farther, with and without 15 mm of wiggling error (a sinusoid of the radial distance with a
1.87 m period, c / 8f at 20 MHz, its phase drawn per trial); on two wiggling sensors (one with a
fifth of the depth noise) ours is also told the modulation frequency (``modulation_hz``, as a
user who knows the camera would); one sensor gives the radial distance (the light's path, as raw
PMD sensors do) instead of z, ours on its defaults (which choose the convention from the data)
and told z, ROS's convention. Both pose regimes: near frontal
(tilt <= 5 deg) and general (<= 40 deg). Also printed: how often the true fx lies within two
of ours' stated standard deviations (``sigma_ok``), how often ours is trusted, and how often it is
trusted while the truth lies beyond those two sigmas (``trusted_wrong``, the worst outcome), and,
trial by trial on the same views, how often ours' error is below OpenCV's and in how many cells
ours is worse beyond chance (a sign test of the cell's trials, ``SIGN_P``).

On the first ``--bound-trials`` scenes of each cell, the Cramér-Rao bound (``sim.bound``) says
what the views can support at best: ``corner_bound``, the least 3D error of any unbiased
calibration from the corners alone with OpenCV's model (nine lens terms); ``depth_bound``, with
every depth pixel too, for a method that knows which terms the sensor has (the lens's, the black
squares' own offset, a wiggle, its period only where ours is told the modulation frequency) and
estimates them, and the depth's offset, which no ToF camera knows beforehand. OpenCV over
``depth_bound`` is about the largest ratio any method could show in that cell; ours over it, how
much of what the views hold ours leaves on the table.

    python benchmarks/paper_table.py [--trials 20] [--bound-trials 5]
                                     [--regime near-frontal|general|both] [--sensor NAME ...]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy.stats import binomtest

from tof_calib_ros import Board, CalibrationError, View, calibrate, sim
from tof_calib_ros.collect.replay import worker_context
from tof_calib_ros.core.depth_bias import wiggle_period
from tof_calib_ros.sim.bound import Bound, Scene, mean_3d_error

BOARD = Board(11, 11, 0.05)
F_TRUE = 284.4
PINHOLE = np.array([F_TRUE, F_TRUE, 99.5, 99.5, 0, 0, 0, 0, 0.0])
LENS = np.array([F_TRUE, F_TRUE, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0.0])
IMAGES = (3, 4, 5, 6, 7)
CORNERS = (4, 9, 16, 25, 36)
REGIMES = {"near-frontal": 5.0, "general": 40.0}
DISTANCE = (0.9, 1.4)
CORNER_NOISE = 0.01   # px
NINE = list(range(9))
MODULATION_HZ = 20e6
WIGGLE = dict(wiggle_amplitude=0.015, wiggle_period=wiggle_period(MODULATION_HZ))
TOF = dict(depth=0.01)                                # 10 mm on a white square at 1 m, sqrt(1/amplitude)
QUIET = dict(depth=0.002)                             # a quieter sensor (or longer exposure): 2 mm
BIAS = dict(offset=0.025, dark_offset=0.015)         # a Kinect-like offset, black squares 13 mm farther


class Sensor(NamedTuple):
    params: np.ndarray      # the camera's intrinsics
    noise: dict             # sim.Noise keywords
    told: dict              # what ours is told of the sensor (calibrate's keywords)
    convention: str = "z"   # the depth it gives
    scenes_of: str = ""     # the sensor whose scenes (seeds) it shares, where only ``told`` differs


SENSORS = {
    "paper": Sensor(PINHOLE, dict(depth_const=0.01), {}),
    "tof": Sensor(LENS, TOF, {}),
    "tof+bias": Sensor(LENS, {**TOF, **BIAS}, {}),
    "tof+wiggle": Sensor(LENS, {**TOF, **WIGGLE}, {}),
    "tof+bias+wiggle": Sensor(LENS, {**TOF, **BIAS, **WIGGLE}, {}),
    "tof+wiggle,20MHz-given": Sensor(LENS, {**TOF, **WIGGLE}, dict(modulation_hz=MODULATION_HZ)),
    "quiet-tof+wiggle,20MHz-given": Sensor(LENS, {**QUIET, **WIGGLE}, dict(modulation_hz=MODULATION_HZ)),
    # the radial distance, as raw PMD sensors give it: ours on its defaults, and told z (ROS's
    # convention, and ours' default before it chose the convention from the data)
    "radial-tof+bias": Sensor(LENS, {**TOF, **BIAS}, {}, "radial"),
    "radial-tof+bias,z-given": Sensor(LENS, {**TOF, **BIAS}, dict(depth_convention="z"), "radial",
                                      "radial-tof+bias"),
}
# Table 1 of the paper: mean 3D error in mm, [corners][images].
PAPER = {
    4: ((53.6795, 12.5422, 8.6423, 3.1773, 1.8796), (7.9059, 1.7206, 0.8978, 0.6689, 0.4144)),
    9: ((51.8946, 10.7673, 2.7336, 3.3252, 2.1771), (8.0193, 1.7345, 0.8591, 0.4818, 0.4220)),
    16: ((151.9972, 8.2549, 6.6561, 3.2660, 1.7817), (37.3031, 1.7453, 0.8137, 0.5875, 0.4384)),
    25: ((57.8784, 8.7056, 5.2105, 2.5943, 0.6113), (4.0092, 1.5235, 0.8008, 0.5373, 0.3934)),
    36: ((40.4462, 8.1659, 2.9612, 1.3889, 0.8504), (4.2415, 1.7081, 0.8109, 0.5640, 0.4449)),
}
# A cell's median can fall either side of OpenCV's by chance where both are at what the views
# support (general poses: the bound); a cell counts as worse beyond chance where ours' error is the
# larger in more of its trials than a fair coin gives at this one-sided false-alarm rate.
SIGN_P = 0.05
# Ours exactly as a user calls it: no options beyond what the sensor's entry says it is told.
METHODS = {"traditional": dict(method="traditional"), "ours": {}}


def subgrid(n: int) -> np.ndarray:
    k = int(round(np.sqrt(n)))
    sel = np.round(np.linspace(0, BOARD.cols - 1, k)).astype(int)
    return np.array([r * BOARD.cols + c for r in sel for c in sel])


def score(result, poses, camera: np.ndarray) -> float:
    """The paper's mean 3D error (mm) of a calibration result."""
    params = np.r_[result.K[0, 0], result.K[1, 1], result.K[0, 2], result.K[1, 2], result.D]
    return mean_3d_error(params, [(v.rvec, v.tvec) for v in result.views], poses,
                         sim.SimCamera(camera, 200, 200), BOARD)


def bounds(scene: Scene, seed: int, period_known: bool) -> dict:
    """The least 3D error (mm) any unbiased calibration makes on this scene: from the corners
    alone with OpenCV's model, and with the depth knowing the sensor's terms but not its offset,
    nor the wiggle's period where ours is not told the modulation frequency."""
    b = Bound(scene)
    lens = [k for k in NINE if k < 4 or scene.camera.params[k] != 0]
    wiggles = scene.noise.wiggle_amplitude > 0
    terms = ["offset"] + ["black"] * (scene.noise.dark_offset != 0) + ["wiggle"] * wiggles \
        + ["period"] * (wiggles and not period_known)
    rng = np.random.default_rng(seed)
    return dict(corner_bound=b.expected_3d_error(NINE, None, rng), depth_bound=b.expected_3d_error(lens, terms, rng))


def trial(args) -> dict:
    sensor, regime, n_img, n_corn, seed, with_bound = args
    params, noise, told, convention, _ = SENSORS[sensor]
    camera = sim.SimCamera(params, 200, 200)
    rng = np.random.default_rng(seed)
    if "wiggle_amplitude" in noise:
        noise = {**noise, "wiggle_phase": rng.uniform(0, 2 * np.pi)}
    poses = sim.random_poses(camera, BOARD, n_img, rng, distance=DISTANCE, max_tilt_deg=REGIMES[regime])
    ids = subgrid(n_corn)
    views = []
    for rvec, tvec in poses:
        frame = sim.render(camera, BOARD, rvec, tvec, convention=convention, noise=sim.Noise(**noise), rng=rng)
        views.append(View(frame.depth, frame.corners[ids] + rng.normal(0, CORNER_NOISE, (len(ids), 2)), ids))
    out = {}
    if with_bound:
        out["bound"] = bounds(Scene(camera, BOARD, poses, ids, sim.Noise(**noise), CORNER_NOISE, convention), seed,
                              "modulation_hz" in told)
    for name, kwargs in METHODS.items():
        t0 = time.perf_counter()
        try:
            res = calibrate(views, BOARD, **(kwargs if name == "traditional" else {**kwargs, **told}))
            out[name] = dict(error_mm=score(res, poses, params), focal_rel=abs(res.K[0, 0] / F_TRUE - 1),
                             sigma_ok=bool(abs(res.K[0, 0] - F_TRUE) <= 2 * res.std["fx"]), trusted=res.ok,
                             depth_gain=None if res.depth_gain is None else res.depth_gain["fx"],
                             seconds=time.perf_counter() - t0)
        except CalibrationError:
            out[name] = dict(error_mm=float("inf"), focal_rel=float("inf"), sigma_ok=False, trusted=False,
                             seconds=time.perf_counter() - t0)
    return out


def _grid(rows: list[dict], key: str, fmt: str) -> list[str]:
    lines = [f"    {'corners':>7} | " + " ".join(f"{i:>8}" for i in IMAGES) + "  (images)"]
    for c in CORNERS:
        lines.append(f"    {c:7d} | " + " ".join(format(next(r[key] for r in rows if r["corners"] == c
                                                              and r["images"] == i), fmt) for i in IMAGES))
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--bound-trials", type=int, default=5, help="scenes a cell whose Cramér-Rao bound is computed")
    ap.add_argument("--regime", choices=[*REGIMES, "both"], default="both")
    ap.add_argument("--sensor", choices=list(SENSORS), nargs="+", default=list(SENSORS))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--output", type=Path, default=Path(__file__).parent / "results" / "paper_table.json")
    args = ap.parse_args()
    regimes = list(REGIMES) if args.regime == "both" else [args.regime]
    cells = [(s, r, i, c) for s in args.sensor for r in regimes for c in CORNERS for i in IMAGES]
    jobs = [(s, r, i, c, 100000 * list(SENSORS).index(SENSORS[s].scenes_of or s) + 1000 * k + 7 * i + c
             + 50000 * list(REGIMES).index(r), k < args.bound_trials)
            for s, r, i, c in cells for k in range(args.trials)]
    t0 = time.time()
    runs = []
    with worker_context().Pool(args.jobs) as pool:   # fresh workers, not forks of this process
        for run in pool.imap(trial, jobs, chunksize=4):
            runs.append(run)
            if len(runs) % 100 == 0 or len(runs) == len(jobs):   # an hour's run says where it is
                left = (time.time() - t0) / len(runs) * (len(jobs) - len(runs))
                print(f"  {len(runs)}/{len(jobs)} trials, about {left / 60:.0f} min left", file=sys.stderr, flush=True)
    rows = []
    for s, r, i, c in cells:
        got = [o for job, o in zip(jobs, runs) if job[:4] == (s, r, i, c)]
        row = {"sensor": s, "regime": r, "images": i, "corners": c}
        if s == "paper":
            row.update(paper_traditional=PAPER[c][0][IMAGES.index(i)], paper_ours=PAPER[c][1][IMAGES.index(i)])
        for m in METHODS:
            e = np.array([g[m]["error_mm"] for g in got])
            row[m] = float(np.median(e))
            row[m + "_failures"] = int(np.sum(~np.isfinite(e)))
            row[m + "_focal_rel_error"] = float(np.median([g[m]["focal_rel"] for g in got]))
            row[m + "_seconds"] = float(np.median([g[m]["seconds"] for g in got]))
        row["ours_sigma_ok"] = float(np.mean([g["ours"]["sigma_ok"] for g in got]))
        row["ours_trusted"] = float(np.mean([g["ours"]["trusted"] for g in got]))
        # what the depth added: fx's sigma from the corners alone over ours' (result.depth_gain)
        row["ours_depth_gain"] = float(np.median([g["ours"]["depth_gain"] for g in got
                                                  if g["ours"].get("depth_gain") is not None] or [np.nan]))
        # the worst outcome: trusted, with a stated uncertainty that misses the truth
        row["ours_trusted_wrong"] = float(np.mean([g["ours"]["trusted"] and not g["ours"]["sigma_ok"] for g in got]))
        row["ratio_traditional_over_ours"] = row["traditional"] / row["ours"]
        # paired, trial by trial on the same views (a tie, both refused, counts half)
        ours_e, cv_e = (np.array([g[m]["error_mm"] for g in got]) for m in ("ours", "traditional"))
        row["ours_better"] = float(np.mean((ours_e < cv_e) + 0.5 * (ours_e == cv_e)))
        row["ours_worse_p"] = float(binomtest(int(np.sum(ours_e > cv_e)), int(np.sum(ours_e != cv_e)),
                                              alternative="greater").pvalue) if np.any(ours_e != cv_e) else 1.0
        for b in ("corner_bound", "depth_bound"):
            row[b] = float(np.median([g["bound"][b] for g in got if "bound" in g] or [np.nan]))
        # on the scenes with a bound: the most any method could gain over OpenCV, and what ours leaves
        bounded = [g for g in got if "bound" in g]
        row["ratio_traditional_over_bound"] = float(np.median([g["traditional"]["error_mm"] / g["bound"]["depth_bound"]
                                                               for g in bounded] or [np.nan]))
        row["ours_over_bound"] = float(np.median([g["ours"]["error_mm"] / g["bound"]["depth_bound"]
                                                  for g in bounded] or [np.nan]))
        rows.append(row)
    print(f"mean 3D error over all 121 corners, mm: median of {args.trials} trials a cell (a refusal counts as "
          f"inf); OpenCV and ours on its defaults on the same views; {time.time() - t0:.0f} s")
    summary = []
    for s in args.sensor:
        for r in regimes:
            sel = [x for x in rows if x["sensor"] == s and x["regime"] == r]
            ratios = np.array([x["ratio_traditional_over_ours"] for x in sel])
            line = {"sensor": s, "regime": r, "ratio_min": float(ratios.min()),
                    "ratio_median": float(np.median(ratios)),
                    "ours_max_mm": max(x["ours"] for x in sel), "opencv_max_mm": max(x["traditional"] for x in sel),
                    "ours_worse_cells": int(np.sum(ratios < 1)), "ours_failures": sum(x["ours_failures"] for x in sel),
                    "ours_better_trials": float(np.mean([x["ours_better"] for x in sel])),
                    "ours_worse_cells_sign": int(np.sum([x["ours_worse_p"] < SIGN_P for x in sel])),
                    "sigma_ok": float(np.mean([x["ours_sigma_ok"] for x in sel])),
                    "trusted": float(np.mean([x["ours_trusted"] for x in sel])),
                    "trusted_wrong": float(np.mean([x["ours_trusted_wrong"] for x in sel])),
                    "bound_ratio_min": float(np.min([x["ratio_traditional_over_bound"] for x in sel])),
                    "bound_ratio_median": float(np.median([x["ratio_traditional_over_bound"] for x in sel])),
                    "depth_bound_max_mm": float(np.max([x["depth_bound"] for x in sel])),
                    "ours_over_bound_median": float(np.median([x["ours_over_bound"] for x in sel])),
                    "ours_over_bound_max": float(np.max([x["ours_over_bound"] for x in sel]))}
            summary.append(line)
            print(f"\n{s}, {r}: OpenCV / ours from {line['ratio_min']:.1f} (median {line['ratio_median']:.1f}); "
                  f"ours at most {line['ours_max_mm']:.2f} mm (OpenCV {line['opencv_max_mm']:.2f}); worse than OpenCV "
                  f"in {line['ours_worse_cells']}/{len(sel)} cells ({line['ours_worse_cells_sign']} by the sign "
                  f"test of its trials at {SIGN_P:.0%}; ours better in {line['ours_better_trials']:.0%} of the paired "
                  "trials); "
                  f"{line['ours_failures']} failures; true fx within "
                  f"2 stated sigmas in {line['sigma_ok']:.0%}; trusted {line['trusted']:.0%}, trusted with the truth "
                  f"beyond 2 stated sigmas {line['trusted_wrong']:.0%}")
            print(f"  the bound: OpenCV / the least any depth-aided method can make from {line['bound_ratio_min']:.1f} "
                  f"(median {line['bound_ratio_median']:.1f}), that least at most {line['depth_bound_max_mm']:.2f} mm; "
                  f"ours / it {line['ours_over_bound_median']:.1f} in the median cell, "
                  f"{line['ours_over_bound_max']:.1f} at worst")
            print("  OpenCV, mm:")
            print("\n".join(_grid(sel, "traditional", "8.3f")))
            print("  ours, mm:")
            print("\n".join(_grid(sel, "ours", "8.3f")))
            print("  what the depth added to ours: fx's sigma from the corners alone over ours', each on its noise "
                  "(nan: the corners alone give none):")
            print("\n".join(_grid(sel, "ours_depth_gain", "8.1f")))
            for b, what in (("corner_bound", "from the corners alone"), ("depth_bound", "with the depth")):
                print(f"  the bound {what}, mm:")
                print("\n".join(_grid(sel, b, "8.3f")))
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(merged(args.output, args.trials, summary, rows), indent=1))
    print(f"wrote {args.output}")


def merged(path: Path, trials: int, summary: list[dict], rows: list[dict]) -> dict:
    """The results file with these rows in place of the same sensors' and regimes', the others
    kept: a run of one sensor (``--sensor``) must not drop the rest of the table."""
    old = json.loads(path.read_text()) if path.is_file() else {}
    if old.get("trials") != trials:   # a table mixes no trial counts
        old = {}
    done = {(x["sensor"], x["regime"]) for x in summary}
    order = [(s, r) for s in SENSORS for r in REGIMES]

    def key(x: dict) -> tuple:
        return order.index((x["sensor"], x["regime"])), x.get("corners", 0), x.get("images", 0)

    def kept(entries: list[dict]) -> list[dict]:
        return [x for x in entries if (x["sensor"], x["regime"]) not in done and (x["sensor"], x["regime"]) in order]

    return {"trials": trials, "summary": sorted(kept(old.get("summary", [])) + summary, key=key),
            "rows": sorted(kept(old.get("rows", [])) + rows, key=key)}


if __name__ == "__main__":
    main()
