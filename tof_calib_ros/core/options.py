"""How a calibration is to be done, checked once before any work, and what the data chose.

``CalibrationOptions`` holds what the caller asked for; a bad option fails here, before a view
is read. ``Model`` is what a depth-aided calibration settled on where the options left the
choice to the data ('auto'): the distortion terms, the depth error terms, the squares the depth
planes use, and the evidence for each choice. Both travel with the result, so that a report or
a cross-validation repeats the calibration exactly, as mrcal's ``optimization_inputs`` do.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

from . import depth_bias as bias_model
from .camera import DEPTH_CONVENTIONS
from .errors import CalibrationError

# The distortion presets, each the one before plus terms (indices into the intrinsics): the
# last, rational (ROS's rational_polynomial), for wide lenses no polynomial holds.
DISTORTION_TERMS = {"none": [], "k1": [4], "k1k2": [4, 5], "plumb_bob": [4, 5, 6, 7],
                    "full": [4, 5, 6, 7, 8], "rational": [4, 5, 6, 7, 8, 9, 10, 11]}


def lens_named(terms) -> str:
    """The lens whose distortion terms (intrinsics' indices) are ``terms``."""
    return next(name for name, own in DISTORTION_TERMS.items() if own == sorted(terms))


PLANE_SQUARES = ("auto", "white", "all")
CONVENTIONS = ("auto", *DEPTH_CONVENTIONS)
METHODS = ("depth", "traditional")
LOSSES = (None, "huber", "cauchy")


@dataclass(frozen=True)
class CalibrationOptions:
    """``depth_convention``: 'z' (along the optical axis, REP 118), 'radial' (the light's path) or
    'auto' (the one the boards are flat in; z where they read alike: core.depth_convention).
    ``depth_bias``: 'auto' (the offset, and scale, tilt and a radial offset where the data call
    for them), 'none', or terms from 'offset', 'scale', 'tilt', 'wiggle', 'radial' joined by '+'
    ('radial', an offset in the light's path, only for z-depth: in radial depth it is the offset).
    ``distortion``: 'auto' (the terms the data call for; with method 'traditional', plumb_bob,
    ROS camera_calibration's default) or a preset of ``DISTORTION_TERMS``. ``plane_squares``:
    'auto' (the whole board unless the black squares read apart from the white), 'white' (the
    paper's) or 'all'. ``loss``: None, 'huber' or 'cauchy'.
    ``modulation_hz``: the camera's modulation frequency, which sets the period of its wiggling
    error; given, 'auto' always estimates a wiggling term; not given, 'auto' looks for one over
    the periods ToF cameras have and takes it where the data call for it (see
    model_choice.select_model). A depth_bias naming 'wiggle' needs it."""

    method: str = "depth"
    depth_convention: str = "auto"
    depth_units: float | None = None
    depth_bias: str = "auto"
    distortion: str = "auto"
    loss: str | None = None
    plane_squares: str = "auto"
    min_views: int = 3
    modulation_hz: float | None = None

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise CalibrationError(f"method must be 'depth' or 'traditional', got {self.method!r}")
        if self.depth_convention not in CONVENTIONS:
            raise CalibrationError(f"depth_convention must be one of {', '.join(map(repr, CONVENTIONS))}, "
                                   f"got {self.depth_convention!r}")
        if self.modulation_hz is not None and not (isinstance(self.modulation_hz, (int, float))
                                                   and 1e5 <= self.modulation_hz <= 1e10):
            raise CalibrationError(f"modulation_hz must be a frequency from 100 kHz to 10 GHz or None, "
                                   f"got {self.modulation_hz!r}")
        if self.depth_bias != "auto":
            terms = bias_model.parse(self.depth_bias)
            if self.modulation_hz is None and set(bias_model.TERMS["wiggle"]) & set(terms):
                raise CalibrationError("the wiggle term needs the camera's modulation frequency "
                                       "(modulation_hz), which sets the wiggle's period")
            if self.depth_convention != "z" and set(bias_model.TERMS["radial"]) & set(terms):
                raise CalibrationError("the radial term is for z-depth (depth_convention 'z'): in radial depth an "
                                       "offset in the light's path is the depth offset ('offset')")
        if not isinstance(self.distortion, str) or self.distortion not in ("auto", *DISTORTION_TERMS):
            raise CalibrationError(f"distortion must be 'auto' or one of {sorted(DISTORTION_TERMS)}, "
                                   f"got {self.distortion!r}")
        if self.loss not in LOSSES:
            raise CalibrationError(f"loss must be None, 'huber' or 'cauchy', got {self.loss!r}")
        if self.plane_squares not in PLANE_SQUARES:
            raise CalibrationError(f"plane_squares must be one of {', '.join(map(repr, PLANE_SQUARES))}, "
                                   f"got {self.plane_squares!r}")

    def fixed(self, model: Model) -> CalibrationOptions:
        """These options with every 'auto' replaced by what ``model`` chose: the same
        calibration on other views (halves, held-out views) without choosing again."""
        hz = self.modulation_hz if model.wiggle_period is None else bias_model.modulation_hz(model.wiggle_period)
        return CalibrationOptions(self.method, model.depth_convention, self.depth_units, model.depth_bias,
                                  model.distortion, self.loss, model.plane_squares, self.min_views, hz)

    @property
    def wiggle_period(self) -> float | None:
        """The wiggling error's period (m), where the modulation frequency is given."""
        return None if self.modulation_hz is None else bias_model.wiggle_period(self.modulation_hz)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class Model:
    """What the calibration settled on, and why. ``evidence``: for each term tested, its
    likelihood-ratio statistic (the larger of the score test and the refit's drop in deviance)
    against the information criterion's price for its parameters; a term is taken when the
    statistic exceeds the price.
    ``dropped_corners``: board indices, per view, of corners a robust loss removed.
    ``depth_inflation``: how many times its noise the depth's error was taken to be, where the
    depth at its full weight pulled the corners off their fit (1: its noise).
    ``wiggle_period``: the period (m) of the depth model's wiggle, where it has one: from the
    modulation frequency given, or the one the data chose. ``fold_periods``: where the data chose
    it, the period (m, None for no wiggle) that calibrations without each fold of the views chose
    again; ``period_spread``: fx's and fy's spread (px) over those calibrations, where it raised
    their uncertainty (the re-runs' spread as a whole: the folds need not choose other periods,
    ``settled_period`` says whether they did).
    ``depth_convention``: the depth's, as given or as the boards' flatness chose
    (core.depth_convention)."""

    distortion: str = "none"
    depth_bias: str = "none"
    plane_squares: str = "white"
    evidence: dict[str, dict[str, float]] = field(default_factory=dict)
    reasons: list[str] = field(default_factory=list)
    dropped_corners: dict[int, list[int]] = field(default_factory=dict)
    depth_inflation: float = 1.0
    wiggle_period: float | None = None
    fold_periods: list[float | None] = field(default_factory=list)
    period_spread: dict[str, float] = field(default_factory=dict)
    depth_convention: str = "z"

    @property
    def settled_period(self) -> bool:
        """Whether every fold of the views chose the period the whole of them did."""
        return all(p == self.wiggle_period for p in self.fold_periods)

    def to_dict(self) -> dict:
        out = asdict(self)
        out["dropped_corners"] = {str(k): v for k, v in self.dropped_corners.items()}
        return out
