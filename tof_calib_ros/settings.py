"""Every setting of the node and of ``tof_calib``, once: name, default, range, description, check.

The node declares its ROS parameters from these (``-p views.min:=12``) and ``tof_calib`` builds
its options from them (``--views-min 12``), so the two cannot drift apart: the same defaults,
the same ranges, the same refusals in the same words. The calibration options (the depth
model, distortion, loss, plane squares) are here too, so the node offers what the CLI does.
Shared by both front ends (``offline`` and ``ros``), so it sits below them: it may import
``core``, ``collect`` and ``files``, and no ROS.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from .collect.collector import CollectorConfig
from .core.board import MAX_CORNERS_PER_SIDE, MAX_SQUARE_M, MIN_CORNERS_PER_SIDE, MIN_SQUARE_M
from .core.errors import CalibrationError
from .core.options import CONVENTIONS, DISTORTION_TERMS, PLANE_SQUARES, CalibrationOptions
from .files.calibration_file import CAMERA_NAME

LOSSES = ("none", "huber", "cauchy")


def _depth_model(value: str) -> str | None:
    try:   # calibrate's own check of the terms; the frequency and convention are judged with it in ``refusal``
        CalibrationOptions(depth_convention="z", depth_bias=value, modulation_hz=20e6)
    except CalibrationError as exc:
        return str(exc)
    return None


def _modulation_hz(mhz: float) -> float | None:
    """calibrate's ``modulation_hz`` from the setting in MHz (0: not known)."""
    return mhz * 1e6 or None


def _camera_name(value: str) -> str | None:
    if CAMERA_NAME.fullmatch(value):
        return None
    return f"camera name {value!r} must be letters, digits and '_' (camera_info_manager refuses anything else)"


def _not_empty(value: str) -> str | None:
    return None if value.strip() else "must not be empty"


@dataclass(frozen=True)
class Setting:
    """One setting. ``flag``: ``tof_calib``'s option, None when only the node has it. ``low`` and
    ``high`` bound a number, ``choices`` a text; ``check`` returns why a value is refused."""

    name: str
    default: bool | int | float | str
    text: str
    flag: str | None = None
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] | None = None
    check: Callable[[Any], str | None] | None = None
    read_only: bool = False

    def refusal(self, value: Any) -> str | None:
        """Why ``value`` cannot be this setting's, or None."""
        kind = type(self.default)
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if type(value) is not kind:
            return f"{self.name} must be {kind.__name__}, got {value!r}"
        if self.low is not None and not (value >= self.low):
            return f"{self.name} must be at least {self.low:g}, got {value!r}"
        if self.high is not None and not (value <= self.high):
            return f"{self.name} must be at most {self.high:g}, got {value!r}"
        if self.choices is not None and value not in self.choices:
            return f"{self.name} must be one of {', '.join(map(repr, self.choices))}, got {value!r}"
        if self.check is not None:
            reason = self.check(value)
            if reason:
                return f"{self.name}: {reason}"
        return None


