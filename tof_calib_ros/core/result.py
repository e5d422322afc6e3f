"""What a calibration returns, and an honest verdict on whether to trust it."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy.stats import f as f_distribution

from .camera import distortion_model
from .depth_bias import NAMES
from .options import DISTORTION_TERMS, CalibrationOptions, Model

if TYPE_CHECKING:   # coverage reaches bundle, which imports this module
    from .coverage import Extrapolated

INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")

# Thresholds of the quality verdict; each failed one is given as a reason.
# (A depth scale this far from 1 is a wrong square size or depth unit as well, see below.)
MAX_PIXEL_RMS = 1.0          # px
MAX_DEPTH_RMS = 0.02         # m, after the bias correction
MAX_FOCAL_REL_STD = 0.01     # 1 % of the focal length
MAX_CENTER_REL_STD = 0.02    # 2 % of the image size
# A joint fit still moving at its iteration cap is not the data's best fit, nor is its covariance
# what the data say of it: a run-off lens crept 1,800 iterations to fx 648 for 284.
NOT_CONVERGED = ("the joint fit stopped at its iteration cap, still moving: the estimate is not the best fit to "
                 "these views, nor is its uncertainty what they say; views that reach the image's edges, at more "
                 "tilts, settle the lens")
# where calibrations re-run without each fold of the views, each choosing the wiggle's period again,
# set the uncertainty (``Model.period_spread``): told the frequency, nothing is chosen or re-run.
# Where the folds chose other periods, the period is what is unsettled; where each chose the data's
# (a pico flexx class sensor's seed 3: all five took 0.459 m, the truth 0.468, and fx still spread
# ±3.6 px), it is these views, and the frequency only removes the period's part of that.
GIVE_FREQUENCY = ("the camera's modulation frequency (the node's depth.modulation_mhz, tof_calib's "
                  "--modulation-mhz, modulation_hz in Python)")
PERIOD_UNSETTLED = ("the views do not settle the wiggle's period the data chose (calibrated without each fold of "
                    f"them, the folds chose other periods and it spreads as far): give {GIVE_FREQUENCY}, or ")
FOLDS_SPREAD = ("calibrated without each fold of the views, every fold choosing the period all of them chose, "
                f"it spreads as far: give {GIVE_FREQUENCY}, which fixes the period, and ")
# The corners alone (Zhang) fix the focal lengths whatever the square size and the depth's units;
# the depth-aided ones scale with both. They disagree when they are further apart than 5 of the
# standard deviations of their difference (a square 18 % off was let through by a fixed 25 %
# at 140 of them), and than this share of the focal length: on the real Kinect v2 views
# downsampled to 205x170 the corners alone are 3.6 % (8 of them) from the depth-aided result,
# which agrees with the full-resolution one; a square 10 % off moves the depth-aided one 5.6 %.
MAX_CORNER_DEPTH_DISAGREEMENT = 0.05
REFUSE_SIGMAS = 5.0   # a focal length or depth scale off by more than this many standard deviations is no noise
# A lens the chosen model does not hold: the corners alone fit a rational lens this many times closer
# (the Azure Kinect's wide mode: 2.6-3.6 times under plumb_bob; the real Kinect v2's lens, all views: 1.005). No
# polynomial holds a 120 degree lens: trusted in plumb_bob, such views put fx 2 % off.
LENS_MISFIT = 2.0
# The corners must fit about as well with the depth as alone. The depth costs them a little on real
# data (real Kinect v2 subsets of 3-10 views: up to 1.55 times the corners-alone pixel noise, 0.018 px
# above it); a lens model too small for the lens or a wrong depth convention costs more (0.03-0.05 px
# on the simulated 200x200 camera). Flagged when all three say so: the F-test at this false-alarm
# rate, the ratio and the excess.
CORNER_FIT_P = 1e-3
MAX_PIXEL_NOISE_RATIO = 1.6
MIN_PIXEL_EXCESS = 0.02      # px


def corners_pulled(ours: tuple[float, int], alone: tuple[float, int], tested: bool = True) -> bool:
    """Whether the corners fit worse with the depth than alone (pixel noise per degree of
    freedom and those degrees, ``noise_per_dof``): by the ratio and the excess, and where
    ``tested`` the F-test (which few degrees of freedom leave without power: 4 corners a view)."""
    (noise, dof), (noise_alone, dof_alone) = ours, alone
    return bool(dof > 0 and dof_alone > 0 and noise - noise_alone > MIN_PIXEL_EXCESS
                and noise > MAX_PIXEL_NOISE_RATIO * noise_alone
                and (not tested or (noise / noise_alone) ** 2 > f_distribution.ppf(1 - CORNER_FIT_P, dof, dof_alone)))


def noise_per_dof(pixel_residuals: list[np.ndarray], n_intrinsics: int) -> tuple[float, int]:
    """The pixel noise per degree of freedom (px) of a fit's per-view residuals, and those
    degrees: each view's 6 pose parameters and the ``n_intrinsics`` estimated fit noise too."""
    r = np.concatenate([p.ravel() for p in pixel_residuals])
    dof = r.size - 6 * len(pixel_residuals) - n_intrinsics
    return (float(np.sqrt(np.sum(r ** 2) / dof)) if dof > 0 else float("nan")), int(dof)


