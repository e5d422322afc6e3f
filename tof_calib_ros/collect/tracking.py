"""Finding the board in a stream of frames: where it was last seen first, the whole image
when it is lost.

Judging whether a found board makes a good view is ``collector``'s job; this module only says
where the corners are. Following a board from the previous frame (``_follow``, about 1 ms)
instead of searching the whole image (10 to 90 ms at 640x576) is what lets the node keep up
with the camera.
"""
from __future__ import annotations

import functools

import cv2
import numpy as np

from ..core.board import Board
from ..core.detection import Detection, detect, locate, sharpen, small, tone_map
from ..core.errors import CalibrationError

# quick_locate(near=...): a corner followed from the previous frame may move this many squares
# and lie this many squares off the grid; the light squares must be this many grey levels (of 255)
# above the dark ones. The detector then searches NEAR_MARGIN_SQUARES squares around the previous
# corners (one for the outer squares, one for motion) plus a few pixels for its border.
FOLLOW_MAX_MOVE = 0.5
FOLLOW_GRID_TOLERANCE = 0.25
FOLLOW_MIN_CONTRAST = 20.0
NEAR_MARGIN_SQUARES = 2.0
# A followed corner refined a second time moves less than this (px), or it was not found.
FOLLOW_CONVERGED_PX = 0.1
NEAR_MARGIN_PX = 4.0

# While the board is not found, the whole image (50 to 90 ms at 640x576 when it holds no board
# the detector sees) is searched every this many frames, and only where the board was last seen
# in between: a board lost from sight is found again at most this many frames late (0.2 s at 15 fps).
WHOLE_IMAGE_EVERY = 4


def quick_locate(amplitude: np.ndarray, board: Board, near: np.ndarray | None = None,
                 before: np.ndarray | None = None, whole_image: bool = True, thorough: bool = False) -> Detection:
    """The quick corners ``add`` judges a frame by, with a blank or constant frame as a miss.

    ``near``: the corners last seen, when the caller keeps them (``BoardTracker``), and ``before``
    the ones of the frame before those. A board held still or moved smoothly is then
    followed (``_follow``, about 1 ms where the detector takes 10 to 60 ms): from where its
    motion so far puts it, then from where it was. Failing that, the detector looks in the
    region around both (its cost grows with the area searched), and then, unless
    ``whole_image`` is False, in the whole image: with no ``near``, that is the only search.
    ``thorough``: where the quick search of the whole image finds nothing, ``detect`` searches
    it as the calibration's own detector does (a 2x upscaled copy of small images, both OpenCV
    detectors): at 205x170 the quick search alone misses three boards in four.
    """
    if near is not None:
        square = _square_px(near, board)
        starts = [near] if before is None else [2 * near - before, near]
        for start in starts:
            followed = _follow(amplitude, board, start, square)
            if followed is not None:
                return Detection(followed, "followed from where it was last seen")
        (x0, y0), (x1, y1) = _region(np.concatenate(starts), NEAR_MARGIN_SQUARES * square + NEAR_MARGIN_PX,
                                     amplitude.shape)
        if x1 > x0 and y1 > y0:
            found = quick_locate(amplitude[y0:y1 + 1, x0:x1 + 1], board)
            if found.corners is not None:
                return Detection(found.corners + np.array([x0, y0], dtype=float), found.message)
        if not whole_image:
            return Detection(None, f"no {board.cols}x{board.rows} board found where it was last seen")
    elif not whole_image:
        return Detection(None, f"no {board.cols}x{board.rows} board seen lately: the whole image is searched "
                               f"every {WHOLE_IMAGE_EVERY} frames")
    try:
        found = locate(amplitude, board)
        # where the board is, not its accurate corners (accurate_detect): no second look
        return detect(amplitude, board, second_look=False) if found.corners is None and thorough else found
    except CalibrationError as exc:
        return Detection(None, str(exc))


