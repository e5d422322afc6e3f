"""What a single ToF frame shows about a board that moved while it was taken.

A board that moves during the exposure blurs the amplitude image along the motion, and, on a
multi-phase ToF camera, which takes its correlation samples one after another, gives the pixels
on the squares' edges a depth that no surface has (each sample saw another brightness). Both
are read from the frame alone, so they judge a still from a folder or a frame from a sparse
recording as well as one from a 30 Hz stream:

- ``edge_blur_px``: how wide the squares' edges are, across each of the board's two edge
  directions (motion blurs the edges across it and leaves the ones along it sharp);
- ``edge_depth_error``: how far the depth on the squares' edges is from the plane through the
  squares' centres, against how far the centres themselves are.
"""
from __future__ import annotations

import cv2
import numpy as np

from ..core.board import Board
from ..core.detection import tone_map
from ..core.inputs import depth_in_metres, depth_units

# Profile across an edge: this far into each square (a fraction of the square), in steps of this many px.
PROFILE_REACH = 0.45
PROFILE_STEP_PX = 0.25
# Along each edge, profiles at these fractions of the way from one corner to the next, averaged.
ALONG = (0.3, 0.5, 0.7)
# The edge is where the profile's slope is at least this fraction of its steepest.
EDGE_FRACTION = 0.1


def _edges(corners: np.ndarray, board: Board) -> tuple[np.ndarray, np.ndarray]:
    """Start and end corner of every segment between neighbouring corners, grouped by direction:
    (2, n, 2, 2) would be ragged, so a list of two (n_k, 2, 2) arrays."""
    grid = corners.reshape(board.rows, board.cols, 2)
    along_rows = np.stack([grid[:, :-1], grid[:, 1:]], axis=2).reshape(-1, 2, 2)
    along_cols = np.stack([grid[:-1], grid[1:]], axis=2).reshape(-1, 2, 2)
    return along_rows, along_cols


