"""Every view's depth planarized at its corners (the paper's step 2, for all views at once): the
plane samples each view keeps, which squares they come from, and the observations the joint fit
takes, with what each view's depth off its plane says of a wiggle and of a radial offset."""
from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from . import bundle
from . import depth_bias as bias_model
from .inputs import Prepared
from .options import CalibrationOptions
from .planarize import (
    DepthSamples,
    Plane,
    corner_depth_along,
    directions,
    fit_plane_to,
    off_plane,
    planar_part,
    smoothed,
)

PLANE_DOF = 3.0  # a view's denoised corner depths are one plane: three independent numbers
BLACK_APART_SIGMAS = 5.0  # a black-square offset this many standard errors from 0 keeps them out of the planes
MIN_SQUARE_PIXELS = 30  # fewer pixels of one colour say nothing of its offset or its bow


class PlaneSamples:
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


class Planarized(NamedTuple):
    """Each view's corner depths as the camera would report them, depth error floor, plane, and
    what its depth off the plane says of a wiggle (where there is one) and of a radial offset."""
    depths: list[np.ndarray]
    floors: list[float]
    planes: list[Plane | None]
    wiggles: list[bundle.WiggleShape | None]
    radials: list[bundle.RadialShape | None]


def planarize_all(views: list[Prepared], samples: PlaneSamples, intr: np.ndarray, bias: np.ndarray,
                  convention: str, period: float | None = None, radial: bool = False) -> Planarized:
    """The views planarized (the plane is fitted to depth corrected by the bias's planar terms and
    its radial offset, where the board really is flat), and where there is a wiggle (``period``)
    what each view's depth says of it, and of a radial offset where one may be in the model
    (``radial``, ``radial_may_enter``).
    The wiggle is not corrected before the plane is fitted: the plane would then depend on the
    wiggle's estimate, which near frontal settles on a wrong offset and wiggle that agree with the
    planes they shaped (1.7 % in fx on noiseless views). Instead the plane keeps the wiggle's planar
    part, and the fit predicts that part, and the depth off the plane (``bundle.WiggleShape``).
    A view without usable depth gets NaN depths: it counts with its corners only."""
    depths, floors, planes, shapes, radials = planarize_periods(views, samples, intr, bias, convention,
                                                                [] if period is None else [period], radial)
    return Planarized(depths, floors, planes, [s[0] if s else None for s in shapes], radials)


def planarize_periods(views: list[Prepared], samples: PlaneSamples, intr: np.ndarray, bias: np.ndarray,
                      convention: str, periods: Sequence[float], radial: bool
                      ) -> tuple[list[np.ndarray], list[float], list[Plane | None], list[list[bundle.WiggleShape]],
                                 list[bundle.RadialShape | None]]:
    """``planarize_all`` with what each view's depth says of a wiggle of each of ``periods``:
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


def radial_may_enter(options: CalibrationOptions) -> bool:
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
    bases = []
    for period in periods:
        corrected = bias_model.true_depth(bias, on_plane, su, period)
        bases.append(bias_model.wiggle_basis(period, corrected, corrected * along_su))
    if not wiggle.any():   # a search over periods: each period's terms off the one plane, sharing its noise weights
        information, moment = off_plane(plane, su, flat, smp.black, np.hstack(bases))
        return [bundle.WiggleShape(_corner_curve(plane, su, flat, smp.black, b, u, p, along_u),
                                   information[2 * k:2 * k + 2, 2 * k:2 * k + 2], moment[2 * k:2 * k + 2])
                for k, (p, b) in enumerate(zip(periods, bases))]
    shapes = []
    for period, basis in zip(periods, bases):
        clean = flat - basis @ wiggle
        at_plane = fit_plane_to(su, clean, smp.pixels, smp.black)
        # the depth off the plane fitted with the estimate taken out says how far the estimate is off:
        # the part of the whole wiggle a plane takes is not linear in it (a plane's depth is
        # 1 / (ray . coef)), and off the plane fitted with it in, 15 mm of wiggle read 0.4 mm off.
        # The noise is still the scatter about that plane, the wiggle's curve in it
        information, moment = off_plane(at_plane, su, clean, smp.black, basis, (plane, flat))
        shapes.append(bundle.WiggleShape(_corner_curve(at_plane, su, clean, smp.black, basis, u, period, along_u),
                                         information, moment + information @ wiggle))
    return shapes


def _corner_curve(plane: Plane, su: np.ndarray, depth: np.ndarray, black: np.ndarray, basis: np.ndarray,
                  u: np.ndarray, period: float, along_u: np.ndarray) -> np.ndarray:
    """Each wiggle term at the corners (along ``u``, on ``plane``) less the part of it the plane keeps."""
    at, _ = corner_depth_along(plane, u)
    return bias_model.wiggle_basis(period, at, at * along_u) - planar_part(plane, su, depth, black, basis, u)


def view_observations(obj, views: list[Prepared], depths, floors, wiggles, radials,
                      inflation: float = 1.0) -> list[bundle.Observations]:
    return [bundle.Observations(o, v.corners, d, f, PLANE_DOF, w, inflation, r)
            for o, v, d, f, w, r in zip(obj, views, depths, floors, wiggles, radials)]


def black_reads_apart(offsets: list[tuple[float, float]]) -> tuple[bool, str]:
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


def black_offset(smp: DepthSamples, plane: Plane, intr: np.ndarray, convention: str) -> tuple[float, float] | None:
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
