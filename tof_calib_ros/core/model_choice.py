"""The depth and distortion model the data call for, chosen by an information criterion, and the
joint fit with it (the paper's step 5), re-planarizing until the depths and the fit agree."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from . import bundle
from . import depth_bias as bias_model
from .camera import N_INTRINSICS, fold_distance
from .options import DISTORTION_TERMS, CalibrationOptions, Model
from .planarize import Plane
from .view_planes import planarize_all, radial_may_enter, view_observations

MAX_OUTER_ROUNDS = 6
# Anderson's step beyond a round's output, at most this many times the round's own move: 1.8 lands on
# the fixed point of a map that keeps 0.64 of each move (the pico flexx class sensor's slowest)
MAX_MIXED_STEP = 2.0
HELD_OUT_FOLDS = 5
K3 = DISTORTION_TERMS["full"][-1]
# 'auto' grows the polynomial presets, and tries the rational lens only where k3 folds the lens in
# the image (_rational_where_k3_folds): on real Kinect v2 views the rational lens paid by the
# criterion (197-526 against a price of 25) for a pixel RMS 5 % lower, with coefficients of
# thousands that cancel, and moved the depth's offset from 25 to 76 mm
AUTO_PRESETS = list(DISTORTION_TERMS).index("full") + 1


def select_model(observations: list[bundle.Observations], state: bundle.State, convention: str,
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
    (``look_for_wiggle``) and, where it finds one, chooses again with its period as if given;
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
    fit = bundle.solve(observations, _within(state, base), convention, base, loss=options.loss, wiggle_period=period)
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
            # every larger preset, by the terms it adds: k1 alone may not pay where k1 and k2 do; not
            # the rational lens, tried only where k3 folds (choose_and_fit)
            larger = list(DISTORTION_TERMS)[list(DISTORTION_TERMS).index(model.distortion) + 1:AUTO_PRESETS]
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


def _within(state: bundle.State, terms: list[int]) -> bundle.State:
    """``state`` with the lens and depth terms outside ``terms`` at none. A choice started from a
    fit in a larger model (the lens and tilt chosen before a wiggle was found) held that model's
    other terms at its values: a wiggle's refit chose no lens and no tilt and kept k1 -0.43,
    k2 1.04, k3 -1.69 and a tilt of 68 mm a metre, unestimated (4 corners x 3 images, fx 3.6 % off)."""
    at = state.globals_
    at[np.setdiff1d(np.arange(4, len(at)), terms)] = 0.0
    return bundle.State(at[:N_INTRINSICS], at[N_INTRINSICS:], state.poses.copy())


def joint(prepared, plane_samples, obj, observations, state, free, options: CalibrationOptions, say):
    """The joint fit, re-planarizing with its K and bias until no estimated parameter moves by a
    hundredth of its own uncertainty (the paper re-planarizes once; a few rounds make
    noiseless data exact). Returns the fit, the corner depths, the planes and the observations
    they make (at the depth's inflation the given ones have).

    Each round is a map from the K and bias the views were planarized with to the fit's; its
    fixed point is the answer. Plain rounds settle slowly where the map contracts weakly (each
    round moved the pico flexx class sensor's fx 0.25-0.64 times the last, and 6 rounds left it
    short) and swing between two states where it overshoots (few corners a view), so from the
    third round the point planarized at is Anderson's mixing of the rounds so far."""
    inflation = observations[0].depth_inflation
    convention = options.depth_convention
    at, rounds = None, []
    for round_ in range(MAX_OUTER_ROUNDS):
        fit = bundle.solve(observations, state, convention, free, loss=options.loss,
                           wiggle_period=options.wiggle_period)
        state = fit.state
        say(f"joint fit, round {round_ + 1}: fx={state.intrinsics[0]:.3f} "
            f"fy={state.intrinsics[1]:.3f} offset={state.bias[0] * 1e3:.1f} mm, {fit.iterations} iterations")
        mapped = state.globals_
        std = np.sqrt(np.maximum(np.diag(fit.covariance), 0))
        # the first round starts where the model's choice left it, on the same observations: only
        # from the second does a small move say the observations have stopped changing
        settled = at is not None and np.all(np.abs(mapped - at)[fit.free_global]
                                            <= np.maximum(0.01 * std, 1e-12 * np.abs(at[fit.free_global])))
        if at is not None:
            rounds.append((at, mapped))
        if not np.all(np.isfinite(std) & (std > 0)):
            rounds = []  # a degenerate fit (a depth that shows no board): no uncertainty to scale a step by
        elif len(rounds) > 1 and _moved(rounds[-1], fit.free_global, std) > _moved(rounds[-2], fit.free_global, std):
            rounds = rounds[-1:]  # the map is not smooth here: mixing extrapolates nonsense
        last = settled or round_ == MAX_OUTER_ROUNDS - 1
        at = mapped if last else _mixed(rounds, fit.free_global, std, mapped)
        depths, floors, planes, wiggles, radials = planarize_all(prepared, plane_samples, at[:N_INTRINSICS],
                                                                 at[N_INTRINSICS:], convention, options.wiggle_period,
                                                                 radial_may_enter(options))
        observations = view_observations(obj, prepared, depths, floors, wiggles, radials, inflation)
        if settled:
            break
    return fit, depths, planes, observations


def _mixed(rounds: list[tuple[np.ndarray, np.ndarray]], free: np.ndarray, std: np.ndarray,
           mapped: np.ndarray, depth: int = 3) -> np.ndarray:
    """Anderson's mixing: the combination of the last rounds' outputs whose residual (output less
    input, in units of each free parameter's uncertainty ``std``) is least; the latest output
    where there are fewer than two rounds to mix."""
    if len(rounds) < 2:
        return mapped
    recent = rounds[-depth - 1:]
    g = np.array([_move(r, free, std) for r in recent])
    f = np.array([out[free] for _, out in recent])
    gamma = np.linalg.lstsq((g[1:] - g[:-1])[::-1].T, g[-1], rcond=None)[0]
    step = -gamma @ (f[1:] - f[:-1])[::-1] / std
    mixed = mapped.copy()
    mixed[free] += step * min(1.0, MAX_MIXED_STEP * np.linalg.norm(g[-1]) / max(np.linalg.norm(step), 1e-300)) * std
    return mixed


def _move(round_: tuple[np.ndarray, np.ndarray], free: np.ndarray, std: np.ndarray) -> np.ndarray:
    """A round's move of the free globals (output less input), in their uncertainties."""
    return (round_[1] - round_[0])[free] / std


def _moved(round_: tuple[np.ndarray, np.ndarray], free: np.ndarray, std: np.ndarray) -> float:
    """How far a round moved the free globals, in their uncertainties."""
    return float(np.linalg.norm(_move(round_, free, std)))


class Fitted(NamedTuple):
    """A joint fit with the model it was fitted with, and the views as it planarized them."""
    fit: bundle.Fit
    free: list[int]
    model: Model
    depths: list[np.ndarray]
    planes: list[Plane | None]
    observations: list[bundle.Observations]


def choose_and_fit(prepared, plane_samples, obj, observations, state, scale: bool, options: CalibrationOptions, say,
                   model: Model | None = None, free: list[int] | None = None, radial: bool = False) -> Fitted:
    """The model the data call for (unless ``model`` and its ``free`` parameters are given; a radial
    offset among the candidates where ``radial``) and the joint fit with it, with a depth scale
    term where ``scale``. Returns the fit, its free parameters, the model, and what ``joint``
    returns beside the fit."""
    start, given = state, observations
    if model is None or free is None:
        state, free, model = select_model(observations, state, options.depth_convention, options, say, radial)
    if scale:
        free = sorted({*free, N_INTRINSICS + 1})
        model.depth_bias = "+".join(t for t in bias_model.TERMS if t == "scale" or t in model.depth_bias.split("+"))
    fit, depths, planes, observations = joint(prepared, plane_samples, obj, observations, state, free, options, say)
    if options.distortion == "auto" and K3 in free:
        image_size = prepared[0].depth.shape[::-1]
        folds = fold_distance(fit.state.intrinsics, image_size)
        if folds is not None:
            without = _without_k3(prepared, plane_samples, obj, observations, fit, free, folds, image_size, options,
                                  model, say)
            if without is not None:
                return _rational_where_k3_folds(prepared, plane_samples, obj, given, start, scale, radial, fit,
                                                without, folds, image_size, options, say) or without
    return Fitted(fit, free, model, depths, planes, observations)


def _rational_where_k3_folds(prepared, plane_samples, obj, given, start: bundle.State, scale: bool, radial: bool,
                             with_k3: bundle.Fit, without: Fitted, folds: float, image_size: tuple[int, int],
                             options: CalibrationOptions, say) -> Fitted | None:
    """The rational lens, where the polynomial the data called for (k3) folds inside the image and
    the rational lens does not fold and pays for its terms over the lens without k3 both on the
    views (the criterion) and on views it was not fitted to (their deviance, each fifth of them
    predicted by the lens refitted without it): a lens that bends more than the polynomial can
    follow (the Azure Kinect's narrow mode: k3 folded 425 px out, the image reaching 460 px, and
    without k3 fx came out 1.6-3 stated sigmas off; the rational lens gained 120-490 on the views
    and 340-720 on views left out, against a price of 30). Held-out views decide too because the
    criterion alone took it for few real Kinect v2 views (gains of 25-45 against 23-25) that it
    predicted worse in 2 of 4 draws, and, with any held-out gain, for all of them (by 6 and 24
    against 33), moving fx 0.5 px. Taken, it is fitted as if asked for; None otherwise."""
    convention = options.depth_convention
    free = sorted({*without.free, *DISTORTION_TERMS["rational"]})
    extra = len(free) - len(without.free)
    observations = without.observations
    fit = bundle.solve(observations, with_k3.state.copy(), convention, free, loss=options.loss,
                       wiggle_period=options.wiggle_period)
    gain = bundle.deviance(observations, without.fit) - bundle.deviance(observations, fit)
    price = extra * np.log(bundle.n_observations(observations))
    rational_folds = fold_distance(fit.state.intrinsics, image_size)
    if gain <= price or rational_folds is not None:
        say("the rational lens not taken where k3 folds: " + (f"it folds too ({rational_folds:.0f} px)"
            if rational_folds is not None else f"its gain {gain:.1f} is below its price {price:.1f}"))
        return None
    held = _held_out_deviance(observations, fit, free, options)
    held_without = _held_out_deviance(observations, without.fit, without.free, options)
    if held is None or held_without is None:
        say("the rational lens not taken where k3 folds: too few views to leave some out")
        return None
    if held_without - held <= price:
        say(f"the rational lens not taken where k3 folds: it predicts views left out by {held_without - held:.1f} "
            f"of their deviance better than the lens without k3, not more than its price, {price:.1f}")
        return None
    # taken, as if asked for, from the start the choice had: from the folded k3 the fit above can
    # stop short (a wide lens's pixels 0.38 px off, where asked for 0.04 px)
    asked = choose_and_fit(prepared, plane_samples, obj, given, start, scale, replace(options, distortion="rational"),
                           lambda message: say(f"the rational lens: {message}"), radial=radial)
    if fold_distance(asked.fit.state.intrinsics, image_size) is not None:
        say("the rational lens not taken where k3 folds: fitted as if asked for, it folds too")
        return None
    model = asked.model
    model.evidence["rational"] = {"gain": round(gain, 3), "price": round(price, 3),
                                  "held_out_gain": round(held_without - held, 3)}
    model.reasons.append(f"rational lens: with k3 the polynomial folds back {folds:.0f} px from the principal point, "
                         f"inside the image; the rational lens does not, removes {gain:.1f} of the cost against the "
                         f"price of its {extra} further terms, {price:.1f}, and predicts views left out better than "
                         f"the lens without k3 by {held_without - held:.1f} of their deviance, more than that price")
    say(model.reasons[-1])
    return asked


def _held_out_deviance(observations: list[bundle.Observations], fit: bundle.Fit, free: list[int],
                       options: CalibrationOptions) -> float | None:
    """The views' deviance, each fold of them predicted by the model refitted without it
    (``bundle.fold_estimates``; only their poses fitted to them); None where they are too few to
    fold (fewer than 3)."""
    convention, n = options.depth_convention, len(observations)
    refits = bundle.fold_estimates(observations, fit, convention, HELD_OUT_FOLDS, free, options.loss)
    if refits is None:
        return None
    total = 0.0
    for keep, globals_ in zip(bundle.jackknife_folds(n, HELD_OUT_FOLDS), refits):
        out = np.setdiff1d(np.arange(n), keep)
        left = [observations[i] for i in out]
        state = bundle.State(globals_[:N_INTRINSICS], globals_[N_INTRINSICS:], fit.state.poses[out].copy())
        total += bundle.deviance(left, bundle.solve(left, state, convention, [], loss=options.loss,
                                                    wiggle_period=fit.wiggle_period))
    return total


def _without_k3(prepared, plane_samples, obj, observations, fit: bundle.Fit, free: list[int], folds: float,
                image_size: tuple[int, int], options: CalibrationOptions, model: Model, say) -> Fitted | None:
    """The joint fit without k3, where k3 folds the lens back inside the image nearer the centre
    than the lens without it does (None where it does not). k3 acts at the image's edge: fitted
    to views that leave it out, it can turn the lens back just beyond them (7 real Kinect v2 views
    took a k3 of -2, which fit them to 0.08 px and put the views left out 25 px off; without it,
    0.09 px), which is why ROS camera_calibration leaves it out; taken by the data's choice, it
    stays only where the lens it makes holds at least as far out."""
    state = fit.state.copy()
    state.intrinsics[K3] = 0.0
    fewer = [t for t in free if t != K3]
    say(f"with k3 the lens folds back {folds:.0f} px from the principal point: fitting without k3 to compare")
    alt, depths, planes, observations = joint(prepared, plane_samples, obj, observations, state, fewer, options, say)
    alt_folds = fold_distance(alt.state.intrinsics, image_size)
    if alt_folds is not None and alt_folds <= folds:
        say(f"k3 kept: without it the lens folds back nearer still ({alt_folds:.0f} px)")
        return None
    model.distortion = "plumb_bob"
    model.evidence.setdefault("full", {})["folds_at_px"] = round(folds, 1)
    without = ("where without it it does not fold" if alt_folds is None
               else f"nearer than without it ({alt_folds:.0f} px)")
    model.reasons.append(f"k3 left out, the distortion plumb_bob: with it the lens folds back {folds:.0f} px from "
                         f"the principal point, inside the image, {without}: a k3 beyond what the views' corners reach")
    say(model.reasons[-1])
    return Fitted(alt, fewer, model, depths, planes, observations)
