"""Judging an existing calibration on new views, as camera_calibration's cameracheck does, and
with the depth a ToF camera adds.

Per view: the board's pose is found from its corners with the calibration's K and D (PnP);
then the re-projection RMS says how well K and D explain the corners, the depth residuals
(denoised depth at the corners minus the depth the pose predicts, after the calibration's own
depth model) say whether the scale is right, and the plane noise says how flat the board is in
the calibration's geometry. A focal length 2 % off puts every pose 2 % too near or too far,
which the pixels alone cannot see: the depth residuals then grow with the distance, and the
check judges that slope as well as their spread. The limits are the calibration's own.
"""
from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ..core import depth_bias as bias_model
from ..core.board import Board
from ..core.camera import MODEL_TERMS, N_DISTORTION, depth_of, pack_intrinsics, transform
from ..core.errors import CalibrationError
from ..core.inputs import View
from ..core.planarize import planarize
from ..core.result import MAX_DEPTH_RMS, MAX_FOCAL_REL_STD, MAX_PIXEL_RMS
from ..files.calibration_file import CalibrationFileError, CameraYaml, read_camera_yaml

# Depth residuals growing by more than this fraction of the distance fail the check: the focal
# length would be off by as much (the calibration's own limit on its focal length's uncertainty).
MAX_DEPTH_SCALE = MAX_FOCAL_REL_STD
# The slope is judged only when the views' depths span at least this fraction of their mean.
MIN_DEPTH_SPREAD = 0.2


@dataclass
class Calibration:
    """A calibration to check: K, D and image size from the YAML; the depth model and
    convention from the calibration.json beside it, when there is one."""

    K: np.ndarray
    D: np.ndarray
    image_size: tuple[int, int]
    depth_bias: np.ndarray
    depth_convention: str | None
    source: str
    wiggle_period: float | None = None

    @property
    def has_depth_model(self) -> bool:
        return self.depth_convention is not None


def _refuse_unreadable_model(cam: CameraYaml, where: str) -> None:
    """The check projects with plumb_bob or rational_polynomial and a K without skew; a file it
    would read otherwise (another model, a K that is not a camera matrix) is refused, not
    half-read into a verdict."""
    K = cam.K
    problems = []
    terms = MODEL_TERMS.get(cam.distortion_model or "plumb_bob")
    if terms is None:
        problems.append(f"distortion model {cam.distortion_model!r} (the check reads plumb_bob and "
                        "rational_polynomial only)")
    elif cam.D.size > terms:
        problems.append(f"{cam.D.size} distortion terms ({cam.distortion_model or 'plumb_bob'} has {terms})")
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        problems.append(f"focal lengths fx={K[0, 0]:g}, fy={K[1, 1]:g} (must be positive)")
    if K[0, 1] != 0:
        problems.append(f"skew K[0][1]={K[0, 1]:g} (the camera model has none)")
    if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        problems.append(f"camera_matrix last rows {K[1].tolist()} {K[2].tolist()} (must be [0, fy, cy] [0, 0, 1])")
    if problems:
        raise CalibrationFileError(f"{where}: cannot be checked as it is: " + "; ".join(problems))


def load_calibration(yaml_path: str | Path) -> Calibration:
    """Read a camera YAML and, when present, the depth model of calibration.json beside it."""
    yaml_path = Path(yaml_path)
    cam = read_camera_yaml(yaml_path)
    _refuse_unreadable_model(cam, str(yaml_path))
    D = np.zeros(N_DISTORTION)
    D[:cam.D.size] = cam.D
    bias, convention, period, source = np.zeros(bias_model.N_BIAS), None, None, str(yaml_path)
    sidecar = yaml_path.with_suffix(".json")
    if sidecar.is_file():
        try:
            doc = json.loads(sidecar.read_text())
            # the terms added later (the wiggle's, the radial offset) are absent from older files
            bias = np.array([float(doc["depth_bias"].get(name, 0.0) if name in bias_model.TERMS_ADDED_LATER
                                   else doc["depth_bias"][name]) for name in bias_model.NAMES])
            convention = doc["depth_convention"]
            # the period chosen; files written before the data could choose it have the frequency given
            period, hz = doc.get("model", {}).get("wiggle_period"), doc.get("options", {}).get("modulation_hz")
            if period is None and hz is not None:
                period = bias_model.wiggle_period(float(hz))
            period = None if period is None else float(period)
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise CalibrationFileError(f"{sidecar}: not a calibration.json with depth_bias and "
                                       f"depth_convention ({exc})") from None
        source += f" with {sidecar.name}"
    return Calibration(cam.K, D, (cam.width, cam.height), bias, convention, source, period)


@dataclass
class ViewCheck:
    index: int
    pixel_rms: float        # px
    depth_mean: float       # m, measured - predicted, mean over the corners
    depth_rms: float        # m
    plane_sigma: float      # m, the white squares' depth noise about their plane
    note: str = ""


