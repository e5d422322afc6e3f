"""A wiggle of unknown period (or a radial offset) looked for where the modulation frequency is
not given, and the focal length's uncertainty over the depth models the data leave likely."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.stats import chi2 as scipy_chi2

from . import bundle
from . import depth_bias as bias_model
from .depth_trust import CORNER_FOLDS
from .model_choice import Fitted, choose_and_fit
from .options import CalibrationOptions
from .view_planes import planarize_periods, radial_may_enter, view_observations

# Without the modulation frequency, the periods looked for: those of 8 to 130 MHz (4.7 to 0.29 m),
# a factor 1.26 apart, over which the wiggle across a board's distances changes little.
WIGGLE_CANDIDATES_HZ = np.geomspace(8e6, 130e6, 13)
WIGGLE_PRICE_TERMS = 3  # its sine, cosine and period, at the information criterion's ln(n) each
# A wiggle larger than this is a depth scale in disguise (a square half its size gave one of 0.5 m
# at 10 MHz); ToF cameras wiggle by millimetres to a few centimetres.
MAX_WIGGLE_M = 0.1
WIGGLE_P = 0.001  # and its amplitude beyond its views' jackknife at this false-alarm rate
MIN_MODEL_WEIGHT = 1e-3  # depth models this much less likely than the rest together are not refitted


def _wiggle_gains(prepared, plane_samples, obj, fit: bundle.Fit, convention: str,
                  radial: bool) -> tuple[np.ndarray, list[list[bundle.Observations]]]:
    """The score test's gain for a wiggle of each candidate period, at ``fit`` (which has none),
    and the views as each period has them: what their distances and their depth off their
    planes say of it (and of a radial offset, where ``radial``). The planes, and so the test,
    need no refit per period: without a wiggle they do not depend on it."""
    periods = [bias_model.wiggle_period(hz) for hz in WIGGLE_CANDIDATES_HZ]
    depths, floors, _, shapes, radials = planarize_periods(prepared, plane_samples, fit.state.intrinsics,
                                                           fit.state.bias, convention, periods, radial)
    at_each = [view_observations(obj, prepared, depths, floors, [s[k] if s else None for s in shapes], radials)
               for k in range(len(periods))]
    gains = [bundle.score(views, replace(fit, wiggle_period=period), convention, bundle.WIGGLE)
             for views, period in zip(at_each, periods)]
    return np.array(gains), at_each


@dataclass
class WiggleSearch:
    """What the search for a wiggle of unknown period found: each candidate period's ``gains``
    against the wiggle's ``price``, the views as each period has them (``views_at``) and as the fit
    without a wiggle had them (``plain``), and where a wiggle was taken, the period of ``hz`` and
    the fit with it (``refit``), which has a radial offset instead where ``radial``. In z-depth,
    ``radial_gain`` is the radial offset's gain, taken or not. ``at_end``: the end of the periods
    looked for (0 the longest, the last the shortest) where the largest gain lies beyond the
    price: an error no wiggle looked for explains."""
    evidence: dict[str, float]
    reason: str
    gains: np.ndarray
    price: float
    views_at: list[list[bundle.Observations]]
    plain: list[bundle.Observations]
    hz: float
    refit: Fitted | None = None
    radial: bool = False
    radial_gain: float | None = None
    at_end: int | None = None


def look_for_wiggle(prepared, plane_samples, obj, fitted: Fitted, start: bundle.State,
                    options: CalibrationOptions, say) -> WiggleSearch:
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
    weighs both (``over_wiggles``)."""
    convention = options.depth_convention
    radial = radial_may_enter(options)
    gains, views_at = _wiggle_gains(prepared, plane_samples, obj, fitted.fit, convention, radial)
    n = bundle.n_observations(fitted.observations)
    price = WIGGLE_PRICE_TERMS * np.log(n)
    k = int(np.argmax(gains))
    hz = float(WIGGLE_CANDIDATES_HZ[k])
    evidence = {"gain": round(float(gains[k]), 3), "price": round(float(price), 3)}
    found = WiggleSearch(evidence, "", gains, float(price), views_at, fitted.observations, hz)
    if radial:
        # the score test, as the wiggle's: the two compare at the same fit
        radial_gain = found.radial_gain = bundle.score(fitted.observations, fitted.fit, convention, [bundle.RADIAL])
        evidence["radial_gain"] = round(radial_gain, 3)
        if radial_gain > np.log(n) and radial_gain >= gains[k]:
            refit = choose_and_fit(prepared, plane_samples, obj, fitted.observations, start, False, options, say,
                                   radial=True)
            if "radial" in refit.model.depth_bias.split("+"):
                found.refit, found.radial = refit, True
                found.reason = (f"a radial offset in the depth (an offset in the light's path, which bows every view "
                                f"alike), not a wiggle: its gain {radial_gain:.1f} against its price {np.log(n):.1f}, "
                                f"a wiggle's at most {gains[k]:.1f} against {price:.1f}")
                say(found.reason)
                return found
    if gains[k] <= price or k in (0, len(gains) - 1):
        if gains[k] > price:
            found.at_end = k
        found.reason = (f"no wiggle in the depth: its largest gain, {gains[k]:.1f} (at {hz / 1e6:.0f} MHz), is "
                        + (f"below its price, {price:.1f}" if gains[k] <= price else
                           "at the end of the periods looked for (an error, but not a wiggle of such a period)"))
        say(found.reason)
        return found
    wiggly = replace(options, modulation_hz=hz)
    refit = choose_and_fit(prepared, plane_samples, obj, views_at[k], start, False, wiggly, say)
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


def over_wiggles(observations: list[bundle.Observations], fit: bundle.Fit, free: list[int],
                 options: CalibrationOptions, search: WiggleSearch, searched: bundle.Fit) -> bundle.Fit:
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
    camera has (beyond MAX_WIGGLE_M) is no candidate. Each is one solve on the views as the
    search planarized them, from ``searched``, the model chosen fitted on those views: each lies
    as far from ``fit`` as from it (``fit`` has the board's border in its samples, where the
    search has the squares alone)."""
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
    here = searched.state.globals_[fit.free_global]
    state = searched.state.copy()
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


def within_corners(alone: bundle.Fit, averaged: bundle.Fit, corner_fit: bundle.Fit) -> bundle.Fit:
    """The model average's spread (``averaged`` less ``alone``, the chosen model's fit) scaled
    down until fx's and fy's uncertainty is no larger than the corners alone put it about this
    estimate: their own variance and the squared distance between the two. Beyond that, the depth
    models' disagreement says less of the focal length than the corners do: 12 consecutive real
    Kinect v2 views were stated 15-20 px apart where the corners alone gave about a third of it."""
    known = np.isfinite(alone.covariance)   # an unconstrained term's variance is infinite in both
    spread = np.zeros_like(alone.covariance)
    spread[known] = averaged.covariance[known] - alone.covariance[known]
    corners = corner_fit.focal()   # fx, fy, their standard deviations
    scale = 1.0
    for k in (0, 1):
        at = int(np.flatnonzero(alone.free_global == k)[0])
        cap = corners[k + 2] ** 2 + (alone.state.intrinsics[k] - corners[k]) ** 2
        if spread[at, at] > 0 and alone.covariance[at, at] + spread[at, at] > cap:
            scale = min(scale, max(cap - alone.covariance[at, at], 0.0) / spread[at, at])
    return replace(averaged, covariance=alone.covariance + scale * spread)