def lens_noise(pixel_residuals: list[np.ndarray], distortion: str) -> tuple[float, int]:
    """``noise_per_dof`` with the camera's four terms and the lens model ``distortion``'s estimated."""
    return noise_per_dof(pixel_residuals, 4 + len(DISTORTION_TERMS.get(distortion, [])))


Focal = tuple[float, float, float, float]   # fx, fy and their standard deviations


def focal_disagreements(depth_focal: Focal, corner_focal: Focal) -> list[tuple[str, float, float, float, float]]:
    """fx and fy where the depth's focal length is beyond MAX_CORNER_DEPTH_DISAGREEMENT and
    REFUSE_SIGMAS standard deviations of the difference off the corners' alone: (name, the
    depth's, the corners', their std, the difference's std), each a wrong square size or depth
    unit the verdict refuses. At the noise's uncertainty: a wrong square tears the views apart,
    and the jackknife spread it makes would hide its cause."""
    out = []
    for k, name in enumerate(("fx", "fy")):
        f, c, s = depth_focal[k], corner_focal[k], corner_focal[k + 2]
        apart = float(np.hypot(s, depth_focal[k + 2]))
        if abs(f - c) > max(MAX_CORNER_DEPTH_DISAGREEMENT * c, REFUSE_SIGMAS * apart):
            out.append((name, f, c, s, apart))
    return out


@dataclass
class ViewReport:
    """Per-view figures: what a person looks at to find a bad view."""

    index: int                    # position in the caller's list of views
    rvec: np.ndarray
    tvec: np.ndarray
    pixel_rms: float              # px
    depth_rms: float              # m (NaN when the view has no depth)
    pixel_residuals: np.ndarray   # (N, 2) predicted - measured
    depth_residuals: np.ndarray   # (N,)
    plane_sigma: float = float("nan")   # m, noise of the white-square depth about its plane
    plane_pixels: int = 0
    plane: np.ndarray | None = None     # the depth plane, coef . X = 1 in the camera frame (see planarize.Plane)
    saturation: float = float("nan")    # share of the board's amplitude pixels clipped (detection.saturation)


