"""Choosing calibration views from a live or replayed ToF stream, or from a folder of stills.

As in ROS camera_calibration (image_pipeline), each frame with a whole board is described by a
vector of normalised parameters; the progress per parameter tells the user what is still
missing. Besides camera_calibration's X, Y, size and skew, two ToF axes count: the board's
distance, because a depth offset and the focal length can only be told apart from boards at
several distances, and its tilt, measured in the depth rather than guessed from the outline.

Rules (``CollectorConfig`` holds the numbers):

- near-duplicates: a view is kept unless it is within ``min_distance`` (L1 over the six axes,
  each in 0..1) of a kept view: a board held still gives one view, a board that moves gives one
  per frame, and every still of a folder is used;
- sharpness, judged physically at any frame rate (``motion``): the board's speed since the
  previous frame (px/s, when that frame is at most ``max_gap_s`` earlier) times the exposure
  ``exposure_s`` is the blur it had; the frame itself shows blur as edges wider across the motion
  than along it or than the sensor's sharp edges, and a multi-phase ToF camera's motion artefacts
  as depth on the squares' edges far off the board's plane. A frame blurred by more than
  ``max_blur_px`` by any of these is refused; a still (a folder of images) has no speed, so only
  the frame's own evidence judges it (``stills=True``);
- when ``max_views`` are kept, a new view replaces the most redundant kept one (the one nearest
  to another), if it is farther from the rest than that one, and only where no axis' end is
  lost: the set stays spread over the recording, and progress only ever rises;
- a frame is judged by its quick corners; a kept view's accurate corners (``accurate_detect``,
  tens of ms where a frame is judged in one) are found later (``sharpen``), where they hold up
  no frame: in another thread or process, or when the views are read. A view swapped out before
  then never costs them, and one whose accurate corners fail is dropped.
"""
from __future__ import annotations

import itertools
import math
from collections import deque
from dataclasses import dataclass, replace

import cv2
import numpy as np

from ..core.board import Board
from ..core.detection import Detection, clipped, saturation
from ..core.errors import CalibrationError
from ..core.inputs import View, depth_in_metres, depth_units
from ..core.planarize import sample_depth, svd_plane
from .motion import edge_blur_px, edge_depth_error
from .tracking import accurate_detect, quick_locate

AXES = ("x", "y", "size", "skew", "depth", "tilt")
# Small values are no achievement on these axes (camera_calibration: size and skew), so their
# range starts at 0 and only their largest value counts.
_FROM_ZERO = {"size", "skew", "tilt"}
# Each axis as a person reads it, in the board picture and the messages ("depth" is the board's
# distance, not the depth image).
LABELS = {"x": "X", "y": "Y", "size": "Size", "skew": "Skew", "depth": "Distance", "tilt": "Tilt"}
# What the person holding the board does to cover each axis further: camera_calibration's bars
# say how far each is, not how to fill it.
WHAT_TO_DO = {
    "x": "move the board across the image, left to right",
    "y": "move it from the image's top to its bottom",
    "size": "bring it nearer, or take a larger board where the depth fails that near",
    "skew": "tilt it about a diagonal, so its corners are not square in the image",
    "depth": "hold it at more distances, near and far",
    "tilt": "tilt it further towards or away from the camera",
}
# The outline checked against the image border lies this many squares beyond the outer corners:
# a corner is located from the squares around it, so those must be in the image too.
EDGE_SQUARES = 0.5
# The quick corners are pixel-accurate; farther from the accurate ones, one of them is wrong.
QUICK_AGREEMENT_PX = 1.5
# The sensor's sharp edges (optics and pixels blur them too) are as wide as the low quantile of
# the narrower direction's edge widths over the last SHARP_HISTORY boards; the motion blur is
# what the wider direction has beyond that (widths add in quadrature).
SHARP_QUANTILE = 0.2
SHARP_HISTORY = 50
# Motion artefacts: the depth on the squares' edges this many times farther from the board's
# plane than the squares' centres are, and at least this far (m), comes from a board that moved.
ARTEFACT_RATIO = 30.0
ARTEFACT_MIN_M = 0.1
# A full set swaps a view only for one this many times farther from the rest: each swap costs an
# accurate detection, and swaps for a marginal gain would churn on every frame of a long recording.
SWAP_GAIN = 1.5
# Views that are enough however the axes stand (camera_calibration's 40): a small board on a
# wide-angle ToF camera cannot fill the Size axis before the camera's depth fails, near.
ENOUGH_VIEWS = 40


