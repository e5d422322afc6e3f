"""The calibration report: one self-contained HTML page that shows whether to trust a calibration.

An RMS alone hides what matters: a focal length that moves with the views chosen, a view that
pulls the fit, a depth error that grows with distance, a corner of the image no view reached.
So the page shows the parameters with their standard deviations, the residuals over the image
and over distance, each view's share, the coverage, the board poses, the planarization of one
view, the traditional calibration of the same views, and a cross-validation: the first and the
second half of the views, in the order given, calibrated separately, their difference set against
the standard deviation the fits predict for it (mrcal's honesty check), and where over the image
the two project apart (mrcal's projection_diff). Halves in the recording's
order, not alternate views: a person sweeps the board across the image, so the halves of a
recording can cover different parts of it, which alternate views, each half holding views from
all of it, never show (the real Kinect v2 recording's halves: ours' cx 3.8 stated sigmas apart,
OpenCV's 7.8; alternate views' 0.3 and 3.2).

Figures are matplotlib PNGs embedded as data URIs, drawn on ``Figure`` objects with the Agg
canvas directly: pyplot and the user's backend are never touched.
"""
from __future__ import annotations

import base64
import datetime
import html
import io
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from ..core import depth_bias as bias_model
from ..core.board import Board
from ..core.camera import depth_of, pack_intrinsics, project, transform
from ..core.coverage import CELLS, cell_counts, cell_of, grid_in_cells, in_cells, reach
from ..core.errors import CalibrationError
from ..core.inputs import View, depth_in_metres
from ..core.pipeline import calibrate
from ..core.planarize import board_samples, corner_depth_along, directions, fit_plane_to, fit_samples, sample_depth
from ..core.projection_diff import projection_difference
from ..core.result import INTRINSIC_NAMES, CalibrationResult
from ..files.calibration_file import atomic_write

MIN_CV_VIEWS = 6            # three a half: the fewest a calibration accepts
CONSISTENT_SIGMAS = 3.0     # a half-sample difference within this many predicted sigmas is consistent
WORST_SHOWN = 3
DPI = 80

PARAMS = INTRINSIC_NAMES + bias_model.NAMES
UNITS = {"fx": "px", "fy": "px", "cx": "px", "cy": "px", "depth_offset": "mm"}
SHOWN_SCALE = {"depth_offset": 1e3}   # the offset is shown in mm