@dataclass
class CalibrationResult:
    method: str
    image_size: tuple[int, int]
    K: np.ndarray
    D: np.ndarray
    depth_bias: np.ndarray        # offset (m), scale, tilt_x, tilt_y, wiggle sin, cos (m), radial (m): core.depth_bias
    std: dict[str, float]         # stated: the noise's, raised to the views' jackknife spread where that is larger
    views: list[ViewReport]
    rejected: dict[int, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    corner_focal: Focal | None = None   # from the corners alone
    options: CalibrationOptions = field(default_factory=CalibrationOptions)   # as asked
    model: Model = field(default_factory=Model)   # as chosen: distortion, depth terms, plane squares, and why
    square: float = float("nan")   # m, the board's square size as given
    depth_square: float = float("nan")   # m, the square size the depth implies with the corners' focal length
    corner_noise: tuple[float, int] | None = None   # the corners-alone fit's pixel noise (px), its degrees of freedom
    noise_std: dict[str, float] = field(default_factory=dict)   # what the corners' and depth's noise alone give
    # fx, fy and what their noise gives them with the depth at its full weight: the focal length the
    # depth says, where it pulled the corners off their fit and the result leans on the corners
    depth_focal: Focal | None = None
    # (R, 12) the intrinsics refitted without each of R runs of consecutive views, the jackknife
    # behind the stated sigmas: how well each pixel's projection is known (core.projection_diff)
    run_intrinsics: np.ndarray | None = None
    # where the views left part of the image unreached and the projection there is much less known
    extrapolated: Extrapolated | None = None
    # the corners alone: their pixel RMS in the lens chosen and in a rational lens (px), where checked
    lens_rms: tuple[float, float] | None = None
    corner_lens: str = "plumb_bob"   # the lens the corners alone were fitted in (``corner_focal``)
    converged: bool = True   # whether the joint fit came to rest before its iteration cap (``bundle.Fit``)

    @property
    def depth_convention(self) -> str:
        return self.model.depth_convention

    @property
    def depth_offset(self) -> float:
        return float(self.depth_bias[0])

    @property
    def pixel_rms(self) -> float:
        return float(np.sqrt(np.mean(np.concatenate([v.pixel_residuals.ravel() for v in self.views]) ** 2) * 2))

    @property
    def depth_rms(self) -> float:
        d = np.concatenate([v.depth_residuals for v in self.views])
        d = d[np.isfinite(d)]
        return float(np.sqrt(np.mean(d ** 2))) if d.size else float("nan")

    @property
    def depth_gain(self) -> dict[str, float] | None:
        """How many times as certain fx and fy are with the depth as from the corners alone on the same
        views, as ROS camera_calibration fits them (plumb_bob), or in the lens the result has where it
        has more terms (``corner_lens``): what the depth helped. Each on its noise, as the refits that
        may widen the stated uncertainty are not run on the corners alone. None where the corners alone
        were not fitted (the traditional method)."""
        if self.corner_focal is None:
            return None
        _, _, sx, sy = self.corner_focal
        return {"fx": sx / self.noise_std["fx"], "fy": sy / self.noise_std["fy"]}

    @property
    def pixel_noise(self) -> tuple[float, int]:
        """The pixel noise per degree of freedom (px) and those degrees, with the lens model taken."""
        return lens_noise([v.pixel_residuals for v in self.views], self.model.distortion)

    @property
    def verdict(self) -> list[str]:
        """Reasons not to trust the calibration, a wrong square size or depth unit first: it explains
        the residuals and spreads listed after it. Empty when it passes every check."""
        reasons = []
        values = np.r_[self.K.ravel(), self.D, self.depth_bias]
        if not np.all(np.isfinite(values)):
            return ["the calibration has non-finite values"]
        misfit = self.lens_misfit
        if misfit:
            chosen, rational = self.lens_rms
            reasons.append(f"the lens bends more than {self.model.distortion} can follow: the corners fit a rational "
                           f"lens {chosen / rational:.1f} times closer ({rational:.3f} against {chosen:.3f} px RMS), "
                           "as a wide lens's do: calibrate with the distortion 'rational' (ROS's rational_polynomial)")
        if self.corner_focal is not None and self.depth_focal is not None and not misfit:
            for name, f, c, s, apart in focal_disagreements(self.depth_focal, self.corner_focal):
                reasons.append(f"the corners alone give {name}={c:.1f}±{s:.1f} px, the depth {f:.1f} px "
                               f"({f / c - 1:+.1%}, {abs(f - c) / apart:.0f} standard deviations): "
                               + self._squares_look(f / c))
        scale, s = float(self.depth_bias[1]), self.std.get("depth_scale", 0.0)
        if s > 0 and abs(scale) > max(MAX_CORNER_DEPTH_DISAGREEMENT, REFUSE_SIGMAS * s):
            reasons.append(f"the depth reads {scale:+.1%} (±{s:.1%}) off the distances the corners and squares "
                           "give: " + self._squares_look(1 + scale))
        if not self.converged:   # after the causes that can keep a fit moving
            reasons.append(NOT_CONVERGED)
        if self.pixel_rms > MAX_PIXEL_RMS:
            reasons.append(f"pixel RMS {self.pixel_rms:.2f} px exceeds {MAX_PIXEL_RMS} px")
        if np.isfinite(self.depth_rms) and self.depth_rms > MAX_DEPTH_RMS:
            reasons.append(f"depth RMS {self.depth_rms * 1e3:.1f} mm exceeds {MAX_DEPTH_RMS * 1e3:.0f} mm")
        for name, f in (("fx", self.K[0, 0]), ("fy", self.K[1, 1])):
            s = self.std.get(name, float("nan"))
            if not np.isfinite(s) or s > MAX_FOCAL_REL_STD * f:
                reasons.append(f"{name} is poorly constrained (std {s:.3g} px): "
                               + self._unsettled(name)
                               + "add views at other distances and tilts")
        for name, size in (("cx", self.image_size[0]), ("cy", self.image_size[1])):
            s = self.std.get(name, float("nan"))
            if not np.isfinite(s) or s > MAX_CENTER_REL_STD * size:
                reasons.append(f"{name} is poorly constrained (std {s:.3g} px): tilt the board more between views")
        if self.corner_noise is not None and self.method == "depth" and corners_pulled(self.pixel_noise,
                                                                                        self.corner_noise):
            (ours, _), (alone, _) = self.pixel_noise, self.corner_noise
            reasons.append(f"the corners fit worse with the depth than alone ({ours:.3f} against {alone:.3f} px a "
                           "degree of freedom): the lens model is too small for this lens, or the depth pulls the "
                           "camera off what the corners say (a depth error the model does not explain)")
        return reasons

    def _unsettled(self, name: str) -> str:
        """What the folds that chose the wiggle's period again say of ``name``'s uncertainty."""
        if name not in self.model.period_spread:
            return ""
        return FOLDS_SPREAD if self.model.settled_period else PERIOD_UNSETTLED

    @property
    def lens_misfit(self) -> bool:
        """Whether the corners alone fit a rational lens LENS_MISFIT times closer than the lens chosen."""
        return self.lens_rms is not None and self.lens_rms[0] >= LENS_MISFIT * self.lens_rms[1]

    def _squares_look(self, ratio: float) -> str:
        """What a square size ``ratio`` times the given one would mean, for a person to check."""
        size = self.depth_square if np.isfinite(self.depth_square) else self.square * ratio
        implied = f" (the depth says {size * 1e3:.1f} mm, not the {self.square * 1e3:.1f} mm given)" \
            if np.isfinite(size) else ""
        return (f"the squares look {'larger' if ratio > 1 else 'smaller'} than the size given{implied}, or the "
                "depth's units are off: is the square size right, and the depth's units?")

    @property
    def ok(self) -> bool:
        return not self.verdict

    def summary(self, n_views: int, seconds: float) -> str:
        """One line for a person: the intrinsics with their standard deviations, the distortion,
        the residuals, the views used of ``n_views`` given and the time taken. The node's
        answer, the CLI's output and the demo all print this."""
        s = self.std
        return (f"fx={self.K[0, 0]:.2f}±{s['fx']:.2f} fy={self.K[1, 1]:.2f}±{s['fy']:.2f} "
                f"cx={self.K[0, 2]:.2f}±{s['cx']:.2f} cy={self.K[1, 2]:.2f}±{s['cy']:.2f} px; "
                f"D=[{', '.join(f'{d:.4g}' for d in self.D)}]; pixel RMS {self.pixel_rms:.3f} px, "
                f"depth RMS {self.depth_rms * 1e3:.2f} mm, depth offset {self.depth_offset * 1e3:.1f} mm; "
                + ("" if self.depth_gain is None else f"{self.gain_brief()}; ")
                + f"{len(self.views)} of {n_views} views used; {seconds:.1f} s"
                + ("" if self.extrapolated is None else f"; {self.extrapolated.brief()}"))

    def gain_brief(self) -> str:
        """The depth's gain, for a person (with a depth_gain), and where the refits stated fx or fy
        beyond the corners alone's sigma on their noise, both: the gain is on the noise, and beside
        a sigma the refits widened (a pico flexx class sensor's folds: 3.8 on the noise, stated
        ±3.6 against the corners alone's ±2.9) it alone would read as the depth's help. The corners
        alone are not refitted, so this says what was stated, not which is the more certain."""
        g = self.depth_gain
        wider = [f"{name} ±{self.std[name]:.2f} px (the corners alone ±{alone:.2f})"
                 for name, alone in zip(("fx", "fy"), self.corner_focal[2:]) if self.std[name] > alone]
        return (f"the depth made fx {g['fx']:.3g} and fy {g['fy']:.3g} times as certain as the corners alone "
                f"({self.corner_lens}, on the noise of each)"
                + (f"; stated with the refits, {' and '.join(wider)}" if wider else ""))

    def to_dict(self) -> dict:
        """Everything the result holds, as plain JSON-ready types."""
        return {
            "method": self.method,
            "image_width": int(self.image_size[0]),
            "image_height": int(self.image_size[1]),
            "depth_convention": self.depth_convention,
            "options": self.options.to_dict(),
            "model": self.model.to_dict(),
            "camera_matrix": self.K.tolist(),
            "distortion_model": distortion_model(self.D),
            "distortion_coefficients": self.D.tolist(),
            "depth_bias": dict(zip(NAMES, map(float, self.depth_bias))),
            "std": dict(self.std),
            "std_from_noise": dict(self.noise_std),
            "pixel_rms": self.pixel_rms,
            "depth_rms_m": self.depth_rms,
            "verdict": {"ok": self.ok, "reasons": self.verdict},
            "notes": list(self.notes),
            "corner_only_focal": None if self.corner_focal is None else dict(zip(
                ("fx", "fy", "std_fx", "std_fy"), map(float, self.corner_focal))),
            "corner_only_lens": None if self.corner_focal is None else self.corner_lens,
            "depth_gain": self.depth_gain,
            "corner_only_pixel_noise": None if self.corner_noise is None else dict(zip(
                ("px", "dof"), self.corner_noise)),
            "depth_full_weight_focal": None if self.depth_focal is None else dict(zip(
                ("fx", "fy", "std_fx", "std_fy"), map(float, self.depth_focal))),
            "intrinsics_without_each_run": None if self.run_intrinsics is None else self.run_intrinsics.tolist(),
            "extrapolated": None if self.extrapolated is None else self.extrapolated._asdict(),
            "square_m": self.square,
            "square_from_depth_m": self.depth_square,
            "converged": self.converged,
            "lens_rms_px": None if self.lens_rms is None else dict(zip(("chosen", "rational"), self.lens_rms)),
            "rejected_views": {str(k): v for k, v in self.rejected.items()},
            "views": [{
                "index": v.index, "rvec": v.rvec.tolist(), "tvec": v.tvec.tolist(),
                "pixel_rms": v.pixel_rms, "depth_rms_m": v.depth_rms,
                "plane_sigma_m": v.plane_sigma, "plane_pixels": v.plane_pixels,
                "plane": None if v.plane is None else v.plane.tolist(),
                "saturation": None if np.isnan(v.saturation) else v.saturation,
                "pixel_residuals": v.pixel_residuals.tolist(),
                "depth_residuals_m": np.where(np.isfinite(v.depth_residuals), v.depth_residuals, None).tolist(),
            } for v in self.views],
        }