def _real(value: object) -> bool:
    """A number that means one (inf may mean "no limit"; NaN, a bool or a string mean nothing)."""
    return (isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
            and not (isinstance(value, (float, np.floating)) and math.isnan(value)))


@dataclass(frozen=True)
class CollectorConfig:
    """``spans``: per axis of ``AXES``, the range of kept views that counts as full progress
    (camera_calibration's 0.7, 0.7, 0.4, 0.5, then depth and tilt). The distance axis is
    log(distance / near) / log(far / near) over ``depth_range``: its span of 0.25 of the 0.3-3 m
    range asks for boards at two distances 1.8:1 apart, near or far (the simulated camera's 14
    views at 0.5 to 0.85 m give its 20 mm depth offset to 0.1 mm and fx to 0.03 %). ``stills``:
    every frame is a still (no stream to measure the board's speed in), so only the frame's own
    evidence of motion counts.
    ``exposure_s``: how long a frame is exposed (all phases of a multi-phase ToF
    frame), and ``max_blur_px`` how far the board may move in that time (camera_calibration's
    ``max_chessboard_speed``, in physical units: 5 ms and 1.5 px allow 300 px/s). The default
    exposure is the short end of ToF cameras' (5 to 30 ms for all phases): on a camera that
    exposes longer, the speed check underestimates the blur and so never refuses a sharp frame,
    and the frame's own edges show the blur it misses."""

    min_distance: float = 0.02
    max_views: int = 100
    min_views: int = 10
    exposure_s: float = 0.005
    max_blur_px: float = 1.5
    max_gap_s: float = 1.0
    border_px: float = 2.0
    min_depth_fraction: float = 0.5
    depth_range: tuple[float, float] = (0.3, 3.0)
    max_tilt_deg: float = 60.0
    spans: tuple[float, ...] = (0.7, 0.7, 0.4, 0.5, 0.25, 0.5)
    stills: bool = False

    def __post_init__(self) -> None:
        reals = {name: getattr(self, name) for name in
                 ("min_distance", "exposure_s", "max_blur_px", "max_gap_s", "border_px", "min_depth_fraction",
                  "max_tilt_deg")}
        for name, value in reals.items():
            if not _real(value):
                raise CalibrationError(f"{name} must be a number, got {value!r}")
        for name in ("max_views", "min_views"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool):
                raise CalibrationError(f"{name} must be an integer, got {value!r}")
        if not (isinstance(self.depth_range, (tuple, list)) and len(self.depth_range) == 2
                and all(map(_real, self.depth_range))):
            raise CalibrationError(f"depth_range must be (near, far) metres, got {self.depth_range!r}")
        if not (isinstance(self.spans, (tuple, list)) and all(map(_real, self.spans))):
            raise CalibrationError(f"spans must be {len(AXES)} numbers (one per axis {AXES}), got {self.spans!r}")
        lo, hi = self.depth_range
        checks = [
            (self.min_distance >= 0, f"min_distance must be >= 0, got {self.min_distance}"),
            (self.max_views >= 1, f"max_views must be >= 1, got {self.max_views}"),
            (self.min_views >= 1, f"min_views must be >= 1, got {self.min_views}"),
            (self.min_views <= self.max_views, f"min_views ({self.min_views}) must not exceed max_views "
             f"({self.max_views}): the views could never be enough"),
            (self.exposure_s > 0, f"exposure_s must be positive, got {self.exposure_s}"),
            (self.max_blur_px > 0, f"max_blur_px must be positive, got {self.max_blur_px}"),
            (self.max_gap_s > 0, f"max_gap_s must be positive, got {self.max_gap_s}"),
            (self.border_px >= 0, f"border_px must be >= 0, got {self.border_px}"),
            (0 < self.min_depth_fraction <= 1,
             f"min_depth_fraction must be in (0, 1], got {self.min_depth_fraction}"),
            (0 < lo < hi < math.inf,
             f"depth_range must be (near, far) metres with 0 < near < far < inf, got {self.depth_range}"),
            (0 < self.max_tilt_deg <= 90, f"max_tilt_deg must be in (0, 90], got {self.max_tilt_deg}"),
            (len(self.spans) == len(AXES) and all(s > 0 for s in self.spans),
             f"spans must be {len(AXES)} positive numbers (one per axis {AXES}), got {self.spans}"),
        ]
        for ok, message in checks:
            if not ok:
                raise CalibrationError(message)


