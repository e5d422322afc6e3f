"""Real Kinect v2 ToF views (../shared/data/kinect_v2_tof): traditional against depth-aided.

1. A reference calibration from all views, by each method, with its stated uncertainty
   (OpenCV twice: k3 fixed, ROS camera_calibration's default and the baseline, and k3 free,
   OpenCV's own default), and each principal point against OpenCV's with the same lens terms;
   the downsampled runs are scored against the full-resolution references, scaled (a calibration
   of the downsampled views themselves would carry the very bias under test).
2. Its stability: the odd and the even views calibrated separately, and the first and the second
   half of the recording (the files' order), which cover other image regions and distances.
3. Few-view calibrations (3 to 7 random views, 20 draws each): focal error against the
   all-view references, and re-projection RMS on the views left out (each left-out view's
   pose found by solvePnP with the calibration under test), how often it is trusted, and how
   often it is trusted with ours' all-view fx (the best there is; no truth here) beyond 2 of
   its stated sigmas.
4. Runs of consecutive views (8, 12, 16 and 24, every 4th start; full resolution): how often
   each is trusted with fx or fy beyond 2 and 3 stated sigmas of ours' all-view result, and with
   any of fx, fy, cx, cy beyond 2 and 3 sigmas of the difference (the all-view's counted too).
At full resolution (512x424) and downsampled by 0.4 (205x170, PMD class). With
``--modulation-mhz``, ours is also run told each frequency (``modulation_hz``), as a user who
gives one of the camera's frequencies would: the Kinect v2 unwraps three (about 16, 80 and
120 MHz), so its depth error is not the one sinusoid that models, and the figures say what a
frequency given in good faith does to the result. With ``--depth-units``, ours is also run
with the depth read in those units (``depth_units``, metres a count), as a user who knows the
depth's scale from an earlier calibration would: what the few views lose to a depth scale the
data must find.

    python benchmarks/kinect_real.py [--draws 20] [--windows 8 12 16 24] [--data DIR] [--modulation-mhz 80 16]
                                     [--depth-units 0.001019]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import cv2
import numpy as np

from tof_calib_ros import Board, CalibrationError, View, calibrate
from tof_calib_ros.collect.replay import worker_context
from tof_calib_ros.core.camera import pack_intrinsics
from tof_calib_ros.core.coverage import CELLS, reach
from tof_calib_ros.core.detection import detect_corners
from tof_calib_ros.files.image_folder import load_views

BOARD = Board(5, 7, 0.03)
DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "kinect_v2_tof"
# ours on its defaults (the model chosen by the data), and the earlier fixed default beside it
METHODS = {"traditional": dict(method="traditional"),
           "traditional full": dict(method="traditional", distortion="full"),
           "ours": {},
           "ours offset-only": dict(depth_bias="offset", plane_squares="white")}
VIEW_COUNTS = (3, 4, 5, 6, 7)

_views: list[View] = []


def load(data: Path, scale: float) -> list[View]:
    """Views with a detected board; downsampling averages the IR and keeps depth's nearest pixel
    (to the pixel's centre, as the IR's average is: OpenCV's plain nearest takes the pixel at its
    corner, which put the depth half a pixel off the IR at 0.4 scale, where a ToF sensor's two
    images are one)."""
    views = []
    for stored in load_views(data):
        ir, depth = stored.amplitude, stored.depth
        if scale != 1.0:
            size = (round(ir.shape[1] * scale), round(ir.shape[0] * scale))
            ir = cv2.resize(ir, size, interpolation=cv2.INTER_AREA)
            depth = cv2.resize(depth, size, interpolation=cv2.INTER_NEAREST_EXACT)
        corners = detect_corners(ir, BOARD)
        if corners is not None:
            views.append(View(depth, corners, amplitude=ir))
    return views


def _init(views):
    global _views
    _views = views


def heldout_rms(result, views: list[View]) -> float:
    """Re-projection RMS (px) of views the calibration never saw, each posed by solvePnP."""
    err = []
    obj = BOARD.object_points()
    for v in views:
        ok, r, t = cv2.solvePnP(obj, v.corners, result.K, result.D)
        proj, _ = cv2.projectPoints(obj, r, t, result.K, result.D)
        err.append(proj[:, 0] - v.corners)
    e = np.concatenate(err)
    return float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))))


def draw(args) -> dict:
    n, seed = args
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(_views), size=n, replace=False)
    rest = [v for i, v in enumerate(_views) if i not in set(pick)]
    out = {}
    for name, kwargs in METHODS.items():
        try:
            res = calibrate([_views[i] for i in pick], BOARD, **kwargs)
            out[name] = {"fx": res.K[0, 0], "fy": res.K[1, 1], "heldout_rms": heldout_rms(res, rest),
                         "trusted": res.ok, "std_fx": res.std["fx"], "folds_widened": bool(res.model.period_spread)}
        except CalibrationError as exc:
            out[name] = {"error": str(exc)}
    return out


def focal_error(got: dict, ref) -> float:
    if "error" in got:
        return float("inf")
    return 0.5 * (abs(got["fx"] / ref[0, 0] - 1) + abs(got["fy"] / ref[1, 1] - 1))


def scaled_K(K: np.ndarray, scale: float) -> np.ndarray:
    """K of an image resized by ``scale`` (pixel centres at integer coordinates)."""
    out = K.copy()
    out[:2, :2] *= scale
    out[:2, 2] = (K[:2, 2] + 0.5) * scale - 0.5
    return out


def run_scale(views: list[View], scale: float, draws: int, jobs: int, full_refs: dict | None) -> dict:
    print(f"\n== scale {scale}: {len(views)} views with a board, image "
          f"{views[0].depth.shape[1]}x{views[0].depth.shape[0]}")
    refs, report = {}, {"scale": scale, "views": len(views), "reference": {}}
    print(f"{'method':18} {'fx':>16} {'fy':>16} {'cx':>16} {'cy':>16} {'px RMS':>7} {'s':>5}")
    for name, kwargs in METHODS.items():
        t0 = time.perf_counter()
        res = calibrate(views, BOARD, **kwargs)
        dt = time.perf_counter() - t0
        refs[name] = res
        cells = [f"{res.K[i, j]:8.2f} ±{res.std[k]:5.2f}" for (i, j), k in
                 (((0, 0), "fx"), ((1, 1), "fy"), ((0, 2), "cx"), ((1, 2), "cy"))]
        print(f"{name:18} {' '.join(f'{c:>16}' for c in cells)} {res.pixel_rms:7.3f} {dt:5.1f}  "
              f"(distortion {res.model.distortion}, depth {res.model.depth_bias}, planes {res.model.plane_squares}; "
              f"{'trusted' if res.ok else 'not trusted'})")
        if res.depth_gain is not None:
            print(f"{'':21}{res.gain_brief()}")
        report["reference"][name] = {"K": res.K.tolist(), "D": res.D.tolist(), "std": res.std,
                                     "depth_gain": res.depth_gain,
                                     "depth_bias": res.depth_bias.tolist(), "pixel_rms": res.pixel_rms,
                                     "model": res.model.to_dict(), "trusted": res.ok}
        if res.run_intrinsics is not None:   # where over the image the projection is known (core.coverage)
            known = reach(pack_intrinsics(res.K, res.D), res.run_intrinsics,
                          np.concatenate([views[v.index].corners for v in res.views]), res.image_size)
            print(f"  {'':18} each pixel's projection known to {np.median(known.known):.2f} px in the median over "
                  f"the {known.cells} of {CELLS * CELLS} cells the views reached, "
                  f"{known.beyond.max() if known.beyond.size else float('nan'):.2f} px at worst beyond them"
                  + ("; noted" if res.extrapolated is not None else ""))
            report["reference"][name]["projection_known_px"] = {
                "cells": known.cells, "inside_median": float(np.median(known.known)),
                "beyond_worst": float(known.beyond.max()) if known.beyond.size else None}
    # OpenCV's principal point moves with the lens terms it fits: against ROS's default (k3
    # fixed) and against OpenCV fitting the terms this method chose
    trad = refs["traditional"].K
    for name in METHODS:
        d = refs[name].K[:2, 2] - trad[:2, 2]
        same = calibrate(views, BOARD, method="traditional", distortion=refs[name].model.distortion)
        d_same = refs[name].K[:2, 2] - same.K[:2, 2]
        print(f"  {name:18} principal point from OpenCV's all-view: dcx {d[0]:+6.2f}  dcy {d[1]:+6.2f} px; "
              f"from OpenCV's with the same lens terms ({same.model.distortion}): "
              f"dcx {d_same[0]:+6.2f}  dcy {d_same[1]:+6.2f} px")
        report["reference"][name]["principal_point_from_opencv_px"] = d.tolist()
        report["reference"][name]["principal_point_from_opencv_same_lens_px"] = d_same.tolist()
    if full_refs is not None:
        refs = {name: scaled_K(ref, scale) for name, ref in full_refs.items()}
        print("scored against the full-resolution references, scaled: "
              + ", ".join(f"{n} fx {k[0, 0]:.2f} fy {k[1, 1]:.2f}" for n, k in refs.items()))
    else:
        refs = {name: res.K for name, res in refs.items()}
    # stability: two disjoint halves of the views, interleaved and as recorded (the first half of
    # the recording covers other image regions and distances than the second)
    n = len(views)
    for key, halves, (a, b) in (("halves", ("odd", "even"), (views[1::2], views[0::2])),
                                ("recording_halves", ("second", "first"), (views[n // 2:], views[:n // 2]))):
        print(f"stability: {halves[0]} half of the views vs {halves[1]} (difference, px, and in standard "
              "deviations of the difference)")
        report[key] = {name: halves_apart(a, b, kwargs, name, halves) for name, kwargs in METHODS.items()}
    if draws:
        report["few_view"] = few_view(views, draws, jobs, refs)
    report["refs_K"] = {n: k.tolist() for n, k in refs.items()}
    return report


def halves_apart(a: list[View], b: list[View], kwargs: dict, name: str, halves: tuple[str, str]) -> list[float] | str:
    """fx, fy, cx, cy of ``a`` less ``b``'s (the ``halves`` named), fx's and fy's relative, then
    each difference over the standard deviation of the difference the two state."""
    try:
        ra, rb = calibrate(a, BOARD, **kwargs), calibrate(b, BOARD, **kwargs)
    except CalibrationError as exc:
        print(f"  {name:18} refused: {exc}")
        return str(exc)
    keys = ("fx", "fy", "cx", "cy")
    diff = [ra.K[0, 0] - rb.K[0, 0], ra.K[1, 1] - rb.K[1, 1], ra.K[0, 2] - rb.K[0, 2], ra.K[1, 2] - rb.K[1, 2]]
    rel = [diff[0] / rb.K[0, 0], diff[1] / rb.K[1, 1]]
    sigmas = [d / np.hypot(ra.std[k], rb.std[k]) for d, k in zip(diff, keys)]
    verdict = "" if ra.ok and rb.ok else f"  (trusted: {'yes' if ra.ok else 'no'}, {'yes' if rb.ok else 'no'})"
    widened = [half for half, r in zip(halves, (ra, rb)) if r.model.period_spread]
    verdict += f"  (widened by the folds: {', '.join(widened)})" if widened else ""
    print(f"  {name:18} dfx {diff[0]:+7.2f} ({rel[0]:+.2%})  dfy {diff[1]:+7.2f} ({rel[1]:+.2%})  "
          f"dcx {diff[2]:+7.2f}  dcy {diff[3]:+7.2f};  sigmas " + " ".join(f"{z:+.1f}" for z in sigmas) + verdict)
    return diff + rel + sigmas


def few_view(views: list[View], draws: int, jobs: int, refs: dict[str, np.ndarray]) -> list[dict]:
    """Median focal error of random few-view calibrations against each all-view reference."""
    rows = []
    jobs_list = [(n, 1000 * n + k) for n in VIEW_COUNTS for k in range(draws)]
    # fresh workers: a child forked after this process's OpenCV ran may hang in its first detection
    with worker_context().Pool(jobs, initializer=_init, initargs=(views,)) as pool:
        runs = pool.map(draw, jobs_list, chunksize=1)
    names = list(METHODS)
    print(f"few-view, median of {draws} draws: relative focal error vs each all-view reference; "
          "held-out re-projection RMS (px); trusted, and trusted with ours' all-view fx beyond 2 stated sigmas; "
          "draws whose uncertainty the folds that chose the wiggle's period again widened")
    print(f"{'views':>5} | " + " | ".join(f"{m[:18]:>18} vs trad  vs ours  heldout fail trusted off widened"
                                          for m in names))
    for n in VIEW_COUNTS:
        got = [r for (nn, _), r in zip(jobs_list, runs) if nn == n]
        row = {"views": n}
        cells = []
        for m in names:
            e_t = float(np.median([focal_error(g[m], refs["traditional"]) for g in got]))
            e_o = float(np.median([focal_error(g[m], refs["ours"]) for g in got]))
            ho = [g[m]["heldout_rms"] for g in got if "error" not in g[m]]
            fails = sum("error" in g[m] for g in got)
            trusted = [g[m] for g in got if g[m].get("trusted")]
            off = sum(abs(g["fx"] - refs["ours"][0, 0]) > 2 * g["std_fx"] for g in trusted)
            widened = sum(g[m].get("folds_widened", False) for g in got)
            row[m] = {"focal_err_vs_traditional_ref": e_t, "focal_err_vs_ours_ref": e_o,
                      "heldout_rms": float(np.median(ho)) if ho else float("inf"), "failures": fails,
                      "trusted": len(trusted) / len(got), "trusted_off": off / len(got), "folds_widened": widened}
            cells.append(f"{'':18} {e_t:7.4f} {e_o:7.4f} {row[m]['heldout_rms']:7.3f} {fails:4d} "
                         f"{row[m]['trusted']:7.0%} {row[m]['trusted_off']:3.0%} {widened:7d}")
        print(f"{n:5d} | " + " | ".join(cells))
        rows.append(row)
    return rows


TERMS = ((0, 0, "fx"), (1, 1, "fy"), (0, 2, "cx"), (1, 2, "cy"))


def windows(views: list[View], lengths: list[int], ours_all: np.ndarray, ours_std: dict[str, float]) -> list[dict]:
    """Runs of consecutive views (every 4th start), as a user records who keeps the board in one
    part of the image: how often each method is trusted with fx or fy beyond 2 and 3 of its
    stated sigmas from ours' all-view result (the best there is; no truth here), and with any of
    fx, fy, cx, cy beyond 2 and 3 sigmas of the difference, the all-view result's own stated
    sigma counted too (as if the two were independent: a window is part of all the views, so
    this is the lenient one of the two)."""
    print("contiguous windows: trusted, and trusted with fx or fy beyond 2 / 3 stated sigmas of ours' all-view; "
          "with fx, fy, cx or cy beyond 2 / 3 sigmas of the difference (the all-view's sigma counted too)")
    print(f"{'views':>5} {'windows':>7} | " + " | ".join(f"{m[:18]:>18} trusted  >2 sig  >3 sig  >2 dif  >3 dif"
                                                       for m in METHODS))
    rows = []
    for length in lengths:
        row = {"views": length, "windows": 0}
        got = {m: [] for m in METHODS}
        for start in range(0, len(views) - length + 1, 4):
            row["windows"] += 1
            for m, kwargs in METHODS.items():
                try:
                    res = calibrate(views[start:start + length], BOARD, **kwargs)
                except CalibrationError:
                    continue
                off = {name: res.K[i, j] - ours_all[i, j] for i, j, name in TERMS}
                own = max(abs(off[name]) / res.std[name] for name in ("fx", "fy"))
                diff = max(abs(off[name]) / np.hypot(res.std[name], ours_std[name]) for name in off)
                got[m].append((res.ok, own, diff))
        cells = []
        for m in METHODS:
            trusted = [(own, diff) for ok, own, diff in got[m] if ok]
            row[m] = {"trusted": len(trusted), "beyond_2": sum(own > 2 for own, _ in trusted),
                      "beyond_3": sum(own > 3 for own, _ in trusted),
                      "difference_beyond_2": sum(diff > 2 for _, diff in trusted),
                      "difference_beyond_3": sum(diff > 3 for _, diff in trusted)}
            cells.append(f"{'':18} " + " ".join(f"{v:7d}" for v in row[m].values()))
        print(f"{length:5d} {row['windows']:7d} | " + " | ".join(cells))
        rows.append(row)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=20, help="few-view draws per view count; 0 skips them")
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--output", type=Path, default=Path(__file__).parent / "results" / "kinect_real.json")
    ap.add_argument("--modulation-mhz", type=float, nargs="+", default=[],
                    help="also run ours told each of these modulation frequencies")
    ap.add_argument("--windows", type=int, nargs="*", default=[8, 12, 16, 24],
                    help="lengths of the runs of consecutive views calibrated at full resolution; none skips them")
    ap.add_argument("--depth-units", type=float, nargs="+", default=[],
                    help="also run ours with the depth read in each of these units (m a count; the files are mm)")
    args = ap.parse_args()
    METHODS.update({f"ours, {f:g} MHz given": dict(modulation_hz=f * 1e6) for f in args.modulation_mhz})
    METHODS.update({f"ours, {u * 1e3:g} mm": dict(depth_units=u) for u in args.depth_units})
    if not args.data.is_dir():
        raise SystemExit(f"Kinect data not found at {args.data}")
    full_views = load(args.data, 1.0)
    full = run_scale(full_views, 1.0, args.draws, args.jobs, None)
    if args.windows:
        full["windows"] = windows(full_views, args.windows, np.array(full["refs_K"]["ours"]),
                                  full["reference"]["ours"]["std"])
    low = run_scale(load(args.data, 0.4), 0.4, args.draws, args.jobs,
                    {n: np.array(k) for n, k in full["refs_K"].items()})
    reports = [full, low]
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(reports, indent=1, default=float))
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
