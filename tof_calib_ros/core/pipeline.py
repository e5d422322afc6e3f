"""The depth-aided calibration (the paper's Algorithm 1), and the traditional baseline.

1. traditional calibration (OpenCV) as a first guess; a guess from the depth alone where
   OpenCV refuses or diverges;
2. planarize each view's depth at its corners;
3. update K (and the depth offset) until the squares have their true size in 3D,
   re-planarizing with each new K;
4. re-initialise the poses from the 3D corners and update the distortion;
5. the joint LM over pixel and depth residuals, each view weighted by its own variances,
   with the depth bias estimated alongside (beyond the paper: real ToF depth is offset).
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import NamedTuple

import cv2
import numpy as np
from scipy.stats import chi2 as scipy_chi2
from scipy.stats import f as scipy_f
from scipy.stats import norm as scipy_norm

from . import bundle
from . import depth_bias as bias_model
from .board import Board, whole_number
from .camera import N_INTRINSICS, depth_of, split_intrinsics, transform_views
from .depth_init import focal_guess, pose_from_pixels, pose_from_points, square_from_depth, update_intrinsics
from .detection import Detection, detect
from .errors import CalibrationError
from .options import DISTORTION_TERMS, CalibrationOptions, Model
from .planarize import (
    DepthSamples,
    Plane,
    board_samples,
    corner_depth_along,
    directions,
    fit_plane_to,
    fit_samples,
    off_plane,
    planar_part,
    sample_depth,
    smoothed,
)
from .result import (
    INTRINSIC_NAMES,
    MAX_CORNER_DEPTH_DISAGREEMENT,
    CalibrationResult,
    Focal,
    ViewReport,
    corners_pulled,
    focal_disagreements,
    noise_per_dof,
)
from .threads import single_threaded
from .traditional import Traditional, calibrate_opencv

MIN_PARALLEL_SPREAD_DEG = 0.05  # about the precision of a plane-fit normal
CONTRADICTION_DEG = 5.0  # corners this far apart in tilt cannot be boards the depth shows parallel
NO_BOARD = "no board found"
MAX_OUTER_ROUNDS = 6
OUTLIER_SIGMAS = 6.0  # with a robust loss, corners this far off are dropped and the views recalibrated
PLANE_DOF = 3.0  # a view's denoised corner depths are one plane: three independent numbers
DEPTH_UNITS_RANGE = (1e-6, 1.0)  # metres per unit: micrometres to metres
MIN_SPREAD_PX = 0.5  # corners closer than this (RMS) to one line in the image say nothing across it
BLACK_APART_SIGMAS = 5.0  # a black-square offset this many standard errors from 0 keeps them out of the planes
DEPTH_INFLATION_STEP = 2.0  # the depth's error is raised by this factor until the corners fit as well as alone
MAX_DEPTH_INFLATION = 64.0  # and at most to this many times its noise: the depth is then all but silent
MIN_SQUARE_PIXELS = 30  # fewer pixels of one colour say nothing of its offset or its bow
# A depth level this many standard errors from the corners' is a depth scale. Low, since what it
# sets off is mild (a scale term, which the corners fix) and what a miss costs is not: in general
# poses with 15 mm of wiggling, 5 standard errors (and the level as the scale's prior) left fx
# beyond 2 of its sigmas in 4 of 10 seeds, 2 in 1 of 10; no scale was taken in 16 scenes without
# wiggling.
EXCESS_SIGMAS = 2.0
CORNER_FOLDS = 5  # folds of the views for the corners' own focal-length spread
MIN_DISTANCE_SPREAD = 0.05  # views whose distances spread less (relative) are at one distance
STRUCTURE_P = 0.001  # the F-test's false-alarm rate for a depth error that follows the distance
BOWL_SIGMAS = 3.0  # a radial intercept this many standard errors from 0 (pooled, or view by view at the same
#                   false-alarm rate): the depth error is not planar in z
# Without the modulation frequency, the periods looked for: those of 8 to 130 MHz (4.7 to 0.29 m),
# a factor 1.26 apart, over which the wiggle across a board's distances changes little.
WIGGLE_CANDIDATES_HZ = np.geomspace(8e6, 130e6, 13)
WIGGLE_PRICE_TERMS = 3  # its sine, cosine and period, at the information criterion's ln(n) each
# A wiggle larger than this is a depth scale in disguise (a square half its size gave one of 0.5 m
# at 10 MHz); ToF cameras wiggle by millimetres to a few centimetres.
MAX_WIGGLE_M = 0.1
WIGGLE_P = 0.001  # and its amplitude beyond its views' jackknife at this false-alarm rate
MIN_MODEL_WEIGHT = 1e-3  # depth models this much less likely than the rest together are not refitted


@dataclass
class View:
    """One frame: the depth image plus either the amplitude image or already-detected corners.

    ``depth`` is in metres when float, in millimetres when integer (see ``depth_units``);
    0 and NaN are invalid. ``ids`` are the board indices of ``corners`` (default: all, in order).
    """

    depth: np.ndarray
    corners: np.ndarray | None = None
    ids: np.ndarray | None = None
    amplitude: np.ndarray | None = None


@dataclass
class _Prepared:
    index: int
    depth: np.ndarray          # metres, NaN invalid
    corners: np.ndarray
    ids: np.ndarray
    amplitude: np.ndarray | None


# ToF cameras measure to some tens of metres at most: farther is a driver's sentinel (65535 mm) or
# a glitch, and left in, such values overflow the plane fits.
MAX_DEPTH_M = 50.0


def depth_units(depth: np.ndarray) -> float:
    """Metres a count, unless told: integer images are millimetres, float ones metres."""
    return 1e-3 if np.issubdtype(np.asarray(depth).dtype, np.integer) else 1.0


def depth_in_metres(depth: np.ndarray, units: float | None = None) -> np.ndarray:
    """Float metres with NaN for invalid pixels (``units`` as ``depth_units`` unless told):
    0, NaN and anything beyond ``MAX_DEPTH_M``."""
    d = np.asarray(depth)
    with np.errstate(over="ignore", invalid="ignore"):
        out = d.astype(np.float64) * (depth_units(d) if units is None else units)
        out[~(out > 0) | ~(out <= MAX_DEPTH_M)] = np.nan
    return out


def _check_arguments(views: Sequence[View], board: Board, image_size: tuple[int, int] | None,
                     depth_units: float | None, min_views: int, progress: Callable[[str], None] | None) -> None:
    """The caller's own mistakes (a wrong type, a size of zero) named before any work is done."""
    if not isinstance(board, Board):
        raise CalibrationError(f"board must be a Board, got {type(board).__name__}")
    if not isinstance(views, Sequence) or isinstance(views, str):
        raise CalibrationError(f"views must be a list of View, got {type(views).__name__}")
    for i, v in enumerate(views):
        if not isinstance(v, View):
            raise CalibrationError(f"view {i} is not a View but {type(v).__name__}")
    if image_size is not None:
        size = [whole_number(n) for n in image_size] if isinstance(image_size, (Sequence, np.ndarray)) else []
        if len(size) != 2 or None in size or min(size) < 1:
            raise CalibrationError(f"image_size must be (width, height) in pixels, got {image_size!r}")
    if depth_units is not None and (isinstance(depth_units, (bool, np.bool_))
                                    or not isinstance(depth_units, (int, float, np.integer, np.floating))
                                    or not DEPTH_UNITS_RANGE[0] <= depth_units <= DEPTH_UNITS_RANGE[1]):
        raise CalibrationError(f"depth_units must be metres per unit of the depth images, from {DEPTH_UNITS_RANGE[0]}"
                               f" to {DEPTH_UNITS_RANGE[1]}, got {depth_units!r}")
    if whole_number(min_views) is None or min_views < 2:
        raise CalibrationError(f"min_views must be a whole number of at least 2 (one view cannot tell the focal "
                               f"length from the distance), got {min_views!r}")
    if progress is not None and not callable(progress):
        raise CalibrationError(f"progress must be a function taking one line of text, got {progress!r}")


def _prepare(views: Sequence[View], board: Board, image_size: tuple[int, int] | None,
             depth_units: float | None) -> tuple[list[_Prepared], dict[int, str], tuple[int, int]]:
    if len(views) == 0:
        raise CalibrationError("no views given")
    if image_size is None:
        shape = np.asarray(views[0].depth).shape
        if len(shape) != 2:
            raise CalibrationError(f"view 0: depth must be a 2-D image, got shape {shape}")
        image_size = (shape[1], shape[0])
    w, h = image_size
    kept, rejected = [], {}
    for i, v in enumerate(views):
        depth = np.asarray(v.depth)
        if not (np.issubdtype(depth.dtype, np.integer) or np.issubdtype(depth.dtype, np.floating)):
            raise CalibrationError(f"view {i}: depth must be an integer or float image, got {depth.dtype}")
        if depth.shape != (h, w):
            raise CalibrationError(f"view {i}: depth image is {depth.shape[1] if depth.ndim == 2 else '?'}x"
                                   f"{depth.shape[0]} but the image size is {w}x{h}")
        if v.amplitude is not None and np.asarray(v.amplitude).shape[:2] != (h, w):
            raise CalibrationError(f"view {i}: amplitude image size {np.asarray(v.amplitude).shape[:2][::-1]} "
                                   f"differs from the depth image size {(w, h)}")
        corners, ids = v.corners, v.ids
        if corners is None:
            if v.amplitude is None:
                raise CalibrationError(f"view {i}: give either the amplitude image or the corners")
            try:
                found = detect(np.asarray(v.amplitude), board)
            except CalibrationError as exc:
                found = Detection(None, str(exc))
            if found.corners is None:
                rejected[i] = f"{NO_BOARD}: {found.message}"
                continue
            corners = found.corners
        try:
            corners = np.asarray(corners, dtype=float).reshape(-1, 2)
            ids = None if ids is None else np.asarray(ids, dtype=int).ravel()
        except (TypeError, ValueError):
            raise CalibrationError(f"view {i}: corners must be (N, 2) pixels and ids N board indices") from None
        if ids is None:
            if len(corners) != board.n_corners:
                raise CalibrationError(f"view {i}: {len(corners)} corners for a {board.cols}x{board.rows} "
                                       "board; pass ids for a partial set")
            ids = np.arange(board.n_corners)
        if len(ids) != len(corners) or len(np.unique(ids)) != len(ids) \
                or (ids.size and (ids.min() < 0 or ids.max() >= board.n_corners)):
            raise CalibrationError(f"view {i}: corner ids must be distinct board indices, one per corner")
        if not np.all(np.isfinite(corners)):
            raise CalibrationError(f"view {i}: corners contain NaN or inf")
        if len(corners) < 4:
            rejected[i] = f"only {len(corners)} corners (need 4)"
            continue
        if np.any((corners < -0.5) | (corners > np.array([w, h]) - 0.5)):
            rejected[i] = f"corners lie outside the {w}x{h} image"
            continue
        if _on_a_line(board.object_points(ids)[:, :2]):
            rejected[i] = "its corners lie on one line of the board (give corners off that line too)"
            continue
        if _on_a_line(corners, MIN_SPREAD_PX):
            rejected[i] = "its corners lie on one line in the image (a board seen edge on?)"
            continue
        kept.append(_Prepared(i, depth_in_metres(depth, depth_units), corners, ids,
                              None if v.amplitude is None else np.asarray(v.amplitude)))
    return kept, rejected, (int(w), int(h))


