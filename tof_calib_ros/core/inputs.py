"""The caller's views, checked and prepared before any work: depth in metres, the board's corners
found, and each view that cannot be used set aside with the reason."""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .board import Board, whole_number
from .detection import Detection, detect, saturation
from .errors import CalibrationError

NO_BOARD = "no board found"
DEPTH_UNITS_RANGE = (1e-6, 1.0)  # metres per unit: micrometres to metres
MIN_SPREAD_PX = 0.5  # corners closer than this (RMS) to one line in the image say nothing across it


@dataclass
class View:
    """One frame: the depth image plus either the amplitude image or already-detected corners.

    ``depth`` is in metres when float, in millimetres when integer (see ``depth_units``);
    0 and NaN are invalid. ``ids`` are the board indices of ``corners`` (default: all, in order).
    """

    depth: np.ndarray
    corners: np.ndarray | None = None
    ids: np.ndarray | None = None
    amplitude: np.ndarray | None = None


@dataclass
class Prepared:
    index: int
    depth: np.ndarray          # metres, NaN invalid
    corners: np.ndarray
    ids: np.ndarray
    amplitude: np.ndarray | None
    saturation: float = float("nan")   # detection.saturation; NaN without an amplitude image


# ToF cameras measure to some tens of metres at most: farther is a driver's sentinel (65535 mm) or
# a glitch, and left in, such values overflow the plane fits.
MAX_DEPTH_M = 50.0


def depth_units(depth: np.ndarray) -> float:
    """Metres a count, unless told: integer images are millimetres, float ones metres."""
    return 1e-3 if np.issubdtype(np.asarray(depth).dtype, np.integer) else 1.0


def depth_in_metres(depth: np.ndarray, units: float | None = None) -> np.ndarray:
    """Float metres with NaN for invalid pixels (``units`` as ``depth_units`` unless told):
    0, NaN and anything beyond ``MAX_DEPTH_M``."""
    d = np.asarray(depth)
    with np.errstate(over="ignore", invalid="ignore"):
        out = d.astype(np.float64) * (depth_units(d) if units is None else units)
        out[~(out > 0) | ~(out <= MAX_DEPTH_M)] = np.nan
    return out


def check_arguments(views: Sequence[View], board: Board, image_size: tuple[int, int] | None,
                    depth_units: float | None, min_views: int, progress: Callable[[str], None] | None) -> None:
    """The caller's own mistakes (a wrong type, a size of zero) named before any work is done."""
    if not isinstance(board, Board):
        raise CalibrationError(f"board must be a Board, got {type(board).__name__}")
    if not isinstance(views, Sequence) or isinstance(views, str):
        raise CalibrationError(f"views must be a list of View, got {type(views).__name__}")
    for i, v in enumerate(views):
        if not isinstance(v, View):
            raise CalibrationError(f"view {i} is not a View but {type(v).__name__}")
    if image_size is not None:
        size = [whole_number(n) for n in image_size] if isinstance(image_size, (Sequence, np.ndarray)) else []
        if len(size) != 2 or None in size or min(size) < 1:
            raise CalibrationError(f"image_size must be (width, height) in pixels, got {image_size!r}")
    if depth_units is not None and (isinstance(depth_units, (bool, np.bool_))
                                    or not isinstance(depth_units, (int, float, np.integer, np.floating))
                                    or not DEPTH_UNITS_RANGE[0] <= depth_units <= DEPTH_UNITS_RANGE[1]):
        raise CalibrationError(f"depth_units must be metres per unit of the depth images, from {DEPTH_UNITS_RANGE[0]}"
                               f" to {DEPTH_UNITS_RANGE[1]}, got {depth_units!r}")
    if whole_number(min_views) is None or min_views < 2:
        raise CalibrationError(f"min_views must be a whole number of at least 2 (one view cannot tell the focal "
                               f"length from the distance), got {min_views!r}")
    if progress is not None and not callable(progress):
        raise CalibrationError(f"progress must be a function taking one line of text, got {progress!r}")