SETTINGS: dict[str, Setting] = {s.name: s for s in (
    Setting("board.cols", 5, "interior corners per row, as camera_calibration counts them",
            low=MIN_CORNERS_PER_SIDE, high=MAX_CORNERS_PER_SIDE, read_only=True),
    Setting("board.rows", 7, "interior corners per column", low=MIN_CORNERS_PER_SIDE, high=MAX_CORNERS_PER_SIDE,
            read_only=True),
    Setting("board.square", 0.03, "square size, metres", flag="--square", low=MIN_SQUARE_M, high=MAX_SQUARE_M,
            read_only=True),
    Setting("depth.convention", "auto", "depth along the optical axis ('z', REP 118, Kinect), from the optical "
            "centre ('radial', raw PMD), or 'auto': the one the board is flat in (z where both read alike)",
            flag="--depth-convention", choices=CONVENTIONS),
    Setting("depth.scale", 0.001, "metres per count of integer (16UC1) depth; 0.001: millimetres",
            flag="--depth-scale", low=1e-6, high=10.0),
    Setting("depth.bias", "auto", "the depth's systematic error terms estimated alongside: auto (the offset, "
            "and scale, tilt, wiggle and radial offset where the data call for them), none, or offset, scale, tilt, "
            "wiggle, radial joined by + (radial: z-depth only)",
            flag="--depth-bias", check=_depth_model),
    Setting("depth.modulation_mhz", 0.0, "the ToF camera's modulation frequency, MHz: given, the depth model always "
            "estimates a wiggling error of period c / (8 f) (1.87 m at 20 MHz); 0: not known, the data choose the "
            "period (8-130 MHz) where they show a wiggle",
            flag="--modulation-mhz", low=0.0, high=10000.0),
    Setting("calibration.distortion", "auto", "distortion terms: auto (those the data call for) or none, "
            "k1, k1k2, plumb_bob, full, rational (rational_polynomial, for wide lenses)", flag="--distortion",
            choices=("auto", *DISTORTION_TERMS)),
    Setting("calibration.loss", "none", "robust loss against misdetected corners: none, huber or cauchy",
            flag="--loss", choices=LOSSES),
    Setting("calibration.plane_squares", "auto", "the squares the depth planes are fitted to: auto (all unless "
            "the black ones read apart), white (the paper's) or all", flag="--plane-squares", choices=PLANE_SQUARES),
    Setting("calibration.timeout", 120.0, "seconds a calibration may take before its worker process is taken "
            "for stuck, killed and replaced", low=1.0, high=3600.0),
    Setting("sync.slop", 0.02, "largest stamp difference of a paired amplitude and depth frame, s", flag="--slop",
            low=0.0, high=1.0),
    Setting("views.min", 8, "views needed to calibrate", flag="--views-min", low=3, high=1000),
    Setting("views.max", 60, "views kept at most (memory stays bounded)", flag="--views-max", low=3, high=1000,
            read_only=True),
    Setting("motion.exposure", CollectorConfig.exposure_s, "how long a frame is exposed, all its phases, s: the "
            "board's speed between frames times this is its blur", flag="--exposure", low=1e-5, high=1.0,
            read_only=True),
    Setting("motion.max_blur_px", CollectorConfig.max_blur_px, "a frame whose board moved farther than this while "
            "it was exposed is not a view, px", flag="--max-blur", low=0.1, high=100.0, read_only=True),
    Setting("camera_name", "tof_camera", "camera_name written into calibration.yaml", flag="--camera-name",
            check=_camera_name),
    Setting("output_dir", "~/.ros/tof_calib", "where calibration.yaml, calibration.json and views/ go",
            check=_not_empty),
    Setting("set_camera_info_service", "set_camera_info", "the driver's sensor_msgs/SetCameraInfo service",
            read_only=True),
    Setting("qos.reliable", False, "subscribe reliably instead of best effort (sensor data)", read_only=True),
    Setting("bag.path", "", "a recording (rosbag2 folder, sqlite3 or mcap, or ROS 1 .bag) or a folder of "
            "NNNN_ir/NNNN_depth images to collect views from instead of the topics; calibrated once read",
            read_only=True),
    Setting("bag.amplitude_topic", "", "the bag's amplitude topic; empty: the Image topic named amplitude, ir, "
            "intensity...", flag="--amplitude-topic", read_only=True),
    Setting("bag.depth_topic", "", "the bag's depth topic; empty: the Image topic named depth", flag="--depth-topic",
            read_only=True),
)}


# Settings checked together: a change to one is judged with the other's value.
LINKED = (("views.min", "views.max"), ("depth.bias", "depth.modulation_mhz", "depth.convention"))


def refusal(values: Mapping[str, Any]) -> str | None:
    """Why these values (settings by name; others as they are) cannot stand together, or None."""
    for name, value in values.items():
        setting = SETTINGS.get(name)
        reason = f"no setting named {name!r}" if setting is None else setting.refusal(value)
        if reason:
            return reason
    bias, mhz = values.get("depth.bias"), values.get("depth.modulation_mhz")
    if bias is not None and mhz is not None:
        try:   # calibrate's own check of the two together
            CalibrationOptions(depth_convention="z", depth_bias=bias, modulation_hz=_modulation_hz(mhz))
        except CalibrationError as exc:
            return f"depth.bias {bias!r} with depth.modulation_mhz {mhz}: {exc}"
    convention = values.get("depth.convention")
    if bias is not None and convention is not None:
        try:
            CalibrationOptions(depth_convention=convention, depth_bias=bias,
                               modulation_hz=None if mhz is None else _modulation_hz(mhz))
        except CalibrationError as exc:
            return f"depth.bias {bias!r} with depth.convention {convention!r}: {exc}"
    lo, hi = values.get("views.min"), values.get("views.max")
    if lo is not None and hi is not None and lo > hi:
        return f"views.min ({lo}) must not exceed views.max ({hi}): calibration could never start"
    return None


def calibration_options(values: Mapping[str, Any]) -> dict[str, Any]:
    """``calibrate``'s keyword arguments from the settings."""
    loss = values["calibration.loss"]
    return {"depth_convention": values["depth.convention"], "depth_bias": values["depth.bias"],
            "distortion": values["calibration.distortion"], "loss": None if loss == "none" else loss,
            "plane_squares": values["calibration.plane_squares"],
            "modulation_hz": _modulation_hz(values["depth.modulation_mhz"])}


def collector_config(values: Mapping[str, Any], stills: bool = False) -> CollectorConfig:
    """The view collector's rules from the settings."""
    return CollectorConfig(max_views=values["views.max"], min_views=values["views.min"], stills=stills,
                           exposure_s=values["motion.exposure"], max_blur_px=values["motion.max_blur_px"])


def defaults() -> dict[str, Any]:
    return {name: s.default for name, s in SETTINGS.items()}