@dataclass
class CheckResult:
    """Residuals of every view; ``depths`` are the predicted depths of ``depth_residuals``' corners.
    Without a depth model (a YAML alone) the camera's depth offset is unknown: it is fitted here."""

    views: list[ViewCheck]
    pixel_residuals: np.ndarray = field(repr=False)   # (N, 2), all views
    depth_residuals: np.ndarray = field(repr=False)   # (M,) m, all views with depth
    depths: np.ndarray = field(repr=False)            # (M,) m
    has_depth_model: bool = True

    @property
    def pixel_rms(self) -> float:
        return float(np.sqrt(np.mean(np.sum(self.pixel_residuals ** 2, axis=1))))

    @property
    def depth_mean(self) -> float:
        return float(np.mean(self.depth_residuals)) if self.depth_residuals.size else float("nan")

    @property
    def depth_rms(self) -> float:
        """RMS of the depth residuals; about their mean when the calibration has no depth model."""
        d = self.depth_residuals
        if not d.size:
            return float("nan")
        return float(np.sqrt(np.mean((d if self.has_depth_model else d - d.mean()) ** 2)))

    @property
    def depth_scale(self) -> float:
        """How the depth residuals grow with distance (slope, m/m), or NaN when the views are all
        at about one distance. A focal length off by a fraction e puts every pose e too near or far:
        a slope of about -e."""
        d, r = self.depths, self.depth_residuals
        if d.size < 3 or np.ptp(d) < MIN_DEPTH_SPREAD * np.mean(d):
            return float("nan")
        return float(np.polyfit(d, r, 1)[0])

    @property
    def verdict(self) -> list[str]:
        """Reasons the calibration does not fit these views; empty when it does."""
        reasons = []
        if not self.pixel_rms <= MAX_PIXEL_RMS:
            reasons.append(f"re-projection RMS {self.pixel_rms:.2f} px exceeds {MAX_PIXEL_RMS} px")
        if not self.depth_residuals.size:
            reasons.append("no view has usable depth on the board: the depth cannot be checked")
            return reasons
        if not self.depth_rms <= MAX_DEPTH_RMS:
            reasons.append(f"depth residual RMS {self.depth_rms * 1e3:.1f} mm exceeds {MAX_DEPTH_RMS * 1e3:.0f} mm")
        if abs(self.depth_scale) > MAX_DEPTH_SCALE:
            reasons.append(f"the depth residuals grow by {self.depth_scale:+.1%} of the distance (limit "
                           f"{MAX_DEPTH_SCALE:.0%}): the focal length is off by about {-self.depth_scale:+.1%}")
        return reasons

    @property
    def ok(self) -> bool:
        return not self.verdict

    def to_dict(self) -> dict:
        return {"pixel_rms": self.pixel_rms, "depth_rms_m": self.depth_rms, "depth_mean_m": self.depth_mean,
                "depth_scale": self.depth_scale, "depth_model": self.has_depth_model,
                "verdict": {"ok": self.ok, "reasons": self.verdict},
                "views": [vars(v) for v in self.views]}


def check_views(views: Sequence[View], board: Board, calibration: Calibration, convention: str) -> CheckResult:
    """Judge ``calibration`` on views with corners (as the collector keeps them)."""
    if not views:
        raise CalibrationError("no views to check the calibration on")
    h, w = np.asarray(views[0].depth).shape
    if (w, h) != calibration.image_size:
        raise CalibrationError(f"the calibration is for {calibration.image_size[0]}x{calibration.image_size[1]} "
                               f"images, the views are {w}x{h}")
    K, D = calibration.K, calibration.D
    params = pack_intrinsics(K, D)
    obj = board.object_points()
    checks, pixels, residuals, depths = [], [], [], []
    for i, view in enumerate(views):
        corners = np.asarray(view.corners, dtype=float)
        ok, rvec, tvec = cv2.solvePnP(obj, corners, K, D, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            checks.append(ViewCheck(i, float("nan"), float("nan"), float("nan"), float("nan"), "no pose found"))
            continue
        residual = cv2.projectPoints(obj, rvec, tvec, K, D)[0].reshape(-1, 2) - corners
        pixels.append(residual)
        pixel_rms = float(np.sqrt(np.mean(np.sum(residual ** 2, axis=1))))
        X, _ = transform(rvec.ravel(), tvec.ravel(), obj)
        predicted = bias_model.measured(calibration.depth_bias, depth_of(X, convention)[0], X,
                                        calibration.wiggle_period)
        try:
            measured, plane = planarize(np.asarray(view.depth, dtype=float), corners, np.arange(board.n_corners),
                                        board, params, convention, view.amplitude)
        except CalibrationError as exc:
            checks.append(ViewCheck(i, pixel_rms, float("nan"), float("nan"), float("nan"), str(exc)))
            continue
        d = measured - predicted
        residuals.append(d)
        depths.append(predicted)
        checks.append(ViewCheck(i, pixel_rms, float(d.mean()), float(np.sqrt(np.mean(d ** 2))), plane.sigma))
    return CheckResult(checks, np.concatenate(pixels or [np.zeros((0, 2))]), np.concatenate(residuals or [[]]),
                       np.concatenate(depths or [[]]), calibration.has_depth_model)