def prepare(views: Sequence[View], board: Board, image_size: tuple[int, int] | None,
            depth_units: float | None) -> tuple[list[Prepared], dict[int, str], tuple[int, int]]:
    if len(views) == 0:
        raise CalibrationError("no views given")
    if image_size is None:
        shape = np.asarray(views[0].depth).shape
        if len(shape) != 2:
            raise CalibrationError(f"view 0: depth must be a 2-D image, got shape {shape}")
        image_size = (shape[1], shape[0])
    w, h = image_size
    kept, rejected = [], {}
    for i, v in enumerate(views):
        depth = np.asarray(v.depth)
        if not (np.issubdtype(depth.dtype, np.integer) or np.issubdtype(depth.dtype, np.floating)):
            raise CalibrationError(f"view {i}: depth must be an integer or float image, got {depth.dtype}")
        if depth.shape != (h, w):
            raise CalibrationError(f"view {i}: depth image is {depth.shape[1] if depth.ndim == 2 else '?'}x"
                                   f"{depth.shape[0]} but the image size is {w}x{h}")
        if v.amplitude is not None and np.asarray(v.amplitude).shape[:2] != (h, w):
            raise CalibrationError(f"view {i}: amplitude image size {np.asarray(v.amplitude).shape[:2][::-1]} "
                                   f"differs from the depth image size {(w, h)}")
        corners, ids = v.corners, v.ids
        if corners is None:
            if v.amplitude is None:
                raise CalibrationError(f"view {i}: give either the amplitude image or the corners")
            try:
                found = detect(np.asarray(v.amplitude), board)
            except CalibrationError as exc:
                found = Detection(None, str(exc))
            if found.corners is None:
                rejected[i] = f"{NO_BOARD}: {found.message}"
                continue
            corners = found.corners
        try:
            corners = np.asarray(corners, dtype=float).reshape(-1, 2)
            ids = None if ids is None else np.asarray(ids, dtype=int).ravel()
        except (TypeError, ValueError):
            raise CalibrationError(f"view {i}: corners must be (N, 2) pixels and ids N board indices") from None
        if ids is None:
            if len(corners) != board.n_corners:
                raise CalibrationError(f"view {i}: {len(corners)} corners for a {board.cols}x{board.rows} "
                                       "board; pass ids for a partial set")
            ids = np.arange(board.n_corners)
        if len(ids) != len(corners) or len(np.unique(ids)) != len(ids) \
                or (ids.size and (ids.min() < 0 or ids.max() >= board.n_corners)):
            raise CalibrationError(f"view {i}: corner ids must be distinct board indices, one per corner")
        if not np.all(np.isfinite(corners)):
            raise CalibrationError(f"view {i}: corners contain NaN or inf")
        if len(corners) < 4:
            rejected[i] = f"only {len(corners)} corners (need 4)"
            continue
        if np.any((corners < -0.5) | (corners > np.array([w, h]) - 0.5)):
            rejected[i] = f"corners lie outside the {w}x{h} image"
            continue
        if _on_a_line(board.object_points(ids)[:, :2]):
            rejected[i] = "its corners lie on one line of the board (give corners off that line too)"
            continue
        if _on_a_line(corners, MIN_SPREAD_PX):
            rejected[i] = "its corners lie on one line in the image (a board seen edge on?)"
            continue
        amplitude = None if v.amplitude is None else np.asarray(v.amplitude)
        share = saturation(amplitude, corners) if amplitude is not None and amplitude.ndim == 2 else float("nan")
        kept.append(Prepared(i, depth_in_metres(depth, depth_units), corners, ids, amplitude, share))
    return kept, rejected, (int(w), int(h))


def _on_a_line(points: np.ndarray, tolerance: float = 0.0) -> bool:
    """True when the points' RMS distance from their best line is at most ``tolerance``
    (relative to their spread along it when 0): a homography needs points off any line."""
    centred = points - points.mean(0)
    major, minor = np.linalg.svd(centred, compute_uv=False) / np.sqrt(len(points))
    return bool(minor <= max(tolerance, 1e-9 * major))


def require(views: list[Prepared], rejected: dict[int, str], min_views: int, n_given: int) -> None:
    if len(views) >= min_views:
        return
    why = "; ".join(f"view {k}: {r}" for k, r in sorted(rejected.items()))
    if not views and rejected and all(r.startswith(NO_BOARD) for r in rejected.values()):
        raise CalibrationError(f"no board found in any of the {n_given} views")
    raise CalibrationError(f"too few usable views: {len(views)} of {n_given}, need at least {min_views}"
                           + (f" ({why})" if why else ""))