@dataclass(frozen=True)
class Outcome:
    """What became of one frame. ``params`` (one value per ``AXES``) once the board passed every
    check up to novelty; ``corners`` whenever a board was found, for drawing it."""

    accepted: bool
    reason: str
    params: np.ndarray | None = None
    corners: np.ndarray | None = None


class ViewCollector:
    """Keeps the frames worth calibrating from, copied, and nothing of the rest of the stream.

    Not thread safe: feed it from one thread, or under one lock.
    """

    def __init__(self, board: Board, config: CollectorConfig | None = None) -> None:
        self.board = board
        self.config = CollectorConfig() if config is None else config
        self._key = itertools.count()   # names a kept view for ``sharpen``, across resets
        self.reset()

    def reset(self) -> None:
        """Forget every view and the stream so far, as at start-up."""
        self._views: list[View] = []
        self._params: list[np.ndarray] = []
        self._stamps: list[float] = []
        self._keys: list[int] = []
        self._quick: dict[int, np.ndarray] = {}   # key -> quick corners, of the views still to sharpen
        self.dropped: list[str] = []               # why views were dropped when sharpened
        self._size: tuple[int, int] | None = None
        self._previous: tuple[float, np.ndarray] | None = None  # stamp and corners of the last frame
        self._sharp: deque[float] = deque(maxlen=SHARP_HISTORY)  # narrower edge widths of recent boards
        self._frames = 0
        self._last_reason = "no frame yet"

    def __len__(self) -> int:
        """Views kept, those still to sharpen included."""
        return len(self._views)

    @property
    def views(self) -> list[View]:
        """The kept views, oldest first, ready for ``calibrate``: those still without their
        accurate corners are sharpened first, here."""
        self.sharpen()
        return list(self._views)

    def unsharpened(self) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """(key, amplitude, quick corners) of the kept views still without accurate corners,
        oldest first, for a caller that finds them elsewhere and hands them to ``sharpen``."""
        return [(k, v.amplitude, self._quick[k]) for k, v in zip(self._keys, self._views) if k in self._quick]

    def sharpen(self, found: dict[int, Detection] | None = None) -> list[str]:
        """Give kept views their accurate corners: ``found``'s, by ``unsharpened``'s key (keys of
        views no longer kept are ignored), or, with None, every view's still to find, found here.
        A view whose accurate corners are lost or stray from its quick ones is dropped; why, for
        each, is returned and added to ``dropped``."""
        if found is None:
            found = {k: accurate_detect(a, self.board, q)
                     for k, a, q in self.unsharpened()}
        reasons = []
        for key, accurate in found.items():
            if key not in self._quick:
                continue
            i = self._keys.index(key)
            problem = _disagreement(self._quick.pop(key), accurate)
            if problem is None:
                self._views[i] = replace(self._views[i], corners=accurate.corners.copy())
            else:
                reasons.append(f"the view taken at {self._stamps[i]:.3f} s dropped: {problem}")
                self._remove(i)
        self.dropped += reasons
        return reasons

    @property
    def stamps(self) -> list[float]:
        """The time of each kept view, as given to ``add``."""
        return list(self._stamps)

    def add(self, amplitude: np.ndarray, depth_m: np.ndarray, stamp: float,
            located: Detection | None = None, detected: Detection | None = None) -> Outcome:
        """Judge one frame: amplitude image, depth (float metres with NaN or 0 invalid; integer
        images are millimetres, as ``calibrate`` reads them) and its time in seconds.

        ``located`` and ``detected``: the frame's ``quick_locate`` and ``detect`` results when the
        caller ran them already (offline tools run them in worker processes, frames in parallel;
        the judgment stays sequential)."""
        amplitude = np.asarray(amplitude)
        depth_m = np.asarray(depth_m)
        if amplitude.ndim != 2 or amplitude.shape != depth_m.shape:
            raise CalibrationError(f"amplitude {amplitude.shape} and depth {depth_m.shape} must be "
                                   "single-channel images of the same size")
        self._frames += 1
        found = quick_locate(amplitude, self.board) if located is None else located
        outcome = self._judge(amplitude, depth_m, float(stamp), found, detected)
        self._last_reason = outcome.reason
        # The caller gets its own arrays: changing them must not change the kept state.
        return replace(outcome, params=None if outcome.params is None else outcome.params.copy(),
                       corners=None if outcome.corners is None else outcome.corners.copy())

    def progress(self) -> dict:
        """Per axis the covered range [lo, hi] of kept views and its progress 0..1 towards the
        axis' span; frame and view counts; the last frame's reason; whether to calibrate now:
        every axis full, or ``ENOUGH_VIEWS`` views (a full set, if smaller) as in camera_calibration."""
        cfg = self.config
        params = np.array(self._params).reshape(-1, len(AXES))
        axes = {}
        for i, name in enumerate(AXES):
            lo, hi = (float(params[:, i].min()), float(params[:, i].max())) if len(params) else (0.0, 0.0)
            if name in _FROM_ZERO:
                lo = 0.0
            axes[name] = {"lo": lo, "hi": hi, "progress": min((hi - lo) / cfg.spans[i], 1.0)}
        full = all(a["progress"] >= 1.0 for a in axes.values())
        good = len(params) >= cfg.min_views and (full or len(params) >= min(ENOUGH_VIEWS, cfg.max_views))
        return {"axes": axes, "frames": self._frames, "views": len(params),
                "last_reason": self._last_reason, "good_enough": good}

    def _judge(self, amplitude: np.ndarray, depth_m: np.ndarray, stamp: float, found: Detection,
               detected: Detection | None) -> Outcome:
        cfg = self.config
        h, w = depth_m.shape
        if self._size is not None and (w, h) != self._size:
            return Outcome(False, f"image is {w}x{h} but the kept views are {self._size[0]}x{self._size[1]}; "
                                  "reset the collector to start over at the new size")
        previous, self._previous = self._previous, None
        if found.corners is None:
            return Outcome(False, found.message)
        corners = found.corners
        self._previous = (stamp, corners)

        outline = self._outline(corners)
        if outline is None:
            return Outcome(False, "partial board: its corners do not form a plane grid", corners=corners)
        partial = self._off_image(outline, w, h)
        if partial:
            return Outcome(False, partial, corners=corners)
        # Only the corners' depth, not the image's: most frames are judged and let go.
        z = depth_in_metres(sample_depth(depth_m, corners), depth_units(depth_m))
        valid = int(np.isfinite(z).sum())
        if valid < cfg.min_depth_fraction * len(z):
            return Outcome(False, f"no valid depth on the board: {valid} of {len(z)} corners have depth "
                                  f"(need {cfg.min_depth_fraction:.0%})", corners=corners)
        params = self._parameters(corners, outline, z, w, h)
        kept = np.array(self._params).reshape(-1, len(AXES))
        if len(kept):
            nearest = float(np.abs(kept - params).sum(axis=1).min())
            if nearest < cfg.min_distance:
                return Outcome(False, f"too similar to a kept view (distance {nearest:.3f} < "
                                      f"{cfg.min_distance:g}): move, turn or tilt the board", params, corners)
        replaced = None
        if len(self._views) >= cfg.max_views:
            replaced = self._redundant(params)
            if replaced is None:
                return Outcome(False, f"view limit reached ({cfg.max_views} views kept, none as redundant as this "
                                      "one would be)", params, corners)
        moving = self._motion(previous, stamp, corners, amplitude, depth_m)
        if moving:
            return Outcome(False, moving, params, corners)
        # Worth keeping. Accurate corners found already (a still's, by a worker) must agree with
        # the quick ones; otherwise they are found later (``sharpen``).
        if detected is not None:
            problem = _disagreement(corners, detected)
            if problem is not None:
                return Outcome(False, problem, params, corners)
            corners = detected.corners
        if replaced is not None:
            self._remove(replaced)
        key = next(self._key)
        if detected is None:
            self._quick[key] = corners
        self._keys.append(key)
        self._views.append(View(depth=depth_in_metres(depth_m).astype(np.float32), corners=corners.copy(),
                                amplitude=amplitude.copy()))
        self._params.append(params)
        self._stamps.append(stamp)
        self._size = (w, h)
        clip = clipped(saturation(amplitude, corners))
        said = "" if clip is None else f"; {clip}"
        if replaced is not None:
            return Outcome(True, f"accepted in place of a more redundant view ({cfg.max_views} views kept){said}",
                           params, corners)
        return Outcome(True, f"accepted as view {len(self._views)}{said}", params, corners)

    def _remove(self, i: int) -> None:
        del self._views[i], self._params[i], self._stamps[i]
        self._quick.pop(self._keys.pop(i), None)

    def _redundant(self, params: np.ndarray) -> int | None:
        """The kept view a new one at ``params`` should replace once the set is full: the one
        nearest to another kept view, if the new view is ``SWAP_GAIN`` times farther than that
        from all the rest and that view holds no axis' lowest or highest value (progress must
        never fall)."""
        kept = np.array(self._params)
        d = np.abs(kept[:, None, :] - kept[None, :, :]).sum(axis=2)
        np.fill_diagonal(d, np.inf)
        ends = set(np.argmin(kept, axis=0)) | set(np.argmax(kept, axis=0))
        i = next((int(i) for i in np.argsort(d.min(axis=1)) if int(i) not in ends), None)
        if i is None:
            return None
        others = np.delete(kept, i, axis=0)
        return i if np.abs(others - params).sum(axis=1).min() > SWAP_GAIN * d[i].min() else None

    def _outline(self, corners: np.ndarray) -> np.ndarray | None:
        """The image of the board's outline ``EDGE_SQUARES`` beyond its outer corners (4x2
        pixels), or None when the corners form no plane grid."""
        b = self.board
        margin = EDGE_SQUARES * b.square
        far_x, far_y = (b.cols - 1) * b.square + margin, (b.rows - 1) * b.square + margin
        outline = np.array([[-margin, -margin], [far_x, -margin], [far_x, far_y], [-margin, far_y]])
        H, _ = cv2.findHomography(b.object_points()[:, :2], corners, 0)
        return None if H is None else cv2.perspectiveTransform(outline[None], H)[0]

    def _off_image(self, outline: np.ndarray, w: int, h: int) -> str | None:
        """Why the board is not wholly in the image with room to spare, or None when it is."""
        m = self.config.border_px
        if np.all((outline >= m) & (outline <= np.array([w - 1 - m, h - 1 - m]))):
            return None
        return (f"partial board: its outer squares come within {m:g} px of the image border, "
                "where corners are unreliable")

    def _motion(self, previous: tuple[float, np.ndarray] | None, stamp: float, corners: np.ndarray,
                amplitude: np.ndarray, depth_m: np.ndarray) -> str | None:
        """Why the board moved too much while the frame was taken, or None when it is sharp."""
        cfg = self.config
        if not cfg.stills and previous is not None and 0 < stamp - previous[0] <= cfg.max_gap_s:
            speed = float(np.max(np.linalg.norm(corners - previous[1], axis=1))) / (stamp - previous[0])
            if speed * cfg.exposure_s > cfg.max_blur_px:
                return (f"board moving: {speed:.0f} px/s blurs it by {speed * cfg.exposure_s:.1f} px in a "
                        f"{cfg.exposure_s * 1e3:g} ms exposure (limit {cfg.max_blur_px:g} px)")
        across, along = edge_blur_px(amplitude, corners, self.board)
        if np.isfinite(along):
            self._sharp.append(along)
        sharp = float(np.quantile(self._sharp, SHARP_QUANTILE)) if self._sharp else along
        blur = math.sqrt(max(across ** 2 - sharp ** 2, 0.0)) if np.isfinite(across) else 0.0
        if blur > cfg.max_blur_px:
            return (f"motion blur: the board's edges are {across:.1f} px wide across the motion where sharp ones "
                    f"are {sharp:.1f} px, a blur of {blur:.1f} px (limit {cfg.max_blur_px:g} px)")
        edges, centres = edge_depth_error(depth_m, corners, self.board)
        if edges > max(ARTEFACT_RATIO * centres, ARTEFACT_MIN_M):
            return (f"motion artefacts in the depth: the squares' edges lie {edges * 1e3:.0f} mm off the board's "
                    f"plane, its squares {centres * 1e3:.1f} mm (a board moving while the phases are taken)")
        return None

    def _parameters(self, corners: np.ndarray, outline: np.ndarray, z: np.ndarray, w: int, h: int) -> np.ndarray:
        """The view's place on each axis of ``AXES``, each in 0..1."""
        cfg = self.config
        c = self.board.cols
        up_left, up_right, down_right, down_left = corners[[0, c - 1, -1, -c]]
        d1, d2 = down_right - up_left, down_left - up_right
        area = 0.5 * abs(d1[0] * d2[1] - d1[1] * d2[0])  # any simple quadrilateral: half the diagonals' cross
        # Where the board's outline is in the room it leaves inside the border: 0 against one
        # side, 1 against the other. camera_calibration shrinks the centre's range by the side of
        # a square of the board's area instead, which an oblong board filling a low-resolution
        # image can never span.
        m = cfg.border_px
        first, last = outline.min(axis=0), outline.max(axis=0)
        x, y = (first - m) / np.maximum(np.array([w - 1, h - 1]) - 2 * m - (last - first), 1.0)
        size = np.sqrt(area / (w * h))
        a, b = up_left - up_right, down_right - up_right
        angle = np.arccos(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1.0, 1.0))
        skew = 2 * abs(np.pi / 2 - angle)
        near, far = cfg.depth_range
        # Logarithmic: the focal-length error a depth offset left unresolved causes goes with
        # 1 - nearest / farthest distance, a ratio, alike near and far.
        depth = np.log(max(float(np.nanmedian(z)), near) / near) / np.log(far / near)
        tilt = _tilt_deg(corners, z, self.board, w, h) / cfg.max_tilt_deg
        return np.clip(np.array([x, y, size, skew, depth, tilt], dtype=float), 0.0, 1.0)