class BoardTracker:
    """Where to look for the board in a stream of frames: where it was last seen (its motion
    extrapolated when it was seen in the frame before too, ``quick_locate``); while it is not
    found, the whole image is searched every ``WHOLE_IMAGE_EVERY`` frames, or on every frame,
    thoroughly, when the caller has the time (``locate(thorough=True)``: offline, or the node with
    no frame waiting). Thoroughly means by ``detect`` too only on images it sees upscaled
    (``small``: under 300 px), where the quick search misses boards held still (three in four at
    205x170). On larger ones it misses few (2 of 49 Kinect v2 views at 512x424), and a stream's
    frames where it misses are mostly of a moving board: at 640x576 ``detect`` took about 1 s on
    each, 80 % of a replay's time, and the boards it found there were all refused as moving."""

    def __init__(self, board: Board) -> None:
        self.board = board
        self.forget()

    def forget(self) -> None:
        """Start afresh (a reset, a frame that could not be read)."""
        self._seen = self._before = None   # the corners last seen, and the frame's before them when consecutive
        self._misses = 0                   # frames since the board was last seen

    def locate(self, amplitude: np.ndarray, thorough: bool = False) -> Detection:
        found = quick_locate(amplitude, self.board, self._seen, self._before,
                             whole_image=thorough or self._misses % WHOLE_IMAGE_EVERY == 0,
                             thorough=thorough and small(amplitude))
        if found.corners is None:
            self._before = None
            self._misses += 1
        else:
            self._before, self._seen = (self._seen if self._misses == 0 else None), found.corners
            self._misses = 0
        return found


def accurate_detect(amplitude: np.ndarray, board: Board, quick: np.ndarray) -> Detection:
    """``detect``'s accurate corners of a frame whose quick corners are ``quick``, found in the
    region around the quick corners with the whole image's choice of upscaling. Against the
    whole image, at 640x576 the region takes a tenth of the time, and its tone mapping, fitted to
    the board rather than the whole scene, gave corners nearer the truth on rendered views (0.08
    against 0.13 px RMS; the same at 200x200). In the region, the quick
    corners stand for ``detect``'s first look (``sharpen``), which is searched for again only
    where the second look fails."""
    margin = NEAR_MARGIN_SQUARES * _square_px(quick, board) + NEAR_MARGIN_PX
    (x0, y0), (x1, y1) = _region(quick, margin, amplitude.shape)
    region, origin = amplitude[y0:y1 + 1, x0:x1 + 1], np.array([x0, y0], dtype=float)
    found = sharpen(region, board, quick - origin)
    if found.corners is None:
        found = detect(region, board, upscale=small(amplitude))
    return found if found.corners is None else Detection(found.corners + origin, found.message)


def _square_px(corners: np.ndarray, board: Board) -> float:
    """The board's square size in the image, pixels (the longer of the two directions)."""
    grid = corners.reshape(board.rows, board.cols, 2)
    return max(float(np.median(np.linalg.norm(np.diff(grid, axis=k), axis=2))) for k in (0, 1))