CSS = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2em}
table{border-collapse:collapse;margin:.8em 0;font-size:.92em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:right}th{background:#f2f2f2}
td:first-child,th:first-child{text-align:left}
.ok{background:#e6f4e6;border:1px solid #5a5;padding:.6em 1em}
.bad{background:#fbe9e9;border:1px solid #c55;padding:.6em 1em}
.warn{background:#fff4dc;border:1px solid #d9a400;padding:.6em 1em}
.note{background:#f6f6f6;border-left:4px solid #999;padding:.4em .8em}
td.fail{color:#b00;font-weight:bold}td.pass{color:#070}
figure{margin:1em 0}figure img{max-width:100%}figcaption{font-size:.9em;color:#444}
nav a{margin-right:1em}
"""


class ReportError(CalibrationError):
    """The views and the result given to ``write_report`` do not belong together."""


@dataclass
class _ViewData:
    """One used view, per corner, recomputed from the result and the view's images."""

    index: int                 # in the caller's list of views
    ids: np.ndarray            # board indices of the corners
    measured: np.ndarray       # (N, 2) the detected corners, px
    residual: np.ndarray       # (N, 2) predicted - measured, px
    distance: np.ndarray       # (N,) the corners' true depth in the convention, m
    model_depth: np.ndarray    # (N,) the depth the calibrated model says the camera reports, m
    denoised: np.ndarray       # (N,) the planarized corner depth the fit used, m (NaN: none)
    raw: np.ndarray            # (N,) the raw depth at the corner (3x3 median), m (NaN: none)
    tilt_deg: float            # between the board normal and the optical axis
    depth: np.ndarray          # the view's depth image, m, NaN invalid
    amplitude: np.ndarray | None


@dataclass
class _Comparison:
    """The calibrations the report runs itself, each a result or the reason it failed."""

    other: CalibrationResult | str               # the other method on the same views
    halves: tuple[CalibrationResult | str, CalibrationResult | str] | None
    half_views: tuple[list[int], list[int]]      # the caller's view indices of each half
    skipped: str = ""                            # why there is no cross-validation
    # OpenCV fitting the lens terms the depth-aided result chose, where those are not the baseline's
    same_lens: CalibrationResult | str | None = None


def write_report(path, views: Sequence[View], board: Board, result: CalibrationResult, *,
                 title: str | None = None, progress: Callable[[str], None] | None = None) -> Path:
    """Write ``report.html`` for ``result``, the calibration of ``views`` (the very list given to
    ``calibrate``), atomically; returns the path.

    The report calibrates again (the other method on the same views; the first and the second
    half of the views separately) with the options the result records and the model it chose.
    Raises ReportError when the views do not match the result, and CalibrationFileError when the
    file cannot be written.
    """
    say = progress or (lambda _msg: None)
    data = _view_data(views, board, result, result.options.depth_units)
    fixed = result.options.fixed(result.model).to_dict()
    options = {k: fixed[k] for k in ("depth_units", "depth_bias", "distortion", "loss", "plane_squares",
                                     "modulation_hz")}
    comparison = _compare(views, data, board, result, options, say)
    say("drawing the figures")
    sections = [
        ("summary", "Verdict and summary", _section_summary(result, views, options, comparison)),
        ("parameters", "Parameters", _section_parameters(result)),
        ("residuals", "Residuals", _section_residuals(data, result)),
        ("per-view", "Per view", _section_per_view(data, result)),
        ("coverage", "Coverage", _section_coverage(data, result)),
        ("poses", "Board poses", _section_poses(data, result, board)),
        ("planarization", "Depth planarization of one view", _section_planarization(data, result, board)),
        ("comparison", "Traditional vs depth-aided", _section_comparison(result, comparison)),
        ("cross-validation", "Cross-validation: the first half of the views against the second",
         _section_cross_validation(result, comparison, data)),
    ]
    page = _page(title or f"ToF calibration report ({result.image_size[0]}x{result.image_size[1]})", sections)
    out = atomic_write(path, page.encode("utf-8"))
    return out


# -- what the report computes ------------------------------------------------------------------
def _view_data(views: Sequence[View], board: Board, result: CalibrationResult,
               depth_units: float | None) -> list[_ViewData]:
    """Per-corner figures of the used views: the measured corners are the projection of the
    fitted pose less the residual, so no corner is detected again."""
    intr = pack_intrinsics(result.K, result.D)
    dropped = result.model.dropped_corners
    w, h = result.image_size
    out = []
    for rep in result.views:
        if not 0 <= rep.index < len(views):
            raise ReportError(f"the result uses view {rep.index} but only {len(views)} views were given: "
                              "pass the views given to calibrate")
        v = views[rep.index]
        ids = np.arange(board.n_corners) if v.ids is None else np.asarray(v.ids, dtype=int).ravel()
        ids = ids[~np.isin(ids, dropped.get(rep.index, []))]
        depth = depth_in_metres(v.depth, depth_units)
        if len(ids) != len(rep.pixel_residuals) or depth.shape != (h, w):
            raise ReportError(f"view {rep.index} does not match the result ({len(ids)} corners and a "
                              f"{depth.shape[1]}x{depth.shape[0]} image, the result has "
                              f"{len(rep.pixel_residuals)} and {w}x{h}): pass the views given to calibrate")
        X = transform(rep.rvec, rep.tvec, board.object_points(ids))[0]
        measured = project(X, intr).pixels - rep.pixel_residuals
        distance = depth_of(X, result.depth_convention)[0]
        model = bias_model.measured(result.depth_bias, distance, X, result.model.wiggle_period)
        normal = cv2.Rodrigues(np.asarray(rep.rvec, dtype=float).reshape(3, 1))[0][:, 2]
        out.append(_ViewData(rep.index, ids, measured, rep.pixel_residuals, distance, model,
                             model - rep.depth_residuals, sample_depth(depth, measured),
                             float(np.degrees(np.arccos(min(abs(normal[2]), 1.0)))), depth,
                             None if v.amplitude is None else np.asarray(v.amplitude)))
    return out


def _calibrate(views: list[View], board: Board, result: CalibrationResult, method: str,
               options: dict) -> CalibrationResult | str:
    # the convention a depth-aided result chose, or, where none was (a traditional result's), the one asked
    convention = result.depth_convention if result.method == "depth" else result.options.depth_convention
    try:
        return calibrate(views, board, result.image_size, convention, method, **options)
    except CalibrationError as exc:
        return str(exc)


def _compare(views: Sequence[View], data: list[_ViewData], board: Board, result: CalibrationResult,
             options: dict, say: Callable[[str], None]) -> _Comparison:
    # The used views with their corners as the result has them: nothing is detected again, and
    # corners a robust fit dropped stay out.
    known = {d.index: View(views[d.index].depth, d.measured, d.ids, views[d.index].amplitude) for d in data}
    used = [d.index for d in data]
    same_lens = None
    if result.method == "depth":   # the baseline as ROS camera_calibration runs it, whatever lens ours chose
        say(f"the traditional calibration of the same {len(used)} views")
        other = _calibrate([known[i] for i in used], board, result, "traditional", {**options, "distortion": "auto"})
        if not isinstance(other, str) and other.model.distortion != result.model.distortion:
            same_lens = _calibrate([known[i] for i in used], board, result, "traditional", options)
    else:   # a traditional result says nothing of the depth model: the depth method's defaults
        say(f"the depth-aided calibration of the same {len(used)} views")
        other = _calibrate([known[i] for i in used], board, result, "depth",
                           {k: result.options.to_dict()[k] for k in ("depth_units", "loss")})
    half_views = (used[:len(used) // 2], used[len(used) // 2:])
    if len(used) < MIN_CV_VIEWS:
        return _Comparison(other, None, half_views,
                           f"skipped: the calibration used {len(used)} views; a cross-validation needs at least "
                           f"{MIN_CV_VIEWS} (three a half)", same_lens)
    halves = []
    for which, idx in zip(("first", "second"), half_views):
        say(f"the {which} half of the views alone ({len(idx)})")
        halves.append(_calibrate([known[i] for i in idx], board, result, result.method, options))
    return _Comparison(other, (halves[0], halves[1]), half_views, same_lens=same_lens)


def _half_ratios(result: CalibrationResult, comparison: _Comparison) -> list[tuple[str, float, float, float]] | None:
    """Per estimated parameter: the halves' difference, its predicted standard deviation and their
    ratio (in the shown units); None when there is no cross-validation or a half failed."""
    if comparison.halves is None or any(isinstance(h, str) for h in comparison.halves):
        return None
    first, second = comparison.halves
    v1, v2 = _values(first), _values(second)
    out = []
    for n in _estimated(result):
        k = SHOWN_SCALE.get(n, 1.0)
        sigma = float(np.hypot(first.std.get(n, 0.0) * k, second.std.get(n, 0.0) * k))
        diff = (v1[n] - v2[n]) * k
        out.append((n, diff, sigma, abs(diff) / sigma if sigma > 0 else np.inf))
    return out


def _values(r: CalibrationResult) -> dict[str, float]:
    return dict(zip(PARAMS, map(float, np.r_[pack_intrinsics(r.K, r.D), r.depth_bias])))


def _estimated(r: CalibrationResult) -> list[str]:
    return [n for n in PARAMS if r.std.get(n, 0.0) > 0]


# -- formatting --------------------------------------------------------------------------------
def _e(text: object) -> str:
    return html.escape(str(text))


def _decimals(std: float) -> int:
    """Decimals that show a value to the second significant digit of its standard deviation."""
    if not (np.isfinite(std) and std > 0):
        return 4
    return int(np.clip(1 - np.floor(np.log10(std)), 0, 12))


def _num(value: float, decimals: int) -> str:
    return f"{value:.{decimals}f}" if np.isfinite(value) else "—"


def _std(std: float) -> str:
    """Two significant digits; an infinite one is a term the views leave free (a rational lens's
    numerator and denominator trade), not one held fixed."""
    if np.isinf(std):
        return "unconstrained"
    if not (np.isfinite(std) and std > 0):
        return "fixed"
    return f"{std:.0f}" if std >= 10 else f"{std:#.2g}".rstrip(".")


def _shown(result: CalibrationResult, name: str) -> str:
    """A parameter as 'value ± std unit', in the units of the tables."""
    k = SHOWN_SCALE.get(name, 1.0)
    s = result.std.get(name, 0.0) * k
    return f"{_num(_values(result)[name] * k, _decimals(s))} ± {_std(s)} {UNITS.get(name, '')}".rstrip()


def _table(table_id: str, header: list[str], rows: list[list[str]], classes: list[list[str]] | None = None) -> str:
    """A table of already-escaped cells."""
    head = "".join(f"<th>{h}</th>" for h in header)
    body = []
    for r, row in enumerate(rows):
        cls = classes[r] if classes else [""] * len(row)
        body.append("<tr>" + "".join(f'<td class="{c}">{cell}</td>' if c else f"<td>{cell}</td>"
                                     for cell, c in zip(row, cls)) + "</tr>")
    return f'<table id="{table_id}"><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody></table>'


def _figure(fig: Figure, alt: str, caption: str) -> str:
    buf = io.BytesIO()
    FigureCanvasAgg(fig).print_png(buf)
    data = base64.b64encode(buf.getvalue()).decode("ascii")
    return (f'<figure><img alt="{_e(alt)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{_e(caption)}</figcaption></figure>")


def _new_figure(width: float, height: float) -> Figure:
    return Figure(figsize=(width, height), dpi=DPI, layout="tight")  # constrained is twice as slow to draw


def _colours(n: int) -> np.ndarray:
    return colormaps["viridis"](np.linspace(0.0, 0.9, max(n, 1)))


def _page(title: str, sections: list[tuple[str, str, str]]) -> str:
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    nav = "".join(f'<a href="#{sid}">{_e(head)}</a>' for sid, head, _ in sections)
    body = "".join(f'<section id="{sid}"><h2>{_e(head)}</h2>{content}</section>' for sid, head, content in sections)
    return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>{_e(title)}</title>'
            f"<style>{CSS}</style></head><body><h1>{_e(title)}</h1><p>written {_e(when)}</p>"
            f"<nav>{nav}</nav>{body}</body></html>\n")


# -- sections ----------------------------------------------------------------------------------
def _section_summary(result: CalibrationResult, views: Sequence[View], options: dict,
                     comparison: _Comparison) -> str:
    # the banner agrees with the cross-validation below: passing every check is not "trusted"
    # when the halves of the views disagree beyond their stated uncertainties
    apart = [(n, r) for n, _, _, r in _half_ratios(result, comparison) or [] if r > CONSISTENT_SIGMAS]
    if result.ok and apart:
        verdict = ('<div class="warn"><b>Passes every check, but the cross-validation disagrees:</b> the two halves '
                   "of the views give " + _e(", ".join(f"{n} {r:.1f}" for n, r in apart)) + " predicted standard "
                   "deviations apart (see Cross-validation). The stated uncertainties understate the real ones: "
                   "take them as lower bounds, and add views at other distances, tilts and image regions.</div>")
    elif result.ok:
        verdict = '<div class="ok"><b>Trusted:</b> the calibration passes every check.</div>'
    else:
        verdict = ('<div class="bad"><b>Do not trust this calibration:</b><ul>'
                   + "".join(f"<li>{_e(r)}</li>" for r in result.verdict) + "</ul></div>")
    bias = ", ".join(f"{n} {_shown(result, n)}" for n in bias_model.NAMES if result.std.get(n, 0.0) > 0)
    rows = [
        ["method", _e(result.method)],
        ["image size", _e(f"{result.image_size[0]} x {result.image_size[1]} px")],
        ["depth convention", _e(result.depth_convention)],
        ["model", _e(f"distortion {options['distortion']}, depth bias {options['depth_bias']}"
                     + (f", planes on the {options['plane_squares']} squares" if result.method == "depth" else "")
                     + "".join(f"; {r}" for r in result.model.reasons))],
        ["views used", _e(f"{len(result.views)} of {len(views)}")],
        ["pixel RMS", _e(f"{result.pixel_rms:.3f} px")],
        ["depth RMS", _e(f"{result.depth_rms * 1e3:.2f} mm" if np.isfinite(result.depth_rms) else "no depth")],
        ["depth bias", _e(bias or "none estimated")],
    ] + ([] if result.depth_gain is None else [["what the depth added", _e(result.gain_brief())]])
    parts = [verdict, _table("summary-table", ["", ""], rows)]
    if result.rejected:
        parts.append("<p>Views left out:</p><ul>" + "".join(f"<li>view {k}: {_e(r)}</li>"
                                                            for k, r in sorted(result.rejected.items())) + "</ul>")
    if result.notes:
        parts.append('<div class="note"><p>Notes of the calibration:</p><ul>'
                     + "".join(f"<li>{_e(n)}</li>" for n in result.notes) + "</ul></div>")
    return "".join(parts)


def _section_parameters(result: CalibrationResult) -> str:
    values = _values(result)
    rows = []
    for name in PARAMS:
        s = result.std.get(name, 0.0)
        if name in bias_model.NAMES and not (s > 0 or values[name]):
            continue   # a depth bias term neither estimated nor set
        k = SHOWN_SCALE.get(name, 1.0)
        rows.append([_e(name), _num(values[name] * k, _decimals(s * k)), _std(s * k), _e(UNITS.get(name, ""))])
    return ("<p>Each value to the second significant digit of its stated standard deviation: the noise's "
            "(from the Jacobian at the solution, scaled by the residual variance, poses marginalised), "
            "raised to the spread of the refits without each run of views where that is larger, and to the "
            "move of the camera's terms under pixels weighted alike where the noise does not explain it. "
            "What no view reached it does not see: the coverage and cross-validation below tell.</p>"
            + _table("parameters", ["parameter", "value", "± std", "unit"], rows))


def _section_residuals(data: list[_ViewData], result: CalibrationResult) -> str:
    w, h = result.image_size
    colours = _colours(len(data))
    res = np.concatenate([d.residual for d in data])
    pts = np.concatenate([d.measured for d in data])
    point_colours = np.concatenate([np.repeat(c[None], len(d.residual), 0) for c, d in zip(colours, data)])
    fig = _new_figure(11, 4.8)
    a, b = fig.subplots(1, 2, width_ratios=[1, 1.3])
    a.scatter(res[:, 0], res[:, 1], s=7, c=point_colours, linewidths=0, alpha=0.8)
    a.add_patch(Circle((0, 0), result.pixel_rms, fill=False, ls="--", color="k"))
    lim = 1.1 * max(np.abs(res).max(), result.pixel_rms, 1e-9)
    a.set(xlim=(-lim, lim), ylim=(lim, -lim), aspect="equal", xlabel="x residual (px)", ylabel="y residual (px)",
          title=f"pixel residuals, RMS {result.pixel_rms:.3f} px (dashed)")
    a.axhline(0, color="0.7", lw=0.5)
    a.axvline(0, color="0.7", lw=0.5)
    length = np.hypot(res[:, 0], res[:, 1])
    scale = _nice(0.05 * max(w, h) / max(np.percentile(length, 95), 1e-12))
    b.quiver(pts[:, 0], pts[:, 1], res[:, 0] * scale, res[:, 1] * scale, color=point_colours, angles="xy",
             scale_units="xy", scale=1, width=0.0025)
    # The mean residual per image cell: a pattern there is a model error, not noise.
    cell = cell_of(pts[:, 1], h) * CELLS + cell_of(pts[:, 0], w)
    for c in np.unique(cell):
        sel = cell == c
        if sel.sum() >= 3:
            p, r = pts[sel].mean(0), res[sel].mean(0) * scale
            b.annotate("", p + r, p, arrowprops={"arrowstyle": "->", "color": "crimson", "lw": 1.8})
    b.set(xlim=(-0.5, w - 0.5), ylim=(h - 0.5, -0.5), aspect="equal", xlabel="x (px)", ylabel="y (px)",
          title=f"residual vectors over the image, x{scale:g}")
    caption = (f"Left: every corner's residual (predicted minus detected), coloured by view. Right: the same "
               f"residuals drawn at their corners, magnified {scale:g} times, and in red the mean residual of each "
               f"of the {CELLS}x{CELLS} image cells with 3 corners or more (same scale): "
               "a pattern there, rather than noise, means the lens model does not fit.")
    return _figure(fig, "pixel residuals", caption) + _depth_residual_figure(data, result)


def _nice(x: float) -> float:
    """The largest of 1, 2, 5 times a power of ten not above x."""
    p = 10.0 ** np.floor(np.log10(x))
    return float(max(m for m in (1, 2, 5) if m * p <= x) * p)


def _depth_residual_figure(data: list[_ViewData], result: CalibrationResult) -> str:
    dist = np.concatenate([d.distance for d in data])
    raw = np.concatenate([d.raw - d.model_depth for d in data]) * 1e3
    if not (np.isfinite(raw).any() or np.isfinite(result.depth_rms)):
        return '<p class="note">No depth residuals: no view has depth at its corners.</p>'
    fig = _new_figure(10, 4.2)
    ax = fig.subplots()
    ax.scatter(dist, raw, s=5, color="0.65", linewidths=0, label="raw depth at the corner − model")
    for c, d in zip(_colours(len(data)), data):
        ax.scatter(d.distance, (d.denoised - d.model_depth) * 1e3, s=10, color=c, linewidths=0)
    ax.scatter([], [], s=10, color=_colours(1)[0], label="planarized depth − model (used by the fit), by view")
    fin = np.isfinite(raw)
    if fin.sum() >= 8:
        edges = np.linspace(dist[fin].min(), dist[fin].max(), 9)
        which = np.clip(np.digitize(dist[fin], edges) - 1, 0, 7)
        med = [np.median(raw[fin][which == k]) if np.any(which == k) else np.nan for k in range(8)]
        ax.plot((edges[:-1] + edges[1:]) / 2, med, "k-", lw=1.5, label="median of the raw, binned")
        lo, hi = np.percentile(raw[fin], [1, 99])
        ax.set_ylim(min(lo, -1.0) * 1.2, max(hi, 1.0) * 1.2)
    ax.axhline(0, color="k", lw=0.5)
    ax.set(xlabel=f"corner distance ({result.depth_convention}-depth, m)", ylabel="measured − model (mm)",
           title=f"depth residuals against distance; fit depth RMS {result.depth_rms * 1e3:.2f} mm")
    ax.legend(loc="upper right", fontsize=8)
    caption = ("The depth the camera reported at each corner (grey: raw, a 3x3 median; coloured: the planarized "
               "depth the fit used) minus the depth the calibrated model predicts, with the estimated depth bias "
               "applied. A trend of the binned median with distance is a depth error the bias model does not "
               "cover (a scale error, wiggling).")
    return _figure(fig, "depth residuals against distance", caption)


def _worst(values: np.ndarray, index: list[int], unit: str, scale: float = 1.0) -> str:
    fin = np.isfinite(values)
    if not fin.any():
        return "none"
    med = np.median(values[fin])
    order = [k for k in np.argsort(-np.where(fin, values, -np.inf)) if fin[k]][:WORST_SHOWN]
    return ", ".join(f"view {index[k]} ({values[k] * scale:.3g} {unit}, {values[k] / med:.1f}x the median)"
                     if med > 0 else f"view {index[k]} ({values[k] * scale:.3g} {unit})" for k in order)


def _section_per_view(data: list[_ViewData], result: CalibrationResult) -> str:
    index = [rep.index for rep in result.views]
    pix = np.array([rep.pixel_rms for rep in result.views])
    dep = np.array([rep.depth_rms for rep in result.views])
    n = len(index)
    fig = _new_figure(max(6.0, 0.22 * n + 2), 5)
    a, b = fig.subplots(2, 1, sharex=True)
    pos = np.arange(n)
    for ax, values, label in ((a, pix, "pixel RMS (px)"), (b, dep * 1e3, "depth RMS (mm)")):
        fin = np.isfinite(values)
        worst = set(np.argsort(-np.where(fin, values, -np.inf))[:WORST_SHOWN]) & set(np.flatnonzero(fin))
        ax.bar(pos, np.where(fin, values, 0), color=["crimson" if k in worst else "steelblue" for k in range(n)])
        if fin.any():
            ax.axhline(np.median(values[fin]), color="k", ls="--", lw=1)
        ax.set_ylabel(label)
    b.set_xticks(pos, [str(i) for i in index], rotation=90 if n > 20 else 0, fontsize=8)
    b.set_xlabel("view (index in the list given)")
    a.set_title("per-view RMS; the worst in red, the median dashed")
    rows = [[str(d.index), f"{np.median(d.distance):.3f}", f"{d.tilt_deg:.1f}", str(len(d.ids)),
             f"{rep.pixel_rms:.3f}", _num(rep.depth_rms * 1e3, 2), _num(rep.plane_sigma * 1e3, 2),
             str(rep.plane_pixels), _num(rep.saturation * 100, 0)] for d, rep in zip(data, result.views)]
    return (f"<p>Worst by pixel RMS: {_e(_worst(pix, index, 'px'))}.<br>Worst by depth RMS: "
            f"{_e(_worst(dep, index, 'mm', 1e3))}.</p>"
            + _figure(fig, "per-view RMS", "Each view's pixel and depth RMS after the fit. A view far above the "
                      "others is worth a look (a misdetected corner, a moving board, a depth artefact, white "
                      "squares that clip at the amplitude's full scale).")
            + _table("views", ["view", "distance (m)", "tilt (deg)", "corners", "pixel RMS (px)", "depth RMS (mm)",
                               "plane σ (mm)", "plane pixels", "clipped (% of the board)"], rows))


def _section_coverage(data: list[_ViewData], result: CalibrationResult) -> str:
    w, h = result.image_size
    colours = _colours(len(data))
    counts = cell_counts(np.concatenate([d.measured for d in data]), result.image_size)
    covered = int((counts > 0).sum())
    fig = _new_figure(11, 4.6)
    a, b = fig.subplots(1, 2, width_ratios=[1.2, 1])
    a.imshow((counts.T == 0).astype(float), cmap="Reds", vmin=0, vmax=3, extent=(-0.5, w - 0.5, h - 0.5, -0.5),
             interpolation="nearest")
    for c, d in zip(colours, data):
        a.scatter(d.measured[:, 0], d.measured[:, 1], s=5, color=c, linewidths=0)
    for k in range(1, CELLS):
        a.axvline(-0.5 + k * w / CELLS, color="0.8", lw=0.5)
        a.axhline(-0.5 + k * h / CELLS, color="0.8", lw=0.5)
    a.set(xlim=(-0.5, w - 0.5), ylim=(h - 0.5, -0.5), aspect="equal", xlabel="x (px)", ylabel="y (px)",
          title=f"corners over the image: {covered} of {CELLS ** 2} cells (empty cells red)")
    order = np.argsort([np.median(d.distance) for d in data])
    for row, k in enumerate(order):
        d = data[k]
        b.plot([d.distance.min(), d.distance.max()], [row, row], lw=4, color=colours[k], solid_capstyle="butt")
    b.set_yticks(np.arange(len(data)), [str(data[k].index) for k in order], fontsize=7 if len(data) > 25 else 9)
    b.set(xlabel="corner distance (m)", ylabel="view", title="depth range covered by each view")
    near = min(d.distance.min() for d in data)
    far = max(d.distance.max() for d in data)
    tilts = [d.tilt_deg for d in data]
    text = (f"The corners fall in {covered} of the {CELLS}x{CELLS} image cells; the views span "
            f"{near:.3f} to {far:.3f} m and tilts of {min(tilts):.0f} to {max(tilts):.0f} degrees. Corners near the "
            "image edges constrain the distortion; a wide range of distances separates the focal length from the "
            "depth offset.")
    return (f"<p>{_e(text)}</p>" + _figure(fig, "coverage", "Left: every detected corner, coloured by view, over "
            "the image. Right: each view's corner distances, from the nearest corner to the farthest.")
            + _projection_spread(data, result))


def _projection_spread(data: list[_ViewData], result: CalibrationResult) -> str:
    """How well the calibration knows each pixel's ray: its stated sigmas are the runs' spread in
    each parameter, which cannot say where over the image the runs part (mrcal's uncertainty map)."""
    if result.run_intrinsics is None:
        return ('<p class="note">No map of the projection\'s uncertainty: this calibration was not refitted '
                "without each run of views (the traditional method, or too few views).</p>")
    corners = np.concatenate([d.measured for d in data])
    known = reach(pack_intrinsics(result.K, result.D), result.run_intrinsics, corners, result.image_size)
    runs = len(result.run_intrinsics)
    text = (f"How far each pixel's projection moves when the calibration is refitted without each of its {runs} runs "
            "of consecutive views (the grouped jackknife behind the stated standard deviations, taken per pixel; "
            "each refit's frame aligned as in the cross-validation's map). ")
    if known.known.size:
        text += f"Where the views reached, the projection is known to a median of {np.median(known.known):.2f} px " \
                f"({known.known.max():.2f} at most)"
    if known.beyond.size:
        text += f"; beyond them, where the lens terms are extrapolated, to {known.beyond.max():.2f} px at worst"
    text += f". A jackknife over {runs} runs is rough: read it as a scale, not a bound."
    fig, ax = _pixel_map(known.xs, known.ys, known.spread, known.inside, result.image_size,
                         "projection uncertainty (px)", "how well each pixel's projection is known")
    ax.scatter(corners[:, 0], corners[:, 1], s=3, color="w", linewidths=0)
    return f"<p>{_e(text)}</p>" + _figure(fig, "projection uncertainty", (
        "The spread of each pixel's projection over the refits without each run of views (px; colour scale to its "
        "99th percentile). Cyan outlines the cells the views reached; the dots are the corners."))


def _pixel_map(xs: np.ndarray, ys: np.ndarray, values: np.ndarray, outlined: np.ndarray,
               image_size: tuple[int, int], label: str, title: str) -> tuple[Figure, Axes]:
    """A map over the image in px (colour scale to its 99th percentile), the cells ``outlined``
    (same grid) edged in cyan."""
    w, h = image_size
    fig = _new_figure(8.0, 6.4 * h / w + 0.8)   # the colour bar takes a fifth of the width
    ax = fig.subplots()
    top = np.nanpercentile(values, 99) if np.isfinite(values).any() else 1.0
    mesh = ax.pcolormesh(xs, ys, values, cmap="magma", vmin=0.0, vmax=max(top, 1e-3), shading="nearest")
    fig.colorbar(mesh, ax=ax, label=label)
    ax.contour(xs, ys, outlined.astype(float), levels=[0.5], colors="cyan", linewidths=1.5)
    ax.set(xlim=(-0.5, w - 0.5), ylim=(h - 0.5, -0.5), aspect="equal", xlabel="x (px)", ylabel="y (px)", title=title)
    return fig, ax


def _section_poses(data: list[_ViewData], result: CalibrationResult, board: Board) -> str:
    fig = _new_figure(7.5, 6.5)
    ax = fig.add_subplot(projection="3d")
    ax.computed_zorder = False   # the view labels stay on top of the boards
    outline = board.outline(1, per_edge=1)
    allpts = [np.zeros((1, 3))]
    for c, rep in zip(_colours(len(data)), result.views):
        X = transform(rep.rvec, rep.tvec, outline)[0]
        P = np.column_stack([X[:, 0], X[:, 2], -X[:, 1]])   # plotted with the optical axis into the page
        ax.add_collection3d(Poly3DCollection([P], facecolor=c, edgecolor=c, alpha=0.35))
        centre = P.mean(0)
        ax.text(centre[0], centre[1], centre[2], str(rep.index), fontsize=8, zorder=10)
        allpts.append(P)
    pts = np.concatenate(allpts)
    w, h = result.image_size
    near = 0.3 * min(d.distance.min() for d in data)
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], dtype=float)
    ray = directions(corners, pack_intrinsics(result.K, result.D), "z") * near
    for r in ray:
        ax.plot([0, r[0]], [0, r[2]], [0, -r[1]], color="k", lw=0.8)
    ax.plot(*np.column_stack([ray[:, 0], ray[:, 2], -ray[:, 1]])[[0, 1, 2, 3, 0]].T, color="k", lw=0.8)
    lo, hi = pts.min(0), pts.max(0)
    ax.set(xlim=(lo[0], hi[0]), ylim=(0, hi[1]), zlim=(lo[2], hi[2]), xlabel="x (m)", ylabel="z (m)",
           zlabel="−y (m)", title="board poses in the camera frame")
    ax.set_box_aspect(np.maximum(hi - np.r_[lo[0], 0, lo[2]], 1e-3))
    ax.view_init(elev=20, azim=-65)
    return _figure(fig, "board poses", "Each used view's board (its outer edge) in the camera frame, labelled with "
                   "its view index; the camera's field of view in black. Varied tilts fix the principal point, "
                   "varied distances the focal length against the depth offset.")


def _section_planarization(data: list[_ViewData], result: CalibrationResult, board: Board) -> str:
    j = int(np.argmax([rep.plane_pixels for rep in result.views]))
    if result.views[j].plane_pixels == 0:
        return '<p class="note">No view was planarized (a traditional calibration, or no usable depth).</p>'
    d = data[j]
    intr = pack_intrinsics(result.K, result.D)
    conv, bias, period = result.depth_convention, result.depth_bias, result.model.wiggle_period
    try:
        samples = board_samples(d.depth, d.measured, d.ids, board, intr, d.amplitude,
                                squares=result.model.plane_squares)
    except CalibrationError as exc:
        return f'<p class="note">View {d.index} cannot be planarized again: {_e(exc)}</p>'
    # As the calibration does: RANSAC against outliers, then the plane in bias-corrected depth.
    inl = samples.subset(fit_samples(samples, intr, conv).inliers)
    u = directions(inl.pixels, intr, conv)
    plane = fit_plane_to(u, bias_model.true_depth(bias, inl.depth, u, period), inl.pixels, inl.black)

    def on_plane(pixels: np.ndarray) -> np.ndarray:
        """The depth the camera would report on the fitted plane (bias applied)."""
        du = directions(pixels, intr, conv)
        true = corner_depth_along(plane, du)[0]
        return bias_model.measured(bias, true, du * true[:, None], period)

    w, h = result.image_size
    rep = result.views[j]
    outline = project(transform(rep.rvec, rep.tvec, board.outline(1, per_edge=24))[0], intr).pixels
    mask = np.zeros((h, w), np.uint8)
    cv2.fillPoly(mask, [np.round(outline).astype(np.int32)], 1)
    ys, xs = np.nonzero(mask)
    x0, x1, y0, y1 = xs.min(), xs.max(), ys.min(), ys.max()
    planed = np.full((h, w), np.nan)
    planed[ys, xs] = on_plane(np.column_stack([xs, ys]).astype(float))
    raw = np.where(mask > 0, d.depth, np.nan)
    crop = (slice(y0, y1 + 1), slice(x0, x1 + 1))
    resid = (raw - planed)[crop] * 1e3
    fin = resid[np.isfinite(resid)]
    sigma = 1.4826 * np.median(np.abs(fin - np.median(fin))) if fin.size else 1.0
    lim = max(4 * sigma, 1e-3)
    raw_corner = d.raw * 1e3
    den_corner = on_plane(d.measured) * 1e3
    diff = raw_corner - den_corner

    fig = _new_figure(12, 7.5)
    grid = fig.add_gridspec(2, 3, height_ratios=[1.2, 1])
    extent = (x0 - 0.5, x1 + 0.5, y1 + 0.5, y0 - 0.5)
    vals = np.r_[raw[crop][np.isfinite(raw[crop])], planed[crop][np.isfinite(planed[crop])]] * 1e3
    vmin, vmax = np.percentile(vals, [1, 99])
    for k, (image, name) in enumerate(((raw[crop] * 1e3, "raw depth (mm)"), (planed[crop] * 1e3, "fitted plane (mm)"))):
        ax = fig.add_subplot(grid[0, k])
        im = ax.imshow(image, extent=extent, vmin=vmin, vmax=vmax, cmap="viridis", interpolation="nearest")
        fig.colorbar(im, ax=ax, shrink=0.8)
        ax.set_title(name)
    ax = fig.add_subplot(grid[0, 2])
    cmap = _cmap("RdBu_r")
    im = ax.imshow(resid, extent=extent, vmin=-lim, vmax=lim, cmap=cmap, interpolation="nearest")
    ax.plot(d.measured[:, 0], d.measured[:, 1], "k.", ms=2)
    fig.colorbar(im, ax=ax, shrink=0.8, label="mm")
    ax.set_title("raw − plane (mm)")
    ax = fig.add_subplot(grid[1, :2])
    k = np.arange(len(d.ids))
    ax.plot(k, raw_corner, "o", ms=4, color="0.5", label="raw (3x3 median at the corner)")
    ax.plot(k, den_corner, ".-", ms=5, color="tab:blue", label="planarized")
    ax.set(xlabel="corner (board index order)", ylabel="depth (mm)", title="corner depths, raw and planarized")
    ax.legend(fontsize=8, loc="lower left", framealpha=0.9)
    ax = fig.add_subplot(grid[1, 2])
    ax.bar(k, np.nan_to_num(diff), color="0.5")
    ax.axhline(0, color="k", lw=0.5)
    rms = np.sqrt(np.nanmean(diff ** 2)) if np.isfinite(diff).any() else np.nan
    ax.set(xlabel="corner", ylabel="mm", title=f"raw − planarized at the corners, RMS {rms:.2f} mm")
    fitted = "white-square pixels" if result.model.plane_squares == "white" else "pixels of both colours"
    text = (f"View {d.index}, the one with the most plane pixels: {len(plane.pixels)} {fitted} fit the "
            f"plane with σ {plane.sigma * 1e3:.2f} mm on the white squares (bias-corrected depth); over the "
            f"whole board area (black squares and edges included) raw − plane has a robust σ of {sigma:.2f} mm; "
            f"at the {len(d.ids)} corners the raw depth differs from the planarized by {rms:.2f} mm RMS.")
    return (f"<p>{_e(text)}</p>" + _figure(fig, "planarization", "Top: the raw depth over the board, the plane "
            f"fitted to its {result.model.plane_squares} squares (the depth the camera would report on it, bias "
            "included), and their difference, corners dotted. Bottom: the corner depths the calibration uses "
            "(planarized) against the raw depth there: the noise the planarization removes."))


def _cmap(name: str):
    return colormaps[name].with_extremes(bad="0.85")


def _section_comparison(result: CalibrationResult, comparison: _Comparison) -> str:
    other = comparison.other
    if isinstance(other, str):
        return (f'<p class="bad">The {_e("traditional" if result.method == "depth" else "depth-aided")} calibration '
                f"of the same views failed: {_e(other)}</p>")
    depth, trad = (result, other) if result.method == "depth" else (other, result)
    names = [n for n in PARAMS if n in _estimated(depth) or n in _estimated(trad)]
    vd, vt = _values(depth), _values(trad)
    rows = []
    for n in names:
        k = SHOWN_SCALE.get(n, 1.0)
        sd, st = depth.std.get(n, 0.0) * k, trad.std.get(n, 0.0) * k
        dec = _decimals(min(s for s in (sd, st, np.inf) if s > 0))
        if n in bias_model.NAMES and n not in _estimated(trad):   # OpenCV has no depth model
            rows.append([_e(n), _num(vd[n] * k, dec), _std(sd), "—", "", "—", _e(UNITS.get(n, ""))])
            continue
        rows.append([_e(n), _num(vd[n] * k, dec), _std(sd), _num(vt[n] * k, dec), _std(st),
                     _num((vd[n] - vt[n]) * k, dec), _e(UNITS.get(n, ""))])
    rows.append(["pixel RMS", f"{depth.pixel_rms:.3f}", "", f"{trad.pixel_rms:.3f}", "",
                 f"{depth.pixel_rms - trad.pixel_rms:+.3f}", "px"])
    rows.append(["views used", str(len(depth.views)), "", str(len(trad.views)), "", "", ""])
    verdict = "passes its checks" if trad.ok else "fails its checks: " + "; ".join(trad.verdict)
    fig = _new_figure(10, 2.8)
    for ax, n in zip(fig.subplots(1, 4), ("fx", "fy", "cx", "cy")):
        ax.errorbar([0, 1], [vd[n], vt[n]], yerr=[depth.std[n], trad.std[n]], fmt="o", capsize=4, color="k")
        ax.set_xticks([0, 1], ["depth-aided", "traditional"])
        ax.set_xlim(-0.5, 1.5)
        ax.set_title(f"{n} (px)")
    return (f"<p>OpenCV's calibrateCamera (Zhang's method, k3 fixed, as ROS camera_calibration runs it) on the "
            f"same corners. It fits the pixels alone, so its pixel RMS is lower by construction; compare the "
            f"standard deviations and the values. The traditional calibration {_e(verdict)}.</p>"
            + _table("comparison", ["parameter", "depth-aided", "± std", "traditional", "± std",
                                    "depth-aided − traditional", "unit"], rows)
            + _figure(fig, "traditional vs depth-aided", "The focal lengths and principal point of both methods, "
                      "with one standard deviation.")
            + _same_lens(depth, comparison.same_lens))


def _same_lens(depth: CalibrationResult, same: CalibrationResult | str | None) -> str:
    """The principal point beside OpenCV's with the depth-aided result's lens terms: it trades with
    them (on the Kinect v2 views k3 alone moves OpenCV's by 1.4 px), so part of a difference from
    the k3-fixed baseline is the lens model's, not the depth's."""
    if same is None:
        return ""
    lens = _e(depth.model.distortion)
    if isinstance(same, str):
        return f'<p class="note">OpenCV fitting the same lens terms ({lens}) failed: {_e(same)}</p>'
    apart = depth.K[:2, 2] - same.K[:2, 2]
    sigma = np.hypot([depth.std["cx"], depth.std["cy"]], [same.std["cx"], same.std["cy"]])
    return (f'<p class="note">The depth-aided calibration chose the {lens} lens terms. OpenCV fitting the same '
            f"terms gives fx {same.K[0, 0]:.2f}, fy {same.K[1, 1]:.2f}, cx {same.K[0, 2]:.2f} ± {same.std['cx']:.2f}, "
            f"cy {same.K[1, 2]:.2f} ± {same.std['cy']:.2f} px: the depth-aided principal point is "
            f"{apart[0]:+.2f}, {apart[1]:+.2f} px from it ({abs(apart[0]) / sigma[0]:.1f} and "
            f"{abs(apart[1]) / sigma[1]:.1f} standard deviations of the difference). The principal point "
            "trades with the lens terms, so part of its difference from the table's is the lens model's.</p>")


def _section_cross_validation(result: CalibrationResult, comparison: _Comparison, data: list[_ViewData]) -> str:
    if comparison.halves is None:
        return f'<p class="note">Cross-validation {_e(comparison.skipped)}.</p>'
    first, second = comparison.halves
    intro = (f"<p>The views the calibration used, split in the order given (a recording's): first "
             f"{_e(comparison.half_views[0])}, second {_e(comparison.half_views[1])}, each calibrated alone with "
             "the same model. If the standard deviations are honest, the two differ by no more than about three "
             "times the predicted standard deviation of their difference, sqrt(σ_first² + σ_second²). Halves that "
             "cover different parts of the image or distances show here what the views left out would do.</p>")
    for name, half in (("first", first), ("second", second)):
        if isinstance(half, str):
            return intro + f'<p class="bad">The {name} half of the views could not be calibrated: {_e(half)}</p>'
    v1, v2 = _values(first), _values(second)
    rows, classes, ratios, names = [], [], [], []
    for n, diff, sigma, ratio in _half_ratios(result, comparison):
        k = SHOWN_SCALE.get(n, 1.0)
        s1, s2 = first.std.get(n, 0.0) * k, second.std.get(n, 0.0) * k
        ok = ratio <= CONSISTENT_SIGMAS
        dec = _decimals(sigma)
        rows.append([_e(n), _num(v1[n] * k, dec), _std(s1), _num(v2[n] * k, dec), _std(s2), _num(diff, dec),
                     _std(sigma), f"{ratio:.2f}", "consistent" if ok else "inconsistent"])
        classes.append([""] * 8 + ["pass" if ok else "fail"])
        ratios.append(ratio)
        names.append(n)
    bad = [n for n, r in zip(names, ratios) if r > CONSISTENT_SIGMAS]
    summary = (f"{len(names) - len(bad)} of {len(names)} parameters agree within {CONSISTENT_SIGMAS:g} predicted "
               "standard deviations" + (f"; for {', '.join(bad)} the stated standard deviations understate the real "
                                         "uncertainty: take them as lower bounds, and add views (other distances, "
                                         "tilts, image regions)." if bad else "."))
    fig = _new_figure(max(5.0, 0.6 * len(names) + 2), 3.4)
    ax = fig.subplots()
    shown = np.minimum(ratios, 10 * CONSISTENT_SIGMAS)
    ax.bar(np.arange(len(names)), shown, color=["crimson" if r > CONSISTENT_SIGMAS else "seagreen" for r in ratios])
    ax.axhline(CONSISTENT_SIGMAS, color="k", ls="--", lw=1)
    ax.set_xticks(np.arange(len(names)), names, rotation=45, fontsize=8)
    ax.set(ylabel="|difference| / predicted σ", title="first − second half, in predicted standard deviations")
    return (intro + f"<p><b>{_e(summary)}</b></p>"
            + _table("cross-validation", ["parameter", "first half", "± std", "second half", "± std",
                                          "difference (first − second)", "predicted std of the difference", "ratio",
                                          "verdict"], rows, classes)
            + _figure(fig, "cross-validation ratios", f"The difference of each parameter between the halves over "
                      f"its predicted standard deviation; the dashed line is {CONSISTENT_SIGMAS:g}.")
            + _halves_projection(first, second, data, comparison.half_views, result))


def _halves_projection(first: CalibrationResult, second: CalibrationResult, data: list[_ViewData],
                       half_views: tuple[list[int], list[int]], result: CalibrationResult) -> str:
    """Where over the image the halves project apart: the table says by how much each parameter
    differs, not whether that matters where the board was, or only where no view reached."""
    corners = [np.concatenate([d.measured for d in data if d.index in idx]) for idx in half_views]
    both = np.logical_and(*[cell_counts(c, result.image_size) > 0 for c in corners])
    seen = np.concatenate(corners)
    seen = seen[in_cells(both, seen, result.image_size)] if both.any() else seen
    pd = projection_difference(pack_intrinsics(first.K, first.D), pack_intrinsics(second.K, second.D),
                               result.image_size, seen)
    shared = grid_in_cells(both, pd.xs, pd.ys, result.image_size)
    looked = pd.diff[shared & np.isfinite(pd.diff)]
    elsewhere = pd.diff[~shared & np.isfinite(pd.diff)]
    text = (f"Each pixel's ray through the first half's calibration, projected through the second's, after a "
            f"rotation of the camera frame of {pd.angle_deg:.2f}° that the board poses take up (mrcal's "
            "projection_diff): what a user of either would see differ, and where. ")
    if looked.size:
        text += (f"Where both halves saw the board ({int(both.sum())} of {CELLS ** 2} cells) they differ by "
                 f"a median of {np.median(looked):.2f} px, {looked.max():.2f} px at most")
    else:
        text += "No cell of the image holds corners of both halves"
    text += (f"; where at most one of them looked, by up to {elsewhere.max():.2f} px. " if elsewhere.size else ". ")
    text += (f"Against the corners' fit ({result.pixel_rms:.2f} px RMS): a difference far beyond it where both "
             "looked means the halves disagree on the lens itself; one that grows only where one looked means the "
             "views did not reach there, which the standard deviations above cannot show. Add views there.")
    fig, ax = _pixel_map(pd.xs, pd.ys, pd.diff, shared, result.image_size, "projection difference (px)",
                         "first vs second half: projection difference")
    for c, marker, label in zip(corners, ("o", "x"), ("first half", "second half")):
        ax.scatter(c[:, 0], c[:, 1], s=4, marker=marker, color="w" if marker == "o" else "0.6", linewidths=0.6,
                   label=label)
    ax.legend(loc="lower right", fontsize=8, markerscale=3, facecolor="0.35", labelcolor="w")
    return f"<p>{_e(text)}</p>" + _figure(fig, "projection difference of the halves", (
        "The halves' projection difference over the image (px; colour scale to its 99th percentile). Cyan outlines "
        "the cells where both halves saw the board; the dots are the halves' corners."))