def short_axes(progress: dict) -> list[tuple[str, float]]:
    """The axes not yet full in ``ViewCollector.progress``, with their progress, the least first."""
    return sorted(((name, a["progress"]) for name, a in progress["axes"].items() if a["progress"] < 1.0),
                  key=lambda item: item[1])


def still_short(progress: dict) -> str:
    """The two axes of ``ViewCollector.progress`` covered least of those not yet full, each with
    what to do about it; empty when all are full."""
    return "; ".join(f"{LABELS[name]} {share:.0%}: {WHAT_TO_DO[name]}" for name, share in short_axes(progress)[:2])


def _tilt_deg(corners: np.ndarray, z: np.ndarray, board: Board, w: int, h: int) -> float:
    """Angle between the board's normal and the optical axis, from a plane through the corners
    back-projected with their depth.

    There is no calibration yet, so the principal point is taken at the image centre and the
    focal length from the board itself: adjacent corners are one square apart in 3D, which fixes
    f (the median over all pairs with depth). A guess such as f = image width would scale tilts
    by up to 40 % on common sensors. Depth is read as z; radial depth bends the result by a few
    degrees at most near the image edge, which does not matter for telling views apart.
    """
    p = corners - np.array([(w - 1) / 2, (h - 1) / 2])
    pz = (p * z[:, None]).reshape(board.rows, board.cols, 2)
    zz = z.reshape(board.rows, board.cols)
    along = [np.sum(np.diff(pz, axis=k) ** 2, axis=2) for k in (0, 1)]          # |d(p z)|^2, px^2 m^2
    room = [board.square ** 2 - np.diff(zz, axis=k) ** 2 for k in (0, 1)]       # in-image part^2, m^2
    a, r = np.concatenate([x.ravel() for x in along]), np.concatenate([x.ravel() for x in room])
    ok = np.isfinite(a) & np.isfinite(r) & (r > 0) & (a > 0)
    f = float(np.sqrt(np.median(a[ok] / r[ok]))) if ok.sum() >= 3 else float(w)
    valid = np.isfinite(z)
    normal, _ = svd_plane(np.column_stack([p[valid] * z[valid, None] / f, z[valid]]))
    return float(np.degrees(np.arccos(min(abs(normal[2]), 1.0))))


def _disagreement(quick: np.ndarray, accurate: Detection) -> str | None:
    """Why a view's accurate corners cannot stand for its quick ones, or None."""
    if accurate.corners is None:
        return f"board lost by the accurate detector: {accurate.message}"
    offset = float(np.sqrt(np.mean(np.sum((accurate.corners - quick) ** 2, axis=1))))
    if offset > QUICK_AGREEMENT_PX:
        return f"the quick and accurate detections disagree by {offset:.1f} px RMS"
    return None