def _on_a_line(points: np.ndarray, tolerance: float = 0.0) -> bool:
    """True when the points' RMS distance from their best line is at most ``tolerance``
    (relative to their spread along it when 0): a homography needs points off any line."""
    centred = points - points.mean(0)
    major, minor = np.linalg.svd(centred, compute_uv=False) / np.sqrt(len(points))
    return bool(minor <= max(tolerance, 1e-9 * major))


def _require(views: list[_Prepared], rejected: dict[int, str], min_views: int, n_given: int) -> None:
    if len(views) >= min_views:
        return
    why = "; ".join(f"view {k}: {r}" for k, r in sorted(rejected.items()))
    if not views and rejected and all(r.startswith(NO_BOARD) for r in rejected.values()):
        raise CalibrationError(f"no board found in any of the {n_given} views")
    raise CalibrationError(f"too few usable views: {len(views)} of {n_given}, need at least {min_views}"
                           + (f" ({why})" if why else ""))


class _PlaneSamples:
    """Every view's plane samples, with the distinct pixels among them: views share pixels,
    and undistorting each distinct pixel once is what keeps hundreds of views fast."""

    def __init__(self, samples: list[DepthSamples | None], width: int):
        self.samples = samples
        with_depth = [s for s in samples if s is not None]
        pix = np.concatenate([s.pixels for s in with_depth]).astype(int)
        distinct, self.index = np.unique(pix[:, 1] * width + pix[:, 0], return_inverse=True)
        self.distinct = np.column_stack([distinct % width, distinct // width]).astype(float)
        self.cuts = np.cumsum([len(s.pixels) for s in with_depth])[:-1]

    def directions(self, intr: np.ndarray, convention: str) -> list[np.ndarray | None]:
        parts = iter(np.split(directions(self.distinct, intr, convention)[self.index], self.cuts))
        return [None if s is None else next(parts) for s in self.samples]


class _Planarized(NamedTuple):
    """Each view's corner depths as the camera would report them, depth error floor, plane, and
    what its depth off the plane says of a wiggle (where there is one) and of a radial offset."""
    depths: list[np.ndarray]
    floors: list[float]
    planes: list[Plane | None]
    wiggles: list[bundle.WiggleShape | None]
    radials: list[bundle.RadialShape | None]


def _planarize_all(views: list[_Prepared], samples: _PlaneSamples, intr: np.ndarray, bias: np.ndarray,
                   convention: str, period: float | None = None, radial: bool = False) -> _Planarized:
    """The views planarized (the plane is fitted to depth corrected by the bias's planar terms and
    its radial offset, where the board really is flat), and where there is a wiggle (``period``)
    what each view's depth says of it, and of a radial offset where one may be in the model
    (``radial``, ``_radial_may_enter``).
    The wiggle is not corrected before the plane is fitted: the plane would then depend on the
    wiggle's estimate, which near frontal settles on a wrong offset and wiggle that agree with the
    planes they shaped (1.7 % in fx on noiseless views). Instead the plane keeps the wiggle's planar
    part, and the fit predicts that part, and the depth off the plane (``bundle.WiggleShape``).
    A view without usable depth gets NaN depths: it counts with its corners only."""
    depths, floors, planes, shapes, radials = _planarize_periods(views, samples, intr, bias, convention,
                                                                 [] if period is None else [period], radial)
    return _Planarized(depths, floors, planes, [s[0] if s else None for s in shapes], radials)


def _planarize_periods(views: list[_Prepared], samples: _PlaneSamples, intr: np.ndarray, bias: np.ndarray,
                       convention: str, periods: Sequence[float], radial: bool
                       ) -> tuple[list[np.ndarray], list[float], list[Plane | None], list[list[bundle.WiggleShape]],
                                  list[bundle.RadialShape | None]]:
    """``_planarize_all`` with what each view's depth says of a wiggle of each of ``periods``:
    the planes once for them all."""
    corner_dirs = np.split(directions(np.concatenate([v.corners for v in views]), intr, convention),
                           np.cumsum([len(v.corners) for v in views])[:-1])
    planar = bias.copy()
    planar[bias_model.TERMS["wiggle"]] = 0.0
    depths, floors, planes, shapes, radials = [], [], [], [], []
    for v, smp, su, u in zip(views, samples.samples, samples.directions(intr, convention), corner_dirs):
        if smp is None:
            depths.append(np.full(len(v.corners), np.nan))
            floors.append(0.0)
            planes.append(None)
            shapes.append([])
            radials.append(None)
            continue
        flat = bias_model.true_depth(planar, smp.depth, su)
        plane = fit_plane_to(su, flat, smp.pixels, smp.black)
        d, se = corner_depth_along(plane, u)
        depths.append(bias_model.measured(planar, d, u * d[:, None]))
        floors.append(float(np.median(se) * (1 + bias[1])))
        planes.append(plane)
        shapes.append(_wiggle_shapes(plane, su, flat, bias, planar, smp, u, periods) if periods else [])
        radials.append(_radial_shape(plane, su, flat, planar, smp, u, d) if radial else None)
    return depths, floors, planes, shapes, radials


def _radial_may_enter(options: CalibrationOptions) -> bool:
    """Whether a radial offset may be in the depth model: asked for, or one the data may choose
    (z-depth, without the modulation frequency, where the search for a wiggle weighs it). Its
    shapes cost a quarter of the planarization, for nothing elsewhere."""
    if options.depth_bias == "auto":
        return options.depth_convention == "z" and options.modulation_hz is None
    return bias_model.TERMS["radial"][0] in bias_model.parse(options.depth_bias)


def _radial_shape(plane: Plane, su: np.ndarray, flat: np.ndarray, planar: np.ndarray, smp: DepthSamples,
                  u: np.ndarray, d: np.ndarray) -> bundle.RadialShape:
    """What a view's depth says of a radial offset beyond the one taken out before its plane was
    fitted (bundle.RadialShape; ``u`` and ``d``: the corners' directions and depths on the plane):
    a plane takes the offset's planar part and leaves its bow, which is what tells it from the
    depth offset."""
    unit = np.zeros(bias_model.N_BIAS)
    unit[bias_model.TERMS["radial"]] = 1.0
    basis = flat - bias_model.true_depth(planar + unit, smp.depth, su)   # a unit radial offset at the samples
    information, moment = off_plane(plane, su, flat, smp.black, basis[:, None])
    kept = d + planar_part(plane, su, flat, smp.black, basis[:, None], u)[:, 0]
    moved = bias_model.measured(planar, kept, u * kept[:, None]) - bias_model.measured(planar, d, u * d[:, None])
    at = float(planar[bias_model.TERMS["radial"]][0])
    return bundle.RadialShape(float(information[0, 0]), float(moment[0] + information[0, 0] * at),
                              1 / np.linalg.norm(u, axis=1) - moved, at)


def _wiggle_shapes(plane: Plane, su: np.ndarray, flat: np.ndarray, bias: np.ndarray, planar: np.ndarray,
                   smp: DepthSamples, u: np.ndarray, periods: Sequence[float]) -> list[bundle.WiggleShape]:
    """What a view's depth says of a wiggle of each period: each basis term at the corners (along
    ``u``) less the part of it a plane fitted over the samples keeps, and the samples' depth off
    the plane (``flat``: their depth as the plane was fitted to it, with ``planar``, the bias less
    its wiggle, taken out). The basis is placed at the samples' smoothed depth with the bias's
    estimate removed: at each sample's own, its noise would enter the basis and bias what the
    depth off the plane says (by k sigma^2 a sample: 10 times the wiggle near frontal). At the
    corners it is placed on the plane of that depth: on the fitted plane, which holds the
    wiggle's planar part, the fit's depth model was 0.2-0.35 mm off at the true parameters with
    15 mm of wiggling, which near frontal moved fx by up to 1 px."""
    wiggle = bias[bias_model.TERMS["wiggle"]]
    fitted = smoothed(plane, su, flat)
    on_plane = bias_model.measured(planar, fitted, su * fitted[:, None])
    along_su, along_u = np.linalg.norm(su, axis=1), np.linalg.norm(u, axis=1)
    bases, curves = [], []
    for period in periods:
        corrected = bias_model.true_depth(bias, on_plane, su, period)
        basis = bias_model.wiggle_basis(period, corrected, corrected * along_su)
        clean = flat - basis @ wiggle
        # without a wiggle estimate yet (a search over periods) the plane is the one fitted already
        at_plane = fit_plane_to(su, clean, smp.pixels, smp.black) if wiggle.any() else plane
        at, _ = corner_depth_along(at_plane, u)
        curves.append(bias_model.wiggle_basis(period, at, at * along_u)
                      - planar_part(at_plane, su, clean, smp.black, basis, u))
        bases.append(basis)
    # the samples off the plane, for every period at once: their noise weights are shared
    information, moment = off_plane(plane, su, flat, smp.black, np.hstack(bases))
    return [bundle.WiggleShape(c, information[2 * k:2 * k + 2, 2 * k:2 * k + 2], moment[2 * k:2 * k + 2])
            for k, c in enumerate(curves)]


def _observations(obj, views: list[_Prepared], depths, floors, wiggles, radials,
                  inflation: float = 1.0) -> list[bundle.Observations]:
    return [bundle.Observations(o, v.corners, d, f, PLANE_DOF, w, inflation, r)
            for o, v, d, f, w, r in zip(obj, views, depths, floors, wiggles, radials)]


def _spread_deg(normals: np.ndarray) -> float:
    mean = normals.mean(0)
    mean /= np.linalg.norm(mean)
    return float(np.degrees(np.arccos(np.clip(normals @ mean, -1, 1))).max())


def _check_not_parallel(planes: list[Plane], corner_poses: np.ndarray | None) -> None:
    """Refuse views whose depth planes all face one way; ``corner_poses`` (OpenCV's, from the
    corners alone) tell a board held at one tilt from depth images that do not show the board."""
    spread = _spread_deg(np.array([p.normal for p in planes]))
    if len(planes) < 2 or spread >= MIN_PARALLEL_SPREAD_DEG:
        return
    if corner_poses is not None:
        n = len(corner_poses)
        rotations = np.c_[corner_poses[:, :3], np.zeros((n, 3))]
        tilts = _spread_deg(transform_views(rotations, np.tile([0.0, 0.0, 1.0], (n, 1)), np.arange(n))[0])
        if tilts > CONTRADICTION_DEG:
            raise CalibrationError(f"the depth shows all {len(planes)} views at one orientation (within {spread:.2f} "
                                   f"deg) but the corners show boards {tilts:.0f} deg apart: the depth images do "
                                   "not show the board (constant depth? depth of other frames?)")
    raise CalibrationError(f"all {len(planes)} views show the board at the same orientation "
                           f"(within {spread:.2f} deg): tilt the board differently between views")


def _k_update(views, samples, board, intr, bias, convention, estimate_offset, max_iter=10):
    """The paper's lines 4-9: update K, re-planarize, until K settles."""
    err = np.inf
    for _ in range(max_iter):
        depths = _planarize_all(views, samples, intr, bias, convention).depths
        new, offset, err = update_intrinsics(intr, [v.corners for v in views], depths,
                                             [board.object_points(v.ids) for v in views], convention,
                                             estimate_offset)
        settled = abs(new[0] - intr[0]) < 1e-7 * intr[0] and abs(offset - bias[0]) < 1e-7
        intr, bias = new, np.r_[offset, bias[1:]]
        if settled:
            break
    return intr, bias, err


def _report(views: list[_Prepared], fit: bundle.Fit, planes: list[Plane] | None) -> list[ViewReport]:
    out = []
    for j, v in enumerate(views):
        pix, dep = fit.pixel_residuals[j], fit.depth_residuals[j]
        fin = dep[np.isfinite(dep)]
        out.append(ViewReport(
            v.index, fit.state.poses[j, :3].copy(), fit.state.poses[j, 3:].copy(),
            float(np.sqrt(np.mean(np.sum(pix ** 2, axis=1)))),
            float(np.sqrt(np.mean(fin ** 2))) if fin.size else float("nan"), pix, dep,
            planes[j].sigma if planes and planes[j] else float("nan"),
            len(planes[j].pixels) if planes and planes[j] else 0,
            planes[j].coef.copy() if planes and planes[j] else None))
    return out


def _std(fit: bundle.Fit) -> dict[str, float]:
    names = list(INTRINSIC_NAMES) + list(bias_model.NAMES)
    std = {n: 0.0 for n in names}
    for k, i in enumerate(fit.free_global):
        std[names[i]] = float(np.sqrt(max(fit.covariance[k, k], 0.0)))
    return std


def _corner_fit(obj: list[np.ndarray], views: list[_Prepared], trad: Traditional, convention: str,
                lens: str) -> bundle.Fit:
    """OpenCV's solution (``lens``: the distortion terms it fitted) with the uncertainties of a
    corners-only fit, from the sparse joint fit (calibrateCameraExtended's dense covariance
    takes 10x calibrateCamera's time at 200 views)."""
    state = bundle.State(trad.intrinsics.copy(), np.zeros(bias_model.N_BIAS), trad.poses.copy())
    nodepth = [bundle.Observations(o, v.corners, np.full(len(o), np.nan)) for o, v in zip(obj, views)]
    return bundle.solve(nodepth, state, convention, [0, 1, 2, 3, *DISTORTION_TERMS[lens]], rounds=1, max_iter=0)


def _result(options: CalibrationOptions, model: Model, board: Board, image_size, fit, views, planes, rejected,
            notes, corner_fit: bundle.Fit | None = None, noise_fit: bundle.Fit | None = None,
            depth_focal: Focal | None = None) -> CalibrationResult:
    """``noise_fit``: the fit with the covariance its noise gives, where ``fit``'s was raised (by the
    fits of other depth models, by the views' jackknife). ``depth_focal``: see CalibrationResult."""
    K, D = split_intrinsics(fit.state.intrinsics)
    if not (np.all(np.isfinite(fit.state.intrinsics)) and np.all(np.isfinite(fit.state.bias))):
        raise CalibrationError("the joint fit diverged (non-finite parameters)")  # never NaN in a CameraInfo
    corner_focal = corner_noise = None
    if corner_fit is not None:
        corner_focal = _focal(corner_fit)
        corner_noise = noise_per_dof(corner_fit.pixel_residuals, len(corner_fit.free_global))
    return CalibrationResult(options.method, image_size, options.depth_convention, K, D, fit.state.bias.copy(),
                             _std(fit), _report(views, fit, planes), rejected, notes, corner_focal, options, model,
                             board.square, corner_noise=corner_noise, noise_std=_std(noise_fit or fit),
                             depth_focal=depth_focal)


def calibrate(views: Sequence[View], board: Board, image_size: tuple[int, int] | None = None,
              depth_convention: str = "z", method: str = "depth", *, depth_units: float | None = None,
              depth_bias: str = "auto", distortion: str = "auto", loss: str | None = None,
              plane_squares: str = "auto", min_views: int = 3, modulation_hz: float | None = None,
              progress: Callable[[str], None] | None = None) -> CalibrationResult:
    """Calibrate a ToF camera from checkerboard views.

    ``image_size`` is (width, height), taken from the depth images when not given.
    ``method='traditional'`` is OpenCV's Zhang calibration on the same corners (the baseline,
    with the ``distortion`` preset asked for);
    ``'depth'`` is the depth-aided method. The model is chosen by the data where an option is
    'auto' (the defaults): the distortion terms, the depth error terms and the squares the depth
    planes use; see ``CalibrationOptions`` for the choices, and ``result.model`` for what was
    chosen and why. ``loss`` 'huber' or 'cauchy' makes the fit robust to misdetected corners.
    Raises CalibrationError with the reason when the options are wrong or the views cannot be
    calibrated; check ``result.verdict`` before trusting a result.
    """
    _check_arguments(views, board, image_size, depth_units, min_views, progress)
    options = CalibrationOptions(method, depth_convention, depth_units, depth_bias, distortion, loss, plane_squares,
                                 min_views, modulation_hz)
    try:
        return _calibrate_with_loss(views, board, image_size, options, progress)
    except CalibrationError:   # a ValueError too, and already the caller's
        raise
    except (cv2.error, np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
        # views no check above foresaw (OpenCV asserting on a degenerate set, a singular system):
        # the caller gets a CalibrationError, as for every other refusal
        raise CalibrationError(f"the views cannot be calibrated: {type(exc).__name__}: "
                               f"{' '.join(str(exc).split())[:200]}") from exc


def _calibrate_with_loss(views, board, image_size, options: CalibrationOptions, progress) -> CalibrationResult:
    with single_threaded():
        result = _calibrate(views, board, image_size, options, progress)
        if options.loss is None:
            return result
        # A robust loss bounds a misdetected corner's pull but still lets it shape the first
        # guesses and the planes: drop the corners it exposed and calibrate once more.
        dropped = _outlier_corners(result, views, board)
        if not dropped:
            return result
        cleaned = [View(v.depth, *_without(v, board, dropped.get(i, [])), v.amplitude)
                   for i, v in enumerate(views)]
        again = _calibrate(cleaned, board, image_size, options, progress)
        again.model.dropped_corners = dropped
        again.notes.append("dropped outlier corners (view: board indices): "
                           + "; ".join(f"{i}: {ids}" for i, ids in sorted(dropped.items())))
        return again


def _outlier_corners(result: CalibrationResult, views: Sequence[View], board: Board) -> dict[int, list[int]]:
    """Board indices, per view, of corners over OUTLIER_SIGMAS robust sigmas from the fit."""
    out = {}
    for rep in result.views:
        e = np.hypot(rep.pixel_residuals[:, 0], rep.pixel_residuals[:, 1])
        sigma = np.median(e) / bundle.RAYLEIGH_MEDIAN
        bad = np.flatnonzero(e > OUTLIER_SIGMAS * max(sigma, 1e-6))
        if bad.size:
            v = views[rep.index]
            ids = np.arange(board.n_corners) if v.ids is None else np.asarray(v.ids)
            out[rep.index] = [int(k) for k in ids[bad]]
    return out


def _without(view: View, board: Board, drop: list[int]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The view's corners and ids less the dropped board indices (detected corners are kept as
    detected: they are re-detected identically)."""
    if not drop:
        return view.corners, view.ids
    ids = np.arange(board.n_corners) if view.ids is None else np.asarray(view.ids)
    corners = view.corners if view.corners is not None else detect(np.asarray(view.amplitude), board).corners
    keep = ~np.isin(ids, drop)
    return np.asarray(corners)[keep], ids[keep]


def _black_reads_apart(offsets: list[tuple[float, float]]) -> tuple[bool, str]:
    """Whether the black squares read at another range than the white ones: each view's median
    black-minus-white-plane depth and its standard error, pooled. Any difference the data can
    see keeps the black squares out of the planes (a Kinect v2 reads them 4 mm farther)."""
    if not offsets:
        return True, "no black-square depth to compare: planes on the white squares"
    d, se = np.array(offsets).T
    w = 1 / np.maximum(se, 1e-6) ** 2
    mean, err = float(np.sum(w * d) / np.sum(w)), float(1 / np.sqrt(np.sum(w)))
    apart = abs(mean) > BLACK_APART_SIGMAS * err
    return apart, (f"black squares read {mean * 1e3:+.2f} ± {err * 1e3:.2f} mm from the white squares' plane: "
                   + ("planes on the white squares only" if apart else "planes on the whole board"))


def _black_offset(smp: DepthSamples, plane: Plane, intr: np.ndarray, convention: str) -> tuple[float, float] | None:
    """A view's median black-square depth off its white-square plane, with its standard error."""
    black = smp.subset(smp.black)
    if len(black.depth) < MIN_SQUARE_PIXELS:
        return None
    r = black.depth - corner_depth_along(plane, directions(black.pixels, intr, convention))[0]
    r = r[np.isfinite(r)]
    if len(r) < MIN_SQUARE_PIXELS:
        return None
    mad = 1.4826 * np.median(np.abs(r - np.median(r)))
    return float(np.median(r)), float(1.2533 * mad / np.sqrt(len(r)))


def _select_model(observations: list[bundle.Observations], state: bundle.State, convention: str,
                  options: CalibrationOptions, say: Callable[[str], None],
                  radial: bool = False) -> tuple[bundle.State, list[int], Model]:
    """The terms the data call for, against the Bayesian information criterion: a term is taken
    when the likelihood-ratio statistic it brings exceeds ln(n) per parameter, n being the
    independent measurements. The statistic is the larger of the score test (the first-order drop
    in the whitened cost, at the noise the smaller fit assumed) and the drop in deviance of the
    refitted model, each view's noise re-estimated: where a missing term (k1 of a strong lens)
    inflates the noise the smaller fit assumes, the score test understates it and a trusted
    focal length came out 3 % off; where a refit lands short (an LM start far off), the score
    test still sees it. Distortion grows along its presets
    (k1, k2, then p1 p2, then k3); because the depth fixes each view's pose, it is observable
    from 4 corners a view. The depth always has its offset; the tilt (a driver's z-depth
    computed about another centre) is taken when it pays. Where the modulation frequency is
    given, the wiggle is always estimated: near frontal views cannot tell it from the focal
    length (its slope over their distances is a depth scale), so a test of it there would
    pass it over and trust a focal length it has bent; estimated, its uncertainty is the
    focal length's. Not given, the caller looks for one at the model chosen without it
    (``_look_for_wiggle``) and, where it finds one, chooses again with its period as if given;
    where it finds a radial offset instead, it chooses again with that a candidate (``radial``).
    A depth scale is never chosen
    here: it would make the depth silent on the focal length (the two trade exactly), a ToF
    camera's scale is set by its modulation frequency, and a scale the data seem to call for
    is a wrong square size or depth unit, which the verdict reports."""
    model = Model()
    base = [0, 1, 2, 3]
    if options.distortion != "auto":
        base += DISTORTION_TERMS[options.distortion]
        model.distortion = options.distortion
    period = options.wiggle_period
    if options.depth_bias == "auto":
        depth_terms, candidates = ["offset"] + (["wiggle"] if period is not None else []), ["tilt"]
        candidates += ["radial"] if radial else []
    else:
        depth_terms, candidates = ([] if options.depth_bias == "none" else options.depth_bias.split("+")), []
    base += [N_INTRINSICS + k for k in bias_model.parse("+".join(depth_terms) or "none")]
    fit = bundle.solve(observations, state, convention, base, loss=options.loss, wiggle_period=period)
    price = np.log(bundle.n_observations(observations))

    fitted: dict[str, bundle.Fit] = {}

    def tested(name: str, terms: list[int]) -> float:
        """The term's gain less its price, recorded as evidence."""
        fitted[name] = bundle.solve(observations, fit.state, convention, sorted(free + terms), loss=options.loss,
                                    wiggle_period=period)
        gain = max(bundle.score(observations, fit, convention, terms),
                   bundle.deviance(observations, fit) - bundle.deviance(observations, fitted[name]))
        model.evidence[name] = {"gain": round(gain, 3), "price": round(len(terms) * price, 3)}
        return gain - len(terms) * price

    free = list(base)
    if options.distortion == "auto":
        while True:
            # every larger preset, by the terms it adds: k1 alone may not pay where k1 and k2 do
            larger = list(DISTORTION_TERMS)[list(DISTORTION_TERMS).index(model.distortion) + 1:]
            extra = {name: [t for t in DISTORTION_TERMS[name] if t not in free] for name in larger}
            net = {name: tested(name, terms) for name, terms in extra.items()}
            best = max(net, key=net.get, default=None)
            if best is None or net[best] <= 0:
                break
            free += extra[best]
            model.distortion = best
            fit = fitted[best]
    while candidates:
        net = {c: tested(c, [N_INTRINSICS + k for k in bias_model.TERMS[c]]) for c in candidates}
        best = max(net, key=net.get)
        if net[best] <= 0:
            break
        candidates.remove(best)
        depth_terms.append(best)
        free += [N_INTRINSICS + k for k in bias_model.TERMS[best]]
        fit = fitted[best]
    model.depth_bias = "+".join(depth_terms) or "none"
    if options.distortion == "auto" or options.depth_bias == "auto":
        model.reasons.append(f"chosen by the data: distortion {model.distortion}, depth terms {model.depth_bias} ("
                             + ", ".join(f"{k} {v['gain']:.1f} vs {v['price']:.1f}" for k, v in model.evidence.items())
                             + ": the cost each term would remove against its price)"
                             + (f"; the wiggle always, of period {period:.3f} m" if period is not None
                                and options.depth_bias == "auto" else ""))
        say(model.reasons[-1])
    return fit.state, sorted(free), model


def _wiggle_gains(prepared, plane_samples, obj, fit: bundle.Fit, convention: str,
                  radial: bool) -> tuple[np.ndarray, list[list[bundle.Observations]]]:
    """The score test's gain for a wiggle of each candidate period, at ``fit`` (which has none),
    and the views as each period has them: what their distances and their depth off their
    planes say of it (and of a radial offset, where ``radial``). The planes, and so the test,
    need no refit per period: without a wiggle they do not depend on it."""
    periods = [bias_model.wiggle_period(hz) for hz in WIGGLE_CANDIDATES_HZ]
    depths, floors, _, shapes, radials = _planarize_periods(prepared, plane_samples, fit.state.intrinsics,
                                                            fit.state.bias, convention, periods, radial)
    at_each = [_observations(obj, prepared, depths, floors, [s[k] if s else None for s in shapes], radials)
               for k in range(len(periods))]
    gains = [bundle.score(views, replace(fit, wiggle_period=period), convention, bundle.WIGGLE)
             for views, period in zip(at_each, periods)]
    return np.array(gains), at_each


@dataclass
class _WiggleSearch:
    """What the search for a wiggle of unknown period found: each candidate period's ``gains``
    against the wiggle's ``price``, the views as each period has them (``views_at``) and as the fit
    without a wiggle had them (``plain``), and where a wiggle was taken, the period of ``hz`` and
    the fit with it (``refit``), which has a radial offset instead where ``radial``. In z-depth,
    ``radial_gain`` is the radial offset's gain, taken or not."""
    evidence: dict[str, float]
    reason: str
    gains: np.ndarray
    price: float
    views_at: list[list[bundle.Observations]]
    plain: list[bundle.Observations]
    hz: float
    refit: _Fitted | None = None
    radial: bool = False
    radial_gain: float | None = None


def _look_for_wiggle(prepared, plane_samples, obj, fitted: _Fitted, start: bundle.State,
                     options: CalibrationOptions, say) -> _WiggleSearch:
    """Without the modulation frequency: a wiggle at the candidate period whose score-test gain
    is largest, taken where that gain exceeds the price of its sine, cosine and period, is not
    at either end of the periods looked for, and where its amplitude, refitted at that period,
    is one a ToF camera can have and stands beyond the views' jackknife. The gain alone is not
    enough: it counts every sample of the board, so it finds sub-millimetre structure on large
    recordings and, on the real Kinect v2 views (which unwrap three frequencies: no one
    sinusoid), wiggles of 2-4 mm (chi-square 5 to 10 against their jackknife, on 2 degrees of
    freedom), one of which took 5-6 views' fx 2.6 % off. The refit chooses the model again from
    ``start``, the state the choice without it started from.
    In z-depth a radial offset (an offset in the light's path) is the wiggle's limit at long
    periods: it bows every view alike, where a wiggle's bow changes with the distance. Where it
    pays its price (one term) and gains no less than a wiggle at any period, the model is chosen
    again with it a candidate instead: near frontal, a 50 mm radial offset was taken for a wiggle
    and fx trusted 4.4 % off at 18 sigmas. Not where a wiggle gains more, even by less than its
    two further terms' price: near frontal, few views of a 15 mm wiggle gained 2-6 more than a
    radial offset would, which taken put fx 2-8 % off. Nor is a wiggle refitted with the radial
    offset a candidate beside it: near frontal the offset then took the bow the views share, and
    left wiggles that alone stood at chi-square 83-150 against their jackknife within it (0.003
    to 3.1). Where the two gain alike the data cannot tell them apart, and fx's uncertainty
    weighs both (``_over_wiggles``)."""
    convention = options.depth_convention
    radial = _radial_may_enter(options)
    gains, views_at = _wiggle_gains(prepared, plane_samples, obj, fitted.fit, convention, radial)
    n = bundle.n_observations(fitted.observations)
    price = WIGGLE_PRICE_TERMS * np.log(n)
    k = int(np.argmax(gains))
    hz = float(WIGGLE_CANDIDATES_HZ[k])
    evidence = {"gain": round(float(gains[k]), 3), "price": round(float(price), 3)}
    found = _WiggleSearch(evidence, "", gains, float(price), views_at, fitted.observations, hz)
    if radial:
        # the score test, as the wiggle's: the two compare at the same fit
        radial_gain = found.radial_gain = bundle.score(fitted.observations, fitted.fit, convention, [bundle.RADIAL])
        evidence["radial_gain"] = round(radial_gain, 3)
        if radial_gain > np.log(n) and radial_gain >= gains[k]:
            refit = _fit(prepared, plane_samples, obj, fitted.observations, start, False, options, say, radial=True)
            if "radial" in refit.model.depth_bias.split("+"):
                found.refit, found.radial = refit, True
                found.reason = (f"a radial offset in the depth (an offset in the light's path, which bows every view "
                                f"alike), not a wiggle: its gain {radial_gain:.1f} against its price {np.log(n):.1f}, "
                                f"a wiggle's at most {gains[k]:.1f} against {price:.1f}")
                say(found.reason)
                return found
    if gains[k] <= price or k in (0, len(gains) - 1):
        found.reason = (f"no wiggle in the depth: its largest gain, {gains[k]:.1f} (at {hz / 1e6:.0f} MHz), is "
                        + (f"below its price, {price:.1f}" if gains[k] <= price else
                           "at the end of the periods looked for (an error, but not a wiggle of such a period)"))
        say(found.reason)
        return found
    wiggly = replace(options, modulation_hz=hz)
    refit = _fit(prepared, plane_samples, obj, views_at[k], start, False, wiggly, say)
    w = refit.fit.state.bias[bias_model.TERMS["wiggle"]]
    amplitude = f"{np.hypot(*w) * 1e3:.1f} mm"
    if np.hypot(*w) > MAX_WIGGLE_M:
        found.reason = (f"no wiggle in the depth: the one the score test found (gain {gains[k]:.1f} against its price "
                        f"{price:.1f}, at {hz / 1e6:.0f} MHz) would be {amplitude}, beyond any ToF camera's: over "
                        "the distances seen it is a depth scale (is the square size right, and the depth's units?)")
        say(found.reason)
        return found
    stated = bundle.jackknifed(refit.fit, bundle.fold_estimates(refit.observations, refit.fit, convention, CORNER_FOLDS,
                                                                refit.free, options.loss), refit.free)
    at = np.isin(stated.free_global, bundle.WIGGLE)
    cov = stated.covariance[np.ix_(at, at)]
    z2 = float(w @ np.linalg.solve(cov, w)) if np.all(np.isfinite(cov)) else 0.0
    evidence["amplitude_chi2"] = round(z2, 3)
    if z2 <= scipy_chi2.ppf(1 - WIGGLE_P, 2):
        found.reason = (f"no wiggle in the depth: the score test found one (gain {gains[k]:.1f} against its price "
                        f"{price:.1f}, at {hz / 1e6:.0f} MHz), but its amplitude, {amplitude}, lies within its "
                        f"views' jackknife (chi-square {z2:.1f} on 2 degrees of freedom)")
        say(found.reason)
        return found
    found.refit = refit
    found.reason = (f"a wiggle in the depth of period {wiggly.wiggle_period:.3f} m (as of {hz / 1e6:.0f} MHz) "
                    f"chosen by the data: the score test's gain {gains[k]:.1f} against the price of its sine, "
                    f"cosine and period, {price:.1f}; amplitude {amplitude} (chi-square {z2:.1f} against the views' "
                    "jackknife)")
    say(found.reason)
    return found


def _over_wiggles(observations: list[bundle.Observations], fit: bundle.Fit, free: list[int],
                  options: CalibrationOptions, search: _WiggleSearch) -> bundle.Fit:
    """The fit of the depth model chosen, its covariance widened by how far the fits of the others
    lie: no wiggle, a wiggle at each candidate period and, in z-depth, a radial offset, each
    weighted by its likelihood (the score test's gain less the wiggle's price, as the information
    criterion weighs them: a model average over whether the depth wiggles and at what period).
    Near frontal, views cannot tell a wiggle's slope over their distances from the focal length:
    with the wiggle not taken because its gain fell just short of its price, or at the end of the
    periods looked for, or within its views' jackknife, 6 % of such results were trusted with the
    truth 2 to 10 stated sigmas away; with it taken, views that cannot tell the period leave the
    periods near-equally likely and their fits a few standard deviations apart. The radial offset
    is the wiggle's limit at long periods and is chosen over one by its gain alone, so it is
    weighed at the wiggle's price: at its own, the wiggles it narrowly beat weighed 1/n of it, and
    near frontal the 15 mm wiggles it was taken for left fx 4.6 % off at 2-3 stated sigmas (the
    radial offset's fx is the plain model's, with the wiggle's slope in it). A wiggle no ToF
    camera has (beyond MAX_WIGGLE_M) is no candidate. Each is one solve from this fit, on the
    views as the search planarized them."""
    wiggle = bundle.WIGGLE
    base = [t for t in free if t not in (*wiggle, bundle.RADIAL)]
    # (log weight, views, terms, period): no wiggle, the radial offset, then each period
    models = [(0.0, search.plain, base, None)]
    if search.radial_gain is not None:
        models.append((search.radial_gain - search.price, search.plain, sorted({*base, bundle.RADIAL}), None))
    models += [(gain - search.price, views, sorted({*base, *wiggle}), bias_model.wiggle_period(hz))
               for gain, views, hz in zip(search.gains, search.views_at, WIGGLE_CANDIDATES_HZ)]
    log_weight = 0.5 * np.array([m[0] for m in models])
    weights = np.exp(log_weight - log_weight.max())
    weights /= weights.sum()
    # the model fitted, as its free terms say: the yield loop chooses it again and may drop the
    # radial offset the search took
    chosen = len(models) - len(search.gains) + int(np.argmax(search.gains)) if wiggle[0] in free \
        else 1 if bundle.RADIAL in free else 0
    here = fit.state.globals_[fit.free_global]
    state = fit.state.copy()
    state.bias[bias_model.TERMS["wiggle"] + bias_model.TERMS["radial"]] = 0.0
    inflation = observations[0].depth_inflation
    total, spread = weights[chosen], np.zeros_like(fit.covariance)
    for m, ((_, views, terms, period), weight) in enumerate(zip(models, weights)):
        if m == chosen or weight < MIN_MODEL_WEIGHT:
            continue
        views = [replace(o, depth_inflation=inflation) for o in views]
        there = bundle.solve(views, state, options.depth_convention, terms, loss=options.loss, wiggle_period=period)
        if np.hypot(*there.state.bias[bias_model.TERMS["wiggle"]]) > MAX_WIGGLE_M:
            continue
        # the wiggle's own terms mean another function at another period: only the rest compare
        delta = np.where(np.isin(fit.free_global, wiggle), 0.0,
                         there.state.globals_[fit.free_global] - here)
        total += weight
        spread += weight * np.outer(delta, delta)
    if total <= 0:   # the chosen model and every other counted are all but impossible: nothing to weigh
        return fit
    return replace(fit, covariance=fit.covariance + spread / total)


def _within_corners(alone: bundle.Fit, averaged: bundle.Fit, corner_fit: bundle.Fit) -> bundle.Fit:
    """The model average's spread (``averaged`` less ``alone``, the chosen model's fit) scaled
    down until fx's and fy's uncertainty is no larger than the corners alone put it about this
    estimate: their own variance and the squared distance between the two. Beyond that, the depth
    models' disagreement says less of the focal length than the corners do: 12 consecutive real
    Kinect v2 views were stated 15-20 px apart where the corners alone gave about a third of it."""
    spread = averaged.covariance - alone.covariance
    corners = _focal(corner_fit)   # fx, fy, their standard deviations
    scale = 1.0
    for k in (0, 1):
        at = int(np.flatnonzero(alone.free_global == k)[0])
        cap = corners[k + 2] ** 2 + (alone.state.intrinsics[k] - corners[k]) ** 2
        if spread[at, at] > 0 and alone.covariance[at, at] + spread[at, at] > cap:
            scale = min(scale, max(cap - alone.covariance[at, at], 0.0) / spread[at, at])
    return replace(averaged, covariance=alone.covariance + scale * spread)


def _joint(prepared, plane_samples, obj, observations, state, free, options: CalibrationOptions, say):
    """The joint fit, re-planarizing with its K and bias until no estimated parameter moves by a
    hundredth of its own uncertainty (the paper re-planarizes once; a few rounds make
    noiseless data exact). Returns the fit, the corner depths, the planes and the observations
    they make (at the depth's inflation the given ones have)."""
    inflation = observations[0].depth_inflation
    convention = options.depth_convention
    for round_ in range(MAX_OUTER_ROUNDS):
        before = state.globals_
        fit = bundle.solve(observations, state, convention, free, loss=options.loss,
                           wiggle_period=options.wiggle_period)
        state = fit.state
        say(f"joint fit: fx={state.intrinsics[0]:.3f} fy={state.intrinsics[1]:.3f} "
            f"offset={state.bias[0] * 1e3:.1f} mm, {fit.iterations} iterations")
        depths, floors, planes, wiggles, radials = _planarize_all(prepared, plane_samples, state.intrinsics,
                                                                  state.bias, convention, options.wiggle_period,
                                                                  _radial_may_enter(options))
        observations = _observations(obj, prepared, depths, floors, wiggles, radials, inflation)
        change = np.abs(state.globals_ - before)[fit.free_global]
        std = np.sqrt(np.maximum(np.diag(fit.covariance), 0))
        # the first round starts where the model's choice left it, on the same observations: only
        # from the second does a small move say the observations have stopped changing
        if round_ and np.all(change <= np.maximum(0.01 * std, 1e-12 * np.abs(before[fit.free_global]))):
            break
    return fit, depths, planes, observations


class _Fitted(NamedTuple):
    """A joint fit with the model it was fitted with, and the views as it planarized them."""
    fit: bundle.Fit
    free: list[int]
    model: Model
    depths: list[np.ndarray]
    planes: list[Plane | None]
    observations: list[bundle.Observations]


def _fit(prepared, plane_samples, obj, observations, state, scale: bool, options: CalibrationOptions, say,
         model: Model | None = None, free: list[int] | None = None, radial: bool = False) -> _Fitted:
    """The model the data call for (unless ``model`` and its ``free`` parameters are given; a radial
    offset among the candidates where ``radial``) and the joint fit with it, with a depth scale
    term where ``scale``. Returns the fit, its free parameters, the model, and what ``_joint``
    returns beside the fit."""
    if model is None or free is None:
        state, free, model = _select_model(observations, state, options.depth_convention, options, say, radial)
    if scale:
        free = sorted({*free, N_INTRINSICS + 1})
        model.depth_bias = "+".join(t for t in bias_model.TERMS if t == "scale" or t in model.depth_bias.split("+"))
    fit, depths, planes, observations = _joint(prepared, plane_samples, obj, observations, state, free, options, say)
    return _Fitted(fit, free, model, depths, planes, observations)


def _focal(fit: bundle.Fit) -> Focal:
    """fx, fy and their standard deviations."""
    std = _std(fit)
    return float(fit.state.intrinsics[0]), float(fit.state.intrinsics[1]), std["fx"], std["fy"]


def _pixel_noise(fit: bundle.Fit, model: Model) -> tuple[float, int]:
    return noise_per_dof(fit.pixel_residuals, 4 + len(DISTORTION_TERMS.get(model.distortion, [])))


def _one_distance(z: np.ndarray) -> bool:
    """Whether the views' distances spread too little to tell a scale from an offset."""
    return bool(np.ptp(z) <= MIN_DISTANCE_SPREAD * np.mean(z))


def _distance_structure(r: np.ndarray, s: np.ndarray, z: np.ndarray) -> tuple[float, float] | None:
    """How much of the views' depth-to-corner distance ratios ``r`` (standard errors ``s``) is a
    smooth function of the distance ``z`` beyond the offset's a + b / z: a quadratic over the
    range, kept when an F-test finds it (so views that merely scatter, from causes that do not
    follow the distance, do not count). Returns its RMS (relative) and the F statistic."""
    n = len(r)
    if n < 5 or _one_distance(z):
        return None
    t = (z - z.mean()) / max(np.ptp(z), 1e-9)
    base = np.column_stack([np.ones(n), 1 / z])
    full = np.column_stack([base, t, t ** 2])
    fits = [np.linalg.lstsq(A / s[:, None], r / s, rcond=None)[0] for A in (base, full)]
    chi2 = [float(np.sum(((r - A @ c) / s) ** 2)) for A, c in zip((base, full), fits)]
    dof = n - full.shape[1]
    if dof < 1:
        return None
    f_stat = (chi2[0] - chi2[1]) / 2 / max(chi2[1] / dof, 1.0)
    if f_stat <= scipy_f.ppf(1 - STRUCTURE_P, 2, dof):
        return None
    shape = full @ fits[1] - base @ fits[0]   # what the distance terms add to the offset's fit
    return float(np.sqrt(np.mean(shape ** 2))), float(f_stat)


def _bowl(smp: DepthSamples, su: np.ndarray, flat: np.ndarray, convention: str) -> tuple[float, float] | None:
    """A view's radial intercept: how far its white squares' depth curves off their plane the way
    an error in the radial distance does (in z-depth, a bowl deeper towards the image's edges),
    in metres, with its standard error. The errors the model takes (a z offset, a scale, a tilt)
    are planar and leave none; a constant radial offset leaves itself; a depth error that
    changes with the distance, ``w(r)``, leaves the intercept of its tangent, ``w - r dw/dr``,
    and its slope ``dw/dr`` is a depth scale, which near frontal views cannot tell from the
    focal length."""
    white = ~smp.black
    if np.sum(white) < MIN_SQUARE_PIXELS:
        return None
    su, flat, pixels = su[white], flat[white], smp.pixels[white]
    # a metre of the other convention's distance, in this one's terms
    q = 1 / np.linalg.norm(su, axis=1) if convention == "z" else 1 / su[:, 2]
    none_black = np.zeros(len(flat), dtype=bool)
    d = 1 / (su @ fit_plane_to(su, flat, pixels, none_black).coef)
    step = 1e-3
    moved = 1 / (su @ fit_plane_to(su, d + step * q, pixels, none_black).coef)
    shape = q - (moved - d) / step   # the part of a radial offset no plane takes
    ss = float(shape @ shape)
    if ss <= 1e-12 * len(q):
        return None
    e = flat - d
    b = float(e @ shape) / ss
    return b, float(np.sqrt(np.sum((e - b * shape) ** 2) / max(len(e) - 4, 1) / ss))


def _radial_intercept(bowls: list[tuple[float, float]]) -> tuple[float, float, float] | None:
    """The views' common radial intercept and its standard error, their scatter about it
    included (a real sensor's noise is correlated over the board, which a view's own error
    misses), and the chance that every view's intercept is 0 (a wiggle's differs between views
    at different distances, and may pool to nothing)."""
    if len(bowls) < 2:
        return None
    b, se = np.array(bowls).T
    w = 1 / se ** 2
    mean = float(np.sum(w * b) / np.sum(w))
    chi2 = float(np.sum(w * (b - mean) ** 2))
    return (mean, float(np.sqrt(max(1.0, chi2 / (len(b) - 1)) / np.sum(w))),
            float(scipy_chi2.sf(np.sum(w * b ** 2), len(b))))


def _bowl_check(samples: _PlaneSamples, fit: bundle.Fit, convention: str) -> tuple[str, bool] | None:
    """Why the depth may hold a scale the model leaves out, where the views' depth bows off their
    planes as an error in the radial distance does (``_bowl``), and whether the bows differ
    between the views; None where they do not bow. A bow common to the views is a radial offset
    (which holds no scale) or a wiggle's; bows that differ follow a depth error that changes
    with the distance, whose slope is a scale."""
    bias = fit.state.bias
    bowls = [_bowl(smp, su, bias_model.true_depth(bias, smp.depth, su), convention)
             for smp, su in zip(samples.samples, samples.directions(fit.state.intrinsics, convention))
             if smp is not None]
    bowls = [b for b in bowls if b is not None]
    intercept = _radial_intercept(bowls)
    if intercept is None:
        return None
    mean, se, p_none = intercept
    seen = "the board's depth bows off its plane as an error in the radial distance does "
    tail = ("whose slope is a depth scale the focal length cannot be told from but by tilted views; {}. Give the "
            "modulation frequency to model a wiggle")
    if abs(mean) > BOWL_SIGMAS * se:
        return (seen + f"({mean * 1e3:+.0f} ± {se * 1e3:.0f} mm): a radial offset, or a depth error that changes "
                "with the distance (ToF wiggling), " + tail.format("the focal length's uncertainty includes it"), False)
    if p_none < 2 * scipy_norm.sf(BOWL_SIGMAS):
        each = [b for b, _ in bowls]
        return (seen + f"(from {min(each) * 1e3:+.0f} to {max(each) * 1e3:+.0f} mm between the views, p = "
                f"{p_none:.1g} for none): a depth error that changes with the distance (ToF wiggling), "
                + tail.format("a depth scale term lets the corners fix it"), True)
    return None


@dataclass
class _DepthCheck:
    scale: bool = False                   # the corners call for a depth scale term
    level: float = 0.0   # how far off the corners' distances the depth reads (relative)
    reasons: list[str] = field(default_factory=list)


@dataclass
class _CornersAlone:
    """The corners-alone calibration the depth must not leave worse: its fit, and (computed once,
    where asked) its pixel noise a degree of freedom and OpenCV's fx and fy over folds of the views."""

    fit: bundle.Fit
    obj: list[np.ndarray]
    prepared: list[_Prepared]
    image_size: tuple[int, int]

    @cached_property
    def noise(self) -> tuple[float, int]:
        return noise_per_dof(self.fit.pixel_residuals, len(self.fit.free_global))

    @cached_property
    def fold_focals(self) -> np.ndarray | None:
        """fx and fy without each of CORNER_FOLDS groups of the views (a row each), the folds
        ``bundle.fold_estimates`` uses; None where a fold cannot be calibrated."""
        focals = []
        for keep in bundle.jackknife_folds(len(self.prepared), CORNER_FOLDS):
            try:
                focals.append(calibrate_opencv([self.obj[i] for i in keep], [self.prepared[i].corners for i in keep],
                                               self.image_size).intrinsics[:2])
            except CalibrationError:
                return None
        return np.array(focals)

    @cached_property
    def focal_std(self) -> np.ndarray | None:
        """fx's and fy's standard deviations from the corners alone, raised to their spread over
        ``fold_focals``; None where a fold cannot be calibrated."""
        folds = self.fold_focals
        return None if folds is None else np.maximum(_focal(self.fit)[2:], bundle.jackknife_spread(folds))


def _why_yield(observations: list[bundle.Observations], fit: bundle.Fit, free: list[int], model: Model,
               options: CalibrationOptions, corners: _CornersAlone | None) -> tuple[str | None, np.ndarray | None]:
    """Why the depth, at the weight ``observations`` give it, should yield to the corners (None
    where it need not), and the fit's fold estimates where they were needed to tell."""
    if corners is None:
        return None, None
    noise = _pixel_noise(fit, model)
    if corners_pulled(noise, corners.noise, tested=False):
        return (f"the corners fit worse with the depth at its full weight than alone ({noise[0]:.3f} against "
                f"{corners.noise[0]:.3f} px a degree of freedom"), None
    estimates = bundle.fold_estimates(observations, fit, options.depth_convention, CORNER_FOLDS, free, options.loss)
    worse = _less_certain(fit, estimates, free, corners)
    return (None if worse is None else
            f"the depth at its full weight left {worse[0]} less certain than the corners alone ({worse[1]:.2f} "
            f"against {worse[2]:.2f} px, over folds of the views"), estimates


def _less_certain(fit: bundle.Fit, estimates: np.ndarray | None, free: list[int],
                  corners: _CornersAlone) -> tuple[str, float, float] | None:
    """The focal length (fx or fy) the depth leaves less certain than the corners alone, with both
    standard deviations, each raised to its spread over folds of the views (``estimates``, the
    fit's; OpenCV on the same folds for the corners), or None."""
    s = _std(bundle.jackknifed(fit, estimates, free))
    ours = np.array([s["fx"], s["fy"]])
    if np.all(ours <= np.array(_focal(corners.fit)[2:])):   # the corners' spread over folds can only raise theirs
        return None
    alone = corners.focal_std
    if alone is None:
        return None
    k = int(np.argmax(ours / alone))
    return (("fx", "fy")[k], float(ours[k]), float(alone[k])) if ours[k] > alone[k] else None


def _depth_check(fit: bundle.Fit, depths: list[np.ndarray], planes: list[Plane | None], corners: _CornersAlone | None,
                 convention: str) -> _DepthCheck:
    """What the corners can tell of the depth: the distance of each view from the corners alone
    (the board's size in the image, with the corners' own calibration, which the depth did not
    shape) against its distance from the depth.

    Their ratio must be the same for every view, up to the offset the model removes. A level
    common to every ratio is a depth scale (the slope of a wiggling error over the distances
    seen, a square size or depth unit a little off) or a bias of the corners: within
    MAX_CORNER_DEPTH_DISAGREEMENT, and when the corners fix it better than the level itself
    (their covariance and their spread over folds of the views), the depth gets a scale term,
    which the corners fix, so that the focal length rests on the corners for its scale and on
    the depth for the rest; beyond it the verdict refuses. A ratio that follows the distance (a
    ToF wiggling error) is reported."""
    check = _DepthCheck()
    if corners is None:
        return check
    corner_fit = corners.fit
    K, D = split_intrinsics(corner_fit.state.intrinsics)
    bias = fit.state.bias
    ratio, sigma, dist = [], [], []
    for j, (v, d, o, plane) in enumerate(zip(corners.prepared, depths, corners.obj, planes)):
        if plane is None or not np.isfinite(d).all():
            continue
        try:
            ok, rvec, tvec = cv2.solvePnP(o, np.ascontiguousarray(v.corners), K, D, fit.state.poses[j, :3].copy(),
                                          fit.state.poses[j, 3:].copy(), useExtrinsicGuess=True,
                                          flags=cv2.SOLVEPNP_ITERATIVE)
        except cv2.error:   # a view OpenCV cannot pose from its corners alone says nothing here
            continue
        if not ok:
            continue
        X = transform_views(np.r_[rvec.ravel(), tvec.ravel()][None], o, np.zeros(len(o), dtype=int))[0]
        from_pixels = float(np.mean(depth_of(X, convention)[0]))
        u = directions(v.corners, fit.state.intrinsics, convention)
        from_depth = float(np.mean(bias_model.true_depth(bias, d, u, fit.wiggle_period)))
        spread_px = np.sqrt(np.mean(np.sum((v.corners - v.corners.mean(0)) ** 2, axis=1)))
        px = max(float(np.sqrt(np.mean(fit.pixel_residuals[j] ** 2))), bundle.MIN_NOISE[0])
        plane_se = max(float(np.median(corner_depth_along(plane, u)[1])), bundle.MIN_NOISE[1])
        ratio.append(from_depth / from_pixels - 1)
        sigma.append(np.hypot(px / (spread_px * np.sqrt(len(o) / 2)), plane_se / from_depth))
        dist.append(from_pixels)
    n = len(ratio)
    if n < 3:
        return check
    r, s, z = np.array(ratio), np.array(sigma), np.array(dist)
    # views all at one distance cannot tell a scale from an offset: then the level is both
    A = np.ones((n, 1)) if _one_distance(z) else np.column_stack([np.ones(n), 1 / z])
    coef, *_ = np.linalg.lstsq(A / s[:, None], r / s, rcond=None)
    res = r - A @ coef
    dof = n - A.shape[1]
    structure = _distance_structure(r, s, z)
    if structure is not None:   # reported, not corrected: on a real Kinect the corners were the worse
        tau, f_stat = structure
        s = np.hypot(s, tau)
        check.reasons.append(
            f"the ratio of the views' distances from the depth and from the corners varies with the distance "
            f"({tau:.2%} RMS, F = {f_stat:.0f}): a depth error over distance the model does not explain (ToF "
            "wiggling?)")
    # the level (a scale: the offset's b / z aside), with the corners' own focal-length uncertainty
    Aw = A / s[:, None]
    cov = np.linalg.pinv(Aw.T @ Aw) * max(float(np.sum((res / s) ** 2)) / max(dof, 1), 1.0)
    level = float(coef[0])
    corner_rel = corner_fit.covariance[0, 0] ** 0.5 / corner_fit.state.intrinsics[0]
    level_sigma = float(np.hypot(np.sqrt(cov[0, 0]), corner_rel))
    if EXCESS_SIGMAS * level_sigma < abs(level) < MAX_CORNER_DEPTH_DISAGREEMENT:
        # the corners' focal length can rest on a view or two (a real Kinect set moves it 2 %
        # with one view): their spread over folds of the views, not only their covariance
        folds = corners.fold_focals
        spread = np.inf if folds is None else float(bundle.jackknife_spread(folds[:, 0]) / folds[:, 0].mean())
        level_sigma = float(np.hypot(level_sigma, spread))
    check.level = level
    if EXCESS_SIGMAS * level_sigma < abs(level) < MAX_CORNER_DEPTH_DISAGREEMENT:
        check.scale = True
        check.reasons.append(
            f"the depth reads {level:+.2%} (±{level_sigma:.2%}) off the distances the corners give: a depth scale "
            "(the slope of a wiggling error, a square a little off) or a bias of the corners; a depth scale term "
            "lets the corners fix it")
    return check


def _calibrate(views, board, image_size, options: CalibrationOptions, progress) -> CalibrationResult:
    say = progress or (lambda _msg: None)
    convention = options.depth_convention
    prepared, rejected, image_size = _prepare(views, board, image_size, options.depth_units)
    say(f"{len(prepared)} of {len(views)} views have a board")
    _require(prepared, rejected, options.min_views, len(views))
    obj = [board.object_points(v.ids) for v in prepared]
    notes: list[str] = []
    trad: Traditional | None = None
    # the baseline fits the lens model asked for; the depth method starts from ROS's default
    lens = options.distortion if options.method == "traditional" and options.distortion != "auto" else "plumb_bob"
    try:
        trad = calibrate_opencv(obj, [v.corners for v in prepared], image_size, lens)
        say(f"traditional calibration: fx={trad.intrinsics[0]:.2f} fy={trad.intrinsics[1]:.2f}, "
            f"RMS {trad.rms:.3f} px")
    except CalibrationError as exc:
        if options.method == "traditional":
            raise
        notes.append(f"{exc}; initialised from the depth data instead")
        say(notes[-1])

    corner_fit = None if trad is None else _corner_fit(obj, prepared, trad, convention, lens)
    if options.method == "traditional":
        model = Model(distortion=lens, depth_bias="none", plane_squares="white")
        return _result(options, model, board, image_size, corner_fit, prepared, None, rejected, notes)

    # Choose each view's plane samples once (valid depth, RANSAC inliers); a view whose depth is
    # unusable still counts with its corners, and the notes say so.
    guess = focal_guess([v.corners for v in prepared], [sample_depth(v.depth, v.corners) for v in prepared],
                        obj, image_size)
    first = trad.intrinsics if trad is not None else guess
    sampled = "all" if options.plane_squares == "auto" else options.plane_squares
    samples: list[DepthSamples | None] = []
    white_inliers: list[np.ndarray | None] = []
    first_planes, black_offsets = [], []
    for v in prepared:
        try:
            smp = board_samples(v.depth, v.corners, v.ids, board, first, v.amplitude, squares=sampled)
            plane = fit_samples(smp.subset(~smp.black), first, convention, ransac=True)
            offset = _black_offset(smp, plane, first, convention)
            if offset is not None:
                black_offsets.append(offset)
            samples.append(smp)
            white_inliers.append(plane.inliers)
            first_planes.append(plane)
        except CalibrationError as exc:
            samples.append(None)
            white_inliers.append(None)
            notes.append(f"view {v.index}: {exc}; used for its corners only")
            say(notes[-1])
    if not first_planes:
        raise CalibrationError("no view has usable depth on the board (0 or NaN, or too few pixels); "
                               "method='traditional' calibrates from the corners alone")
    _check_not_parallel(first_planes, None if trad is None else trad.poses)
    squares = options.plane_squares
    squares_reason = ""
    if squares == "auto":
        apart, squares_reason = _black_reads_apart(black_offsets)
        squares = "white" if apart else "all"
        say(squares_reason)
    # The RANSAC inliers of the chosen squares are the view's samples from here on (the white
    # squares' were found above).
    for k, smp in enumerate(samples):
        if smp is not None:
            if squares == "all":
                samples[k] = smp.subset(fit_samples(smp, first, convention, ransac=True).inliers)
            else:
                samples[k] = smp.subset(~smp.black).subset(white_inliers[k])
    plane_samples = _PlaneSamples(samples, image_size[0])
    # Start the K update from whichever guess (OpenCV's or the depth's) sizes the squares better;
    # distortion starts at none (OpenCV's, from few corners, can be wild) unless it was asked for.
    estimate_offset = options.depth_bias == "auto" or 0 in bias_model.parse(options.depth_bias)
    obj_pts = [board.object_points(v.ids) for v in prepared]
    guesses = [guess] if trad is None else [trad.intrinsics, guess]
    kept = [0, 1, 2, 3] + DISTORTION_TERMS.get(options.distortion, [])
    guesses = [np.where(np.isin(np.arange(N_INTRINSICS), kept), g, 0.0) for g in guesses]
    try:
        start = min(guesses, key=lambda g: update_intrinsics(
            g, [v.corners for v in prepared], _planarize_all(prepared, plane_samples, g, np.zeros(bias_model.N_BIAS),
                                                            convention)[0], obj_pts, convention, estimate_offset)[2])
        intr, bias, err = _k_update(prepared, plane_samples, board, start.copy(), np.zeros(bias_model.N_BIAS),
                                    convention, estimate_offset)
    except CalibrationError as exc:   # the planes fail once K has run off
        raise CalibrationError(f"sizing the squares from the depth diverged ({exc}): the corners and the depth "
                               "disagree (corners out of order or of other frames, or another board?)") from exc
    say(f"K from square sizes: fx={intr[0]:.2f} fy={intr[1]:.2f} (square size RMS error {err * 100:.2f} %)")

    depths, floors, planes, wiggles, radials = _planarize_all(prepared, plane_samples, intr, bias, convention,
                                                              options.wiggle_period, _radial_may_enter(options))
    poses = []
    for o, v, d in zip(obj, prepared, depths):
        if np.isfinite(d).all():
            u = directions(v.corners, intr, convention)
            poses.append(pose_from_points(o, u * bias_model.true_depth(bias, d, u)[:, None]))
        else:
            poses.append(pose_from_pixels(o, v.corners, intr))
    state = bundle.State(intr, bias, np.array(poses))
    # The denoised depths depend on K and the bias through the rays: re-planarize and re-fit
    # until they agree (the paper re-planarizes once; a few rounds make noiseless data exact).
    observations = _observations(obj, prepared, depths, floors, wiggles, radials)
    start = bundle.solve(observations, state, convention, [], rounds=1).state
    fitted = _fit(prepared, plane_samples, obj, observations, start, False, options, say)
    asked, found_wiggle = options, None
    if options.depth_bias == "auto" and options.modulation_hz is None:
        found_wiggle = _look_for_wiggle(prepared, plane_samples, obj, fitted, start, options, say)
        if found_wiggle.refit is not None:
            options = options if found_wiggle.radial else replace(options, modulation_hz=found_wiggle.hz)
            fitted = found_wiggle.refit
    radial = found_wiggle is not None and found_wiggle.radial
    fit, free, model, depths, planes, observations = fitted
    corners = None if corner_fit is None else _CornersAlone(corner_fit, obj, prepared, image_size)
    check = _depth_check(fit, depths, planes, corners, convention) \
        if options.depth_bias == "auto" else _DepthCheck()
    # Views whose depth bows off their planes by amounts that differ have an error over distance
    # whose slope is a scale: left to the depth, a real Kinect v2's halves came out 2.4 % apart,
    # each stated to 0.3 %; with the scale the corners fix, 0.2 % apart. Not where the depth
    # reads beyond MAX_CORNER_DEPTH_DISAGREEMENT off the corners: a scale term would hide a wrong
    # square size or depth unit, which the verdict refuses
    bowl = _bowl_check(plane_samples, fit, convention) if options.depth_bias == "auto" \
        and options.wiggle_period is None and abs(check.level) < MAX_CORNER_DEPTH_DISAGREEMENT else None
    if bowl is not None:
        check.reasons.append(bowl[0])
        check.scale = check.scale or bowl[1]
    for why in check.reasons:
        say(why)
    if check.scale:
        fit, free, model, depths, planes, observations = _fit(prepared, plane_samples, obj, observations, fit.state,
                                                              True, options, say, model, free)
    depth_focal, full_depths = _focal(fit), depths   # what the depth says at its full weight
    # The verdict refuses a depth this far off the corners at its full weight (a wrong square size
    # or depth unit) whatever its yield makes of the rest: the yield would only delay the refusal
    # (7 model choices, 5 of the 7.8 minutes a wrong unit took on 60 views)
    refuted = corner_fit is not None and bool(focal_disagreements(depth_focal, _focal(corner_fit)))
    found = ([] if found_wiggle is None else [found_wiggle.reason]) + [squares_reason] * bool(squares_reason) \
        + check.reasons
    model = replace(model, plane_squares=squares, reasons=model.reasons + found)
    # Where the depth pulls the corners off their fit, its error is one the model does not explain
    # (a wiggle the views' tilts see): its weight falls until they fit about as well as alone; by
    # the effect's size alone: 4 corners a view leave the corners-alone fit 2 degrees of freedom,
    # which leave the F-test without power (a wiggle 17 times the corners' noise passed it, trusted
    # 1.7 % off at 4 sigmas), and the depth yielding where it need not costs little. Where it leaves
    # the focal length less certain over folds of the views than the corners alone, each view's
    # depth has an error of its own the model does not explain: it falls until it does not.
    inflation = 1.0
    reason, estimates = (None, None) if refuted else _why_yield(observations, fit, free, model, options, corners)
    full_weight = reason
    while inflation < MAX_DEPTH_INFLATION and reason:
        inflation *= DEPTH_INFLATION_STEP
        lighter = [replace(o, depth_inflation=inflation) for o in observations]
        fit, free, chosen, depths, planes, observations = _fit(prepared, plane_samples, obj, lighter, start,
                                                               check.scale, options, say, radial=radial)
        model = replace(chosen, plane_squares=squares, reasons=chosen.reasons + found)
        reason, estimates = _why_yield(observations, fit, free, model, options, corners)
    if inflation > 1:
        model.depth_inflation = inflation
        model.reasons.append(
            f"{full_weight}; the depth says fx={depth_focal[0]:.1f} px): a depth error the model does not explain; its "
            f"error is taken as {inflation:g} times its noise, where the corners fit about as well and are no less "
            f"certain (at most {MAX_DEPTH_INFLATION:g})")
        say(model.reasons[-1])
    noise_fit = fit
    if (bowl is not None or radial) and N_INTRINSICS + 1 not in free:
        # a bow common to the views, or the radial offset taken for it: a wiggle's bows alike too
        # near frontal, and its slope is a scale; the data may fix the scale about the truth, not
        # about this fit's (a 15 mm wiggle taken for a radial offset put fx 2.4 % off), and as far
        # from it as they put the scale
        fit = bundle.widened(observations, fit, convention, N_INTRINSICS + 1, CORNER_FOLDS, options.loss)
    if found_wiggle is not None:
        alone = fit
        fit = _over_wiggles(observations, fit, free, options, found_wiggle)
        if corner_fit is not None:
            fit = _within_corners(alone, fit, corner_fit)
        if _std(fit)["fx"] > 1.1 * _std(alone)["fx"]:
            model.reasons.append(
                f"fx's uncertainty is {_std(fit)['fx']:.2f} px, not the {_std(alone)['fx']:.2f} of the model chosen "
                "alone: it includes the fits of the depth models the data leave likely (without a wiggle, and with "
                "one at each period looked for), each as likely as the data make it, up to what the corners alone "
                "leave of it")
            say(model.reasons[-1])
    if estimates is None:   # the folds of the loop's last fit, whose estimate the steps since leave as it was
        estimates = bundle.fold_estimates(observations, fit, convention, CORNER_FOLDS, free, options.loss)
    stated = bundle.jackknifed(fit, estimates, free)
    model.wiggle_period = options.wiggle_period
    if found_wiggle is not None:
        model.evidence["wiggle"] = found_wiggle.evidence
    result = _result(asked, model, board, image_size, stated, prepared, planes, rejected, notes, corner_fit,
                     noise_fit, depth_focal)
    if corner_fit is not None:
        result.depth_square = board.square * square_from_depth(
            corner_fit.state.intrinsics, [v.corners for v in prepared], full_depths, obj, convention)
    return result