def _region(corners: np.ndarray, margin: float, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Top-left and bottom-right pixel of the corners' bounding box widened by ``margin``, in the image."""
    h, w = shape
    return (np.maximum(np.floor(corners.min(axis=0) - margin), 0).astype(int),
            np.minimum(np.ceil(corners.max(axis=0) + margin), [w - 1, h - 1]).astype(int))


@functools.lru_cache(maxsize=8)
def _grid(cols: int, rows: int) -> np.ndarray:
    """The board's corners in squares, row by row as detected (read-only: it is shared)."""
    ids = np.arange(cols * rows)
    grid = np.column_stack([ids % cols, ids // cols]).astype(float)
    grid.setflags(write=False)
    return grid


def _off_grid(grid: np.ndarray, points: np.ndarray, H: np.ndarray | None) -> float:
    return np.inf if H is None else float(np.linalg.norm(cv2.perspectiveTransform(grid[None], H)[0] - points,
                                                         axis=1).max())


@functools.lru_cache(maxsize=8)
def _grid_leverage(cols: int, rows: int) -> float:
    """The largest leverage of a corner of a ``cols`` x ``rows`` grid in a homography's
    least-squares fit (of a square view; perspective changes it little): a corner displaced by
    e moves off that fit by at least (1 - leverage) e."""
    grid = _grid(cols, rows)
    x, y = (grid - grid.mean(axis=0)).T
    one, zero = np.ones_like(x), np.zeros_like(x)
    J = np.empty((2 * len(x), 8))
    J[0::2] = np.column_stack([x, y, one, zero, zero, zero, -x * x, -x * y])
    J[1::2] = np.column_stack([zero, zero, zero, x, y, one, -x * y, -y * y])
    hat = J @ np.linalg.pinv(J)
    return max(float(np.linalg.eigvalsh(hat[2 * i:2 * i + 2, 2 * i:2 * i + 2]).max()) for i in range(len(x)))


def _grid_homography(board: Board, points: np.ndarray, tolerance: float) -> np.ndarray | None:
    """The homography from the board's grid (``_grid``) to ``points`` if every point lies within
    ``tolerance`` of it, else None. Robust (LMEDS), so that a few corners stuck elsewhere show;
    but where the least-squares fit leaves every point well within what a stuck corner would
    leave (half of (1 - its leverage) the tolerance), none is stuck, and LMEDS, ten times its
    cost and a third of following a board, is not needed."""
    grid = _grid(board.cols, board.rows)
    H, _ = cv2.findHomography(grid, points, 0)
    if _off_grid(grid, points, H) <= 0.5 * (1 - _grid_leverage(board.cols, board.rows)) * tolerance:
        return H
    H, _ = cv2.findHomography(grid, points, cv2.LMEDS)
    return H if _off_grid(grid, points, H) <= tolerance else None


def _follow(amplitude: np.ndarray, board: Board, previous: np.ndarray, square: float) -> np.ndarray | None:
    """The corners refined (cornerSubPix) from where they are expected, or None unless they are
    surely the board's: no corner moved more than ``FOLLOW_MAX_MOVE`` squares, every one lies
    on the grid a homography through all of them predicts, and the squares around them, the outer
    ones included, alternate light and dark. A grid that slipped by a square fails the last test:
    its outer squares fall on the board's margin."""
    h, w = amplitude.shape
    if not np.all((previous >= 0) & (previous <= [w - 1, h - 1])):   # expected partly off the image
        return None
    (x0, y0), (x1, y1) = _region(previous, 1.5 * square + NEAR_MARGIN_PX, amplitude.shape)
    half = int(np.clip(round(0.35 * square), 2, 15))   # detection's cornerSubPix rule, on this square size
    if min(x1 - x0, y1 - y0) < 2 * half + 5:
        return None
    try:
        image = tone_map(amplitude[y0:y1 + 1, x0:x1 + 1]).astype(np.float32)
    except CalibrationError:   # a constant region: nothing to follow
        return None
    origin = np.array([x0, y0], dtype=float)
    pts = (previous - origin).astype(np.float32).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 20, 0.01)
    cv2.cornerSubPix(image, pts, (half, half), (-1, -1), criteria)
    local = pts.reshape(-1, 2).astype(np.float64)
    if not np.all(np.isfinite(local)) or \
            np.linalg.norm(local + origin - previous, axis=1).max() > FOLLOW_MAX_MOVE * square:
        return None
    # Started farther than its window reaches, cornerSubPix stops short of the corner: refined
    # again, it would move on. A board that moved that far is searched for instead.
    cv2.cornerSubPix(image, pts, (half, half), (-1, -1), criteria)
    if np.linalg.norm(pts.reshape(-1, 2) - local, axis=1).max() > FOLLOW_CONVERGED_PX:
        return None
    H = _grid_homography(board, local, FOLLOW_GRID_TOLERANCE * square)
    if H is None:
        return None
    i, j = np.meshgrid(np.arange(-1, board.cols) + 0.5, np.arange(-1, board.rows) + 0.5)
    centres = cv2.perspectiveTransform(np.column_stack([i.ravel(), j.ravel()])[None], H)[0].astype(np.float32)
    if np.any(centres < 0) or np.any(centres > [image.shape[1] - 1, image.shape[0] - 1]):
        return None
    level = cv2.remap(image, centres[None, :, 0], centres[None, :, 1], cv2.INTER_LINEAR).ravel()
    even = (np.floor(i) + np.floor(j)).ravel() % 2 == 0
    light, dark = (level[even], level[~even]) if level[even].mean() > level[~even].mean() else \
        (level[~even], level[even])
    if not light.min() - dark.max() > FOLLOW_MIN_CONTRAST:
        return None
    return local + origin
