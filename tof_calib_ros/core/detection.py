"""Checkerboard corners in time-of-flight amplitude (IR) images.

ToF amplitude images are small (often < 300 px), noisy and of wide dynamic range, so the image
is first tone-mapped by a robust percentile stretch, then OpenCV's sector-based detector
(``findChessboardCornersSB``) is tried, with the classic detector plus ``cornerSubPix`` as the
fallback. The board found is looked at again by the SB detector, cropped and upscaled until its
squares are large enough for that detector to be unbiased. Every detection is checked corner by
corner against the grid its neighbours predict, and its labelling is normalised so that it does
not depend on which corner OpenCV started from.

Pixel convention: OpenCV's, the centre of pixel (0, 0) is the coordinate (0, 0).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .board import Board
from .errors import CalibrationError

# Below this image size (shorter side, pixels) the SB detector also sees a 2x upscaled image:
# it finds boards with squares of only a few pixels more often there.
UPSCALE_BELOW = 300
# A corner farther than this fraction of the local square size (and at least OUTLIER_MIN_PX)
# from where its 3x3 neighbourhood puts it marks the whole detection as bad.
OUTLIER_FRACTION = 0.15
OUTLIER_MIN_PX = 1.0
# The SB detector's corners are biased where the squares it sees are small: on rendered views
# with 6-11 px squares, seen 2x upscaled, it put the pattern 0.1 % too large, 0.3 % with a
# lens's blur (sigma 1 px), and on the real Kinect v2 views that bias moved OpenCV's focal
# length 2 % and its halves 2.6 % apart. With squares of this size or more it has none we can
# measure, so a board found is looked at again, cropped and upscaled until its squares are.
SB_SQUARE_PX = 32.0
MAX_UPSCALE = 8

# No CALIB_CB_NORMALIZE_IMAGE for SB: the image is already stretched, and its histogram
# equalisation lifts the noise of a dark background until SB misses noisy boards (3 of 20
# rendered 200x200 views with 0.5 % amplitude noise, 20 of 20 when upscaled; none without it).
# The second look, on the board's crop, gives the corners kept, in ACCURACY mode: without it the
# real Kinect v2 views' OpenCV fx moves 1.7 % (to 364 px) and their halves 2 % apart, even at
# squares of 48-64 px. The first look only has to find the board: the exhaustive search first,
# then, where that finds nothing, with ACCURACY too (60 % dearer), whose own upsampling finds
# boards the first misses (20 of 59 frames of a moving board at 640x576).
_FIND_FLAGS = (cv2.CALIB_CB_EXHAUSTIVE, cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
_ACCURATE_FLAGS = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
_CLASSIC_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
IMAGE_DTYPES = (np.uint8, np.uint16, np.int16, np.float32, np.float64)   # what the detector reads
# The SB detector draws from OpenCV's random generator (the calling thread's), so the same image
# gave corners up to 1 px apart by what had been detected before it in the process (a real Kinect
# v2 view at 205x170, after five others): seeded before each call, as a new process starts it
# (OpenCV takes the seed 0 for its initial state), an image always gives the same corners.
_SB_SEED = 0
# A board this share of whose pixels sit at the image's brightest value has white squares that clip:
# the edges its corners are placed by are flattened. Real Kinect v2 views with 25-48 % clipped had a
# median pixel RMS of 0.08 px under OpenCV's fit, the others 0.037; rendered ones with 45 % or more,
# 0.10 px off the truth a coordinate, unclipped 0.037 (docs/measurements.md, 2026-12-01).
SATURATED_SHARE = 0.2
CLIPPING_COSTS = ("which places the corners 2-3 times less accurately: lower the exposure, or hold the board "
                  "farther")


@dataclass(frozen=True)
class Detection:
    """Corners (N, 2) in Board order or None; ``message`` says which detector won or why none did."""

    corners: np.ndarray | None
    message: str


def _stretch(image: np.ndarray) -> np.ndarray:
    """Float image mapped to 0..255 (unclipped outside the percentiles, NaN/inf -> 0)."""
    if not isinstance(image, np.ndarray):
        raise CalibrationError(f"amplitude image must be a numpy array, got {type(image).__name__}")
    if image.ndim != 2:
        raise CalibrationError(f"amplitude image must be 2-D (one channel), got shape {image.shape}")
    if image.size == 0:
        raise CalibrationError("amplitude image is empty")
    if image.dtype.type not in IMAGE_DTYPES:
        raise CalibrationError(
            f"amplitude image must be uint8, uint16, int16 or float, got dtype {image.dtype}")
    img = image.astype(np.float64)
    if np.issubdtype(image.dtype, np.integer):
        lo, hi = _integer_range(image)
        finite = None
    else:
        finite = np.isfinite(img)
        values = img[finite]
        if values.size == 0:
            raise CalibrationError("amplitude image has no finite values")
        lo, hi = np.percentile(values, 0.5), np.percentile(values, 99.5)
        if hi <= lo:
            lo, hi = values.min(), values.max()
    if hi <= lo:
        raise CalibrationError(f"amplitude image is constant ({lo:g}); no board can be seen")
    out = (img - lo) * (255.0 / (hi - lo))
    if finite is not None:
        out[~finite] = 0.0
    return out


def _integer_range(image: np.ndarray) -> tuple[float, float]:
    """The 0.5 and 99.5 percentiles of an integer image, interpolated as ``np.percentile`` does,
    from its histogram: a tenth of the time of sorting a 640x576 image, on every frame searched.
    Saturated pixels (often whole retro-reflecting or near objects in ToF) would set the upper
    percentile to full scale and darken the board: they are left out of it unless they are
    half the image."""
    info = np.iinfo(image.dtype)
    # up to the brightest value only: ToF amplitude uses a small part of 16 bits, and the
    # histogram's length is most of the cost in the small regions a stream's board is followed in
    counts = np.bincount(image.ravel().astype(np.int64) - info.min)
    lo = _histogram_percentile(counts, 0.5)
    saturated = len(counts) == info.max - info.min + 1 and counts[-1] <= 0.5 * image.size
    unsaturated = counts.copy()
    unsaturated[-1] = 0
    hi = _histogram_percentile(unsaturated if saturated else counts, 99.5)
    if hi <= lo:
        present = np.flatnonzero(counts)
        lo, hi = float(present[0]), float(present[-1])
    return lo + info.min, hi + info.min


def _histogram_percentile(counts: np.ndarray, q: float) -> float:
    cum = np.cumsum(counts)
    pos = q / 100 * (cum[-1] - 1)
    below = int(pos)
    a, b = np.searchsorted(cum, [below, min(below + 1, cum[-1] - 1)], side="right")
    return float(a + (pos - below) * (b - a))


def tone_map(image: np.ndarray) -> np.ndarray:
    """8-bit view of an amplitude image for the detectors.

    A percentile stretch rather than a shift by 8 bits: ToF amplitude often uses a tenth of the
    16-bit range, and a plain division by 256 would leave the board black.
    """
    return np.clip(np.rint(_stretch(image)), 0, 255).astype(np.uint8)


def small(image: np.ndarray) -> bool:
    """Whether the detector sees ``image`` upscaled first: the images where boards of a few pixels'
    squares are missed without it, by the SB detector and by the quick search alike."""
    return min(image.shape) < UPSCALE_BELOW


def saturation(image: np.ndarray, corners: np.ndarray) -> float:
    """The share of the board's pixels (within its corners' hull) at the image's brightest value,
    which is its full scale where it clips: the clipped squares' edges no longer say where the
    corners are. Whatever the sensor's full scale (12 bits in 16, a float's 1.0)."""
    img = np.asarray(image)
    hull = cv2.convexHull(np.asarray(corners, dtype=np.float32).reshape(-1, 1, 2))
    mask = np.zeros(img.shape[:2], np.uint8)
    cv2.fillConvexPoly(mask, np.rint(hull).astype(np.int32), 1)
    inside = img[mask > 0]
    inside = inside[np.isfinite(inside)] if inside.dtype.kind == "f" else inside
    if inside.size == 0:
        return 0.0
    top = np.nanmax(img) if img.dtype.kind == "f" else img.max()
    return float(np.mean(inside == top))


def clipped(share: float) -> str | None:
    """What a person should hear of a board whose ``saturation`` is ``share``; None where it does
    not clip enough to matter."""
    if not share >= SATURATED_SHARE:
        return None
    return f"its white squares clip ({share:.0%} of the board at the amplitude's full scale), {CLIPPING_COSTS}"


def detect(image: np.ndarray, board: Board, *, upscale: bool | None = None,
           second_look: bool = True) -> Detection:
    """Corners and the reason behind the result, for logs and user feedback.

    The classic detector's corners are refined (cornerSubPix). Either detector's board is looked
    at again by the SB detector in accuracy mode, at squares of SB_SQUARE_PX (``_second_look``),
    unless ``second_look`` is False: a search that only needs to know where the board is, whose
    corners are rougher. ``upscale`` None means: let the SB detector see a 2x upscaled copy of
    images smaller than ``UPSCALE_BELOW`` first. A detection with any corner off its neighbours'
    grid is rejected (the next detector is tried), not repaired: a corner caught on glare or a
    wrong edge would bias the calibration more than a lost view.
    """
    stretched = _stretch(image)
    gray = np.clip(np.rint(stretched), 0, 255).astype(np.uint8)
    fine = np.clip(stretched, 0, 255).astype(np.float32)  # unquantised, for cornerSubPix
    if upscale is None:
        upscale = small(gray)
    reasons = []

    # SB corners are not passed through cornerSubPix: the second look's ACCURACY mode is sub-pixel.
    # cornerSubPix removes SB's small bias on rendered views but doubles the noise on the real
    # Kinect v2 views (0.13 -> 0.24 px RMS) and leaves their halves no closer (README, limitations).
    corners = _detect_sb(gray, board, upscale)
    if corners is None:
        reasons.append("SB detector found no board")
    else:
        bad = _grid_outliers(corners, board)
        if bad is None:
            found = Detection(_normalise_order(corners, board), "found by findChessboardCornersSB")
            return _sharpened(stretched, found, board) if second_look else found
        reasons.append(f"SB detection rejected: {bad}")

    found, raw = cv2.findChessboardCorners(gray, board.pattern_size, flags=_CLASSIC_FLAGS)
    if not found or raw is None or len(raw) != board.n_corners:
        reasons.append("classic detector found no board")
    else:
        corners = _subpix(fine, raw.reshape(-1, 2).astype(np.float64), board)
        bad = _grid_outliers(corners, board)
        if bad is None:
            found = Detection(_normalise_order(corners, board), "found by findChessboardCorners")
            return _sharpened(stretched, found, board) if second_look else found
        reasons.append(f"classic detection rejected: {bad}")
    return Detection(None, f"no {board.cols}x{board.rows} board found: " + "; ".join(reasons))


def locate(image: np.ndarray, board: Board) -> Detection:
    """Quick corners (the SB detector's plain mode on the image as it is, a few ms), in Board
    order: enough to judge a frame's pose, motion and novelty. A live stream cannot afford
    ``detect`` (tens of ms) on every frame, only on the frames worth keeping."""
    found, pts = _find_sb(tone_map(image), board, 0)
    if not found or pts is None or len(pts) != board.n_corners:
        return Detection(None, f"no {board.cols}x{board.rows} board found")
    return Detection(_normalise_order(pts.reshape(-1, 2).astype(np.float64), board), "found by the quick check")


def detect_corners(image: np.ndarray, board: Board) -> np.ndarray | None:
    """(N, 2) float64 corner pixels in Board order, or None when no trustworthy board is seen.

    Use ``detect`` instead to learn why a view was dropped.
    """
    return detect(image, board).corners


def _detect_sb(gray: np.ndarray, board: Board, upscale: bool) -> np.ndarray | None:
    """Where the SB detector finds the board, with each of _FIND_FLAGS in turn, from the upscaled
    image first when asked (then the original)."""
    for f in _FIND_FLAGS:
        for factor in (2, 1) if upscale else (1,):
            corners = _sb_corners(gray, board, f, factor)
            if corners is not None:
                return corners
    return None


def _find_sb(image: np.ndarray, board: Board, flags: int) -> tuple[bool, np.ndarray | None]:
    """findChessboardCornersSB as a function of the image alone (``_SB_SEED``). It resets the
    calling thread's OpenCV random generator, which nothing else of ours draws from."""
    cv2.setRNGSeed(_SB_SEED)
    return cv2.findChessboardCornersSB(image, board.pattern_size, flags=flags)


def _sb_corners(image: np.ndarray, board: Board, flags: int, factor: int) -> np.ndarray | None:
    """SB corners on ``image`` (0..255) upscaled ``factor`` times, in ``image``'s pixels."""
    big = image if factor == 1 else cv2.resize(image, None, fx=factor, fy=factor, interpolation=cv2.INTER_CUBIC)
    if big.dtype != np.uint8:
        big = np.clip(np.rint(big), 0, 255).astype(np.uint8)
    found, pts = _find_sb(big, board, flags)
    if not found or pts is None or len(pts) != board.n_corners:
        return None
    # cv2.resize aligns pixel areas: x_big = factor x + (factor - 1) / 2.
    return (pts.reshape(-1, 2).astype(np.float64) - (factor - 1) / 2) / factor


def sharpen(image: np.ndarray, board: Board, corners: np.ndarray) -> Detection:
    """The accurate corners of a board already located (``corners``, in Board order, from a
    quicker search): ``detect``'s second look without its first, which a stream's tracker has
    already done. No corners where the second look fails or strays from ``corners``."""
    again = _second_look(_stretch(image), np.asarray(corners, dtype=np.float64), board)
    if again is None:
        return Detection(None, "the second look at the board located there failed")
    sharp, seen = again
    return Detection(sharp, f"found where it was located, {seen}")


def _sharpened(stretched: np.ndarray, found: Detection, board: Board) -> Detection:
    """``found`` after the second look, or as it was, and said so, where that look fails."""
    again = _second_look(stretched, found.corners, board)
    if again is None:
        return Detection(found.corners, f"{found.message}, not sharpened: the second look failed")
    sharp, seen = again
    return Detection(sharp, f"{found.message}, {seen}")


def _second_look(stretched: np.ndarray, corners: np.ndarray, board: Board) -> tuple[np.ndarray, str] | None:
    """The board's corners from the SB detector in accuracy mode on a crop upscaled until its
    squares are SB_SQUARE_PX (at most MAX_UPSCALE times), else less upscaled (one of the real
    Kinect v2 views is found only as it is), and how it saw them; None where every look fails or
    strays from ``corners``."""
    grid = corners.reshape(board.rows, board.cols, 2)
    spacing = _spacing(grid)
    factor = int(np.clip(np.ceil(SB_SQUARE_PX / spacing), 1, MAX_UPSCALE))
    steps = np.r_[np.linalg.norm(np.diff(grid, axis=1), axis=2).ravel(),
                  np.linalg.norm(np.diff(grid, axis=0), axis=2).ravel()]
    margin = 1.5 * float(steps.max())   # the outer squares and a quiet zone beyond them
    h, w = stretched.shape
    x0, y0 = (max(int(np.floor(v - margin)), 0) for v in corners.min(axis=0))
    x1, y1 = (min(int(np.ceil(v + margin)), n - 1) for v, n in zip(corners.max(axis=0), (w, h)))
    crop = np.clip(stretched[y0:y1 + 1, x0:x1 + 1], 0, 255).astype(np.float32)
    tolerance = max(OUTLIER_FRACTION * spacing, OUTLIER_MIN_PX)
    for f in dict.fromkeys((factor, min(factor, 2), 1)):
        again = _sb_corners(crop, board, _ACCURATE_FLAGS, f)
        if again is None:
            continue
        again = _normalise_order(again + (x0, y0), board)
        if _grid_outliers(again, board) is None and np.max(np.linalg.norm(again - corners, axis=1)) <= tolerance:
            return again, f"its squares seen at {spacing * f:.0f} px ({f}x upscaled)" if f > 1 else \
                f"its squares seen at {spacing:.0f} px (not upscaled)"
    return None


def _spacing(grid: np.ndarray) -> float:
    """Typical distance between adjacent corners along the shorter-looking board axis."""
    dx = np.linalg.norm(np.diff(grid, axis=1), axis=2)
    dy = np.linalg.norm(np.diff(grid, axis=0), axis=2)
    return float(min(np.median(dx), np.median(dy)))


def _subpix(image: np.ndarray, corners: np.ndarray, board: Board) -> np.ndarray:
    """cornerSubPix with a window matched to the square size, so it neither sees the neighbouring
    corners (window too big) nor misses the saddle's edges (window too small)."""
    grid = corners.reshape(board.rows, board.cols, 2)
    half = int(np.clip(round(0.35 * _spacing(grid)), 2, 15))
    pts = corners.astype(np.float32).reshape(-1, 1, 2).copy()
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    cv2.cornerSubPix(image, pts, (half, half), (-1, -1), crit)
    return pts.reshape(-1, 2).astype(np.float64)


def _grid_outliers(corners: np.ndarray, board: Board) -> str | None:
    """None when every corner sits where a homography through its (up to 3x3) neighbourhood,
    fitted without it, puts it; otherwise a message naming the worst corner.

    A local fit tolerates lens distortion and perspective that a single board-wide homography
    would not, while still catching corners caught on a wrong edge or a swapped row.
    """
    if not np.all(np.isfinite(corners)):
        return "non-finite corner coordinates"
    grid = corners.reshape(board.rows, board.cols, 2)
    spacing = _spacing(grid)
    if not spacing > 0:
        return "degenerate grid (coincident corners)"
    tol = max(OUTLIER_FRACTION * spacing, OUTLIER_MIN_PX)
    wr, wc = 3, 3   # a corner is predicted from its 3x3 neighbourhood (Board has at least 3x3 corners)
    worst, worst_i = 0.0, -1
    for r in range(board.rows):
        r0 = min(max(r - 1, 0), board.rows - wr)
        for c in range(board.cols):
            c0 = min(max(c - 1, 0), board.cols - wc)
            obj, img = [], []
            for rr in range(r0, r0 + wr):
                for cc in range(c0, c0 + wc):
                    if (rr, cc) != (r, c):
                        obj.append((cc, rr))
                        img.append(grid[rr, cc])
            H, _ = cv2.findHomography(np.array(obj, float), np.array(img, float), 0)
            if H is None:
                return f"degenerate neighbourhood around corner {r * board.cols + c}"
            p = H @ np.array([c, r, 1.0])
            err = float(np.hypot(*(p[:2] / p[2] - grid[r, c])))
            if not err <= worst:
                worst, worst_i = err, r * board.cols + c
    if worst > tol:
        return (f"corner {worst_i} is {worst:.1f} px off the grid its neighbours predict "
                f"(tolerance {tol:.1f} px)")
    return None


def _normalise_order(corners: np.ndarray, board: Board) -> np.ndarray:
    """The labelling of the same grid whose x axis (index + 1) points most to the image right
    and y axis (index + cols) most down, without mirroring the board.

    OpenCV may start from any corner. Only relabellings that are symmetries of the grid are
    considered (180 degree turn; 90 degree turns too for square boards), plus one flip when the
    input is mirrored, so the result is always a row-by-row ordering of the detected grid.
    """
    grid = corners.reshape(board.rows, board.cols, 2)
    u = np.diff(grid, axis=1).mean(axis=(0, 1))
    v = np.diff(grid, axis=0).mean(axis=(0, 1))
    if u[0] * v[1] - u[1] * v[0] < 0:
        # Mirrored labelling: a board seen from the front projects with x cross y > 0.
        grid = grid[:, ::-1]
    candidates = [grid, grid[::-1, ::-1]]
    if board.cols == board.rows:
        # Turning the labelling by 90 degrees: new (r, c) = old (c, n-1-r) and its opposite.
        candidates += [np.transpose(grid, (1, 0, 2))[:, ::-1], np.transpose(grid, (1, 0, 2))[::-1, :]]

    def score(g: np.ndarray) -> float:
        ux = np.diff(g, axis=1).mean(axis=(0, 1))
        vy = np.diff(g, axis=0).mean(axis=(0, 1))
        return ux[0] / np.hypot(*ux) + vy[1] / np.hypot(*vy)

    best = max(candidates, key=score)
    return np.ascontiguousarray(best.reshape(-1, 2), dtype=np.float64)
