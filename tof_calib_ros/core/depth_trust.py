"""Whether the depth has earned its weight: what the corners alone say of it. The calibration is
never to be worse than the corners alone; these checks say when the depth reads off the corners'
distances (a depth scale), bows as an unmodelled error over distance does, or leaves the focal
length less certain than the corners would, so that its weight falls."""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import cv2
import numpy as np
from scipy.stats import chi2 as scipy_chi2
from scipy.stats import f as scipy_f
from scipy.stats import norm as scipy_norm

from . import bundle
from . import depth_bias as bias_model
from .camera import depth_of, split_intrinsics, transform_views
from .errors import CalibrationError
from .inputs import Prepared
from .options import CalibrationOptions, Model
from .planarize import DepthSamples, Plane, corner_depth_along, directions, fit_plane_to
from .result import MAX_CORNER_DEPTH_DISAGREEMENT, corners_pulled, lens_noise, noise_per_dof
from .traditional import calibrate_opencv
from .view_planes import MIN_SQUARE_PIXELS, PlaneSamples

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


def bowl_check(samples: PlaneSamples, fit: bundle.Fit, convention: str) -> tuple[str, bool] | None:
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
class DepthCheck:
    scale: bool = False                   # the corners call for a depth scale term
    level: float = 0.0   # how far off the corners' distances the depth reads (relative)
    over_distance: bool = False   # that ratio varies with the distance beyond its noise
    reasons: list[str] = field(default_factory=list)


@dataclass
class CornersAlone:
    """The corners-alone calibration the depth must not leave worse: its fit, and (computed once,
    where asked) its pixel noise a degree of freedom and OpenCV's fx and fy over folds of the views."""

    fit: bundle.Fit
    obj: list[np.ndarray]
    prepared: list[Prepared]
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
        return None if folds is None else np.maximum(self.fit.focal()[2:], bundle.jackknife_spread(folds))


def why_yield(observations: list[bundle.Observations], fit: bundle.Fit, free: list[int], model: Model,
              options: CalibrationOptions, corners: CornersAlone | None) -> tuple[str | None, np.ndarray | None]:
    """Why the depth, at the weight ``observations`` give it, should yield to the corners (None
    where it need not), and the fit's fold estimates where they were needed to tell."""
    if corners is None:
        return None, None
    noise = lens_noise(fit.pixel_residuals, model.distortion)
    if corners_pulled(noise, corners.noise, tested=False):
        return (f"the corners fit worse with the depth at its full weight than alone ({noise[0]:.3f} against "
                f"{corners.noise[0]:.3f} px a degree of freedom"), None
    estimates = bundle.fold_estimates(observations, fit, options.depth_convention, CORNER_FOLDS, free, options.loss)
    worse = less_certain(fit, estimates, free, corners)
    return (None if worse is None else
            f"the depth at its full weight left {worse[0]} less certain than the corners alone ({worse[1]:.2f} "
            f"against {worse[2]:.2f} px, over folds of the views"), estimates


def less_certain(fit: bundle.Fit, estimates: np.ndarray | None, free: list[int],
                 corners: CornersAlone) -> tuple[str, float, float] | None:
    """The focal length (fx or fy) the depth leaves less certain than the corners alone, with both
    standard deviations, each raised to its spread over folds of the views (``estimates``, the
    fit's; OpenCV on the same folds for the corners), or None."""
    s = bundle.jackknifed(fit, estimates, free).std()
    ours = np.array([s["fx"], s["fy"]])
    if np.all(ours <= np.array(corners.fit.focal()[2:])):   # the corners' spread over folds can only raise theirs
        return None
    alone = corners.focal_std
    if alone is None:
        return None
    k = int(np.argmax(ours / alone))
    return (("fx", "fy")[k], float(ours[k]), float(alone[k])) if ours[k] > alone[k] else None


def depth_check(fit: bundle.Fit, depths: list[np.ndarray], planes: list[Plane | None], corners: CornersAlone | None,
                convention: str) -> DepthCheck:
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
    check = DepthCheck()
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
        check.over_distance = True
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