def _edge_widths(image: np.ndarray, segments: np.ndarray, across: float) -> np.ndarray:
    """Width (px) of the edge each corner-to-corner segment lies on, at each of ``ALONG`` (n, 3; a
    segment joins corners along a square's side, which is the edge between two squares), from the spread of the
    slope across it: sqrt(12) standard deviations of the profile's derivative, which is b for a
    ramp b px wide, less what the pixels add (which depends on where the edge falls on them):
    1 px for a sharp edge, sqrt(1 + b^2) for an edge blurred by b px across it. ``across``: the
    squares' size across the edge (px), which the profile must stay within."""
    a, b = segments[:, 0], segments[:, 1]
    d = b - a
    u = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    n = np.column_stack([-u[:, 1], u[:, 0]])
    reach = PROFILE_REACH * across
    steps = np.arange(-reach, reach + 1e-9, PROFILE_STEP_PX)
    points = (a[:, None, None, :] + np.asarray(ALONG)[None, :, None, None] * d[:, None, None, :]
              + steps[None, None, :, None] * n[:, None, None, :])
    xy = points.reshape(1, -1, 2).astype(np.float32)
    profile = cv2.remap(image, xy[..., 0], xy[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    # Each profile on its own: the quick corners are a fraction of a pixel off, so profiles at
    # different places along an edge cross it at different offsets, and averaged they would widen it.
    slope = np.diff(profile.reshape(len(segments) * len(ALONG), len(steps)), axis=1)
    slope = slope * np.sign(slope.sum(axis=1, keepdims=True))   # the step may go either way
    # Only the edge itself: the run of slopes above a fraction of the steepest around it. Noise and
    # the shading of a tilted board, far from the edge, would otherwise dominate the spread.
    peak = np.argmax(slope, axis=1)
    high = slope >= EDGE_FRACTION * slope[np.arange(len(slope)), peak][:, None]
    index = np.arange(slope.shape[1])[None, :]
    low_before = np.where(~high & (index < peak[:, None]), index, -1).max(axis=1)
    low_after = np.where(~high & (index > peak[:, None]), index, slope.shape[1]).min(axis=1)
    slope = np.where((index > low_before[:, None]) & (index < low_after[:, None]), slope, 0.0)
    mass = slope.sum(axis=1)
    at = 0.5 * (steps[1:] + steps[:-1])
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = (slope * at).sum(axis=1) / mass
        var = (slope * (at[None] - mean[:, None]) ** 2).sum(axis=1) / mass
    # Where the edge falls on the pixels: a sharp edge inside a pixel, a fraction phi from its
    # side, spreads over that pixel and the next (variance phi (1 - phi) along each axis beyond
    # the pixel's own 1/12). Taken off, a sharp edge reads 1 px wherever it falls.
    normal = np.repeat(n, len(ALONG), axis=0)
    crossing = points[:, :, 0].reshape(-1, 2) + (mean[:, None] + reach) * normal
    phase = np.mod(crossing + 0.5, 1.0)
    sampling = np.sum(normal ** 2 * phase * (1 - phase), axis=1)
    with np.errstate(invalid="ignore"):
        width = np.sqrt(np.maximum(12 * (var - sampling), 1.0))
    return np.where(mass > 0, width, np.nan).reshape(len(segments), len(ALONG))


def edge_blur_px(amplitude: np.ndarray, corners: np.ndarray, board: Board) -> tuple[float, float]:
    """Edge width (px, the median of ``_edge_widths``: glare or a dirty square widens a few edges,
    motion all of them) across each of the board's two edge directions, the wider first."""
    image = tone_map(amplitude).astype(np.float32)
    families = _edges(corners, board)
    size = [float(np.median(np.linalg.norm(f[:, 1] - f[:, 0], axis=1))) for f in families]
    widths = [float(np.nanmedian(_edge_widths(image, f, size[1 - k]))) for k, f in enumerate(families)]
    return max(widths), min(widths)


def edge_depth_error(depth: np.ndarray, corners: np.ndarray, board: Board) -> tuple[float, float]:
    """Median distance (m) of the depth on the squares' edges, and of the depth at the squares'
    centres, from the plane through the centres (fitted as 1 / depth, which a plane makes linear
    in the pixel coordinates). Noise alone puts both at about the noise; a board that moved puts
    the edges far off. ``depth`` as ``calibrate`` reads it (integer millimetres, float metres):
    only the pixels sampled are converted."""
    grid = corners.reshape(board.rows, board.cols, 2)
    centres = (0.25 * (grid[:-1, :-1] + grid[:-1, 1:] + grid[1:, :-1] + grid[1:, 1:])).reshape(-1, 2)
    edges = np.concatenate([a[:, 0] + f * (a[:, 1] - a[:, 0]) for a in _edges(corners, board) for f in ALONG])
    h, w = depth.shape
    units = depth_units(depth)

    def at(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = np.rint(points).astype(int)
        ok = (p[:, 0] >= 0) & (p[:, 0] < w) & (p[:, 1] >= 0) & (p[:, 1] < h)
        z = np.full(len(p), np.nan)
        z[ok] = depth_in_metres(depth[p[ok, 1], p[ok, 0]], units)
        return points, z

    (pc, zc), (pe, ze) = at(centres), at(edges)
    good = np.isfinite(zc)
    if good.sum() < 6:
        return float("nan"), float("nan")
    A = np.column_stack([pc[good], np.ones(good.sum())])
    coef = np.linalg.lstsq(A, 1.0 / zc[good], rcond=None)[0]
    for _ in range(2):   # refit without the centres far off the plane (invalid or flying pixels)
        res = np.abs(1.0 / (A @ coef) - zc[good])
        keep = res <= 3 * np.median(res) + 1e-6
        coef = np.linalg.lstsq(A[keep], 1.0 / zc[good][keep], rcond=None)[0]
    plane_c = 1.0 / (A @ coef)
    e_ok = np.isfinite(ze)
    plane_e = 1.0 / (np.column_stack([pe[e_ok], np.ones(e_ok.sum())]) @ coef)
    return float(np.median(np.abs(ze[e_ok] - plane_e))), float(np.median(np.abs(zc[good] - plane_c)))
