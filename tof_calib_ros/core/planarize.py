"""Depth planarization: the paper's denoising of the depth at each corner.

The white squares' depth is less noisy than the black squares' (more returned light), and
the board is a plane. So: segment the white squares from the detected corners (the outer
ones too, through the board homography), keep their inner part, drop invalid pixels and
pixels on a steep depth gradient (flying pixels), back-project them, find the outliers by
RANSAC + SVD (the paper's fit), fit the plane to the rest by least squares in depth (where the
noise is), and read each corner's depth where its viewing ray meets that plane.

Beyond the paper, ``squares="all"`` fits the plane to the whole board, each colour weighted
by its own noise: for sensors that read both colours at the same range. Real ToF cameras
often do not (a Kinect v2 reads its black squares 4 mm farther): the calibration chooses
(see pipeline).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from .board import Board
from .camera import project, rays, undistort_normalized
from .errors import CalibrationError

MIN_PLANE_PIXELS = 30
SQUARE_MARGIN = 0.15   # squares: how far the samples keep off a square's edges
MAX_BORDER = 2.0       # squares beyond the pattern's outline that a board's border is looked for in
BORDER_STEP = 0.1      # squares: the width of the rings it is looked for in
# of a ring's valid pixels, what must read as the board for the border to go on: the first ring,
# against the outer black squares, reads 2 % dark at 200x200 (0.98 cut a 1-square border to none)
BORDER_FILL = 0.95


@dataclass
class Plane:
    """A fitted board plane and the pixels it came from.

    The plane is ``coef . X = 1``: along a ray ``u`` (z = 1 for z-depth, unit length for
    radial depth) its depth is ``1 / (coef . u)``, linear in the coefficients, which is what
    makes a fit to depth residuals well posed."""

    coef: np.ndarray
    covariance: np.ndarray  # 3x3, of coef
    sigma: float            # std of the white-square inliers' depth about the plane, metres
    pixels: np.ndarray      # (M, 2) integer pixel coordinates (x, y) of the inliers
    inliers: np.ndarray     # bool, over the samples the plane was fitted to (RANSAC's outliers False)

    @property
    def normal(self) -> np.ndarray:
        """Unit normal, facing the camera."""
        return -self.coef / np.linalg.norm(self.coef)


def _board_points(shape: tuple[int, int], corners: np.ndarray, ids: np.ndarray, board: Board, params: np.ndarray,
                  reach: float) -> tuple[np.ndarray, np.ndarray]:
    """(M, 2) integer pixels (x, y) about the board, out to ``reach`` squares beyond the pattern's
    outline, and (M, 2) the board-plane point (metres) each sees. The board-to-image map is a
    homography on undistorted coordinates, so lens distortion is honoured."""
    if len(corners) < 4:
        raise CalibrationError("planarization needs at least 4 corners in a view")
    H = _board_homography(corners, ids, board, params)
    if H is None:
        raise CalibrationError("the corners of a view do not form a valid board (degenerate homography)")
    h, w = shape
    fx, fy, cx, cy = params[:4]
    on = cv2.perspectiveTransform(board.outline(1 + reach, per_edge=1)[None, :, :2], H)[0]
    # The bounding box of the outline, distortion-free, padded.
    px = np.column_stack([on[:, 0] * fx + cx, on[:, 1] * fy + cy])
    pad = 0.1 * (px.max(0) - px.min(0)) + 2
    x0, y0 = np.maximum(np.floor(px.min(0) - pad), 0).astype(int)
    x1, y1 = np.minimum(np.ceil(px.max(0) + pad), [w - 1, h - 1]).astype(int)
    if x1 <= x0 or y1 <= y0:
        return np.zeros((0, 2), dtype=int), np.zeros((0, 2))
    xs, ys = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1))
    grid = _normalized_grid(tuple(map(float, params)), h, w)
    on_board = cv2.perspectiveTransform(grid[(ys * w + xs).ravel()][None], np.linalg.inv(H))[0]
    return np.column_stack([xs.ravel(), ys.ravel()]), on_board


def square_pixels(shape: tuple[int, int], corners: np.ndarray, ids: np.ndarray, board: Board,
                  params: np.ndarray, margin: float, amplitude: np.ndarray | None,
                  squares: str = "white", border: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(M, 2) pixel coordinates (x, y) on the board and (M,) whether each is on a black square.

    ``squares="white"``: inside the white squares, ``margin`` squares off their edges;
    ``"all"``: anywhere on the squares, ``margin`` squares inside the pattern's outline.
    ``border``: the board's white border, from ``margin`` off the outline to ``border`` squares
    beyond it, is sampled too (as white). When the amplitude image is given, the brighter of the
    two square colourings is taken as white, which also covers boards whose colours are swapped
    by a 180 degree turn.
    """
    pix, points = _board_points(shape, corners, ids, board, params, border)
    bx, by = points.T
    white = board.is_white(bx, by, margin)
    turned = False
    if amplitude is not None:   # the squares labelled black, where the amplitude says they are white
        other = board.is_black(bx, by, margin)
        a = amplitude[pix[:, 1], pix[:, 0]].astype(float)
        if white.any() and other.any() and np.nanmedian(a[other]) > np.nanmedian(a[white]):
            white, turned = other, True
    rim = board.in_squared_area(bx, by, -border) & ~board.in_squared_area(bx, by, -margin)
    if squares == "white":
        white |= rim
        return pix[white], np.zeros(int(white.sum()), dtype=bool)
    on = board.in_squared_area(bx, by, margin)
    lit = board.is_black(bx[on], by[on]) if turned else board.is_white(bx[on], by[on])
    return np.concatenate([pix[on], pix[rim]]), np.r_[~lit, np.zeros(int(rim.sum()), dtype=bool)]


def border_reach(depth: np.ndarray, corners: np.ndarray, ids: np.ndarray, board: Board, params: np.ndarray,
                 plane: Plane, convention: str, amplitude: np.ndarray | None = None) -> float:
    """How far (squares) beyond the pattern's outline the view's board goes on, white and in its
    plane: the board's border, whose depth is the board's too (a 1-square border takes the
    samples twice as far from the board's centre, and near frontal it halved the 3D error of a
    quiet sensor). Ring by ring outward, as long as nearly all (``BORDER_FILL``) of a ring's
    valid pixels read the depth of the plane ``plane`` (fitted to the squares) within 4 of its
    sigmas and, given the amplitude, at least half the white squares' brightness: a board's
    edge, a hand on it or the wall behind ends it."""
    pix, points = _board_points(depth.shape, corners, ids, board, params, MAX_BORDER)
    if not len(pix):
        return 0.0
    u, v = points[:, 0] / board.square, points[:, 1] / board.square
    beyond = np.max([-1 - u, u - board.cols, -1 - v, v - board.rows], axis=0)   # squares beyond the outline
    d = depth[pix[:, 1], pix[:, 0]].astype(float)
    valid = np.isfinite(d) & (d > 0)
    expected = 1.0 / (directions(pix.astype(float), params, convention) @ plane.coef)
    board_like = valid & (np.abs(d - expected) < 4 * max(plane.sigma, 1e-4))
    if amplitude is not None:
        a = amplitude[pix[:, 1], pix[:, 0]].astype(float)
        lit = board.is_white(points[:, 0], points[:, 1], SQUARE_MARGIN)
        if lit.any():
            board_like &= a >= 0.5 * np.nanmedian(a[lit])
    reach = 0.0
    while reach < MAX_BORDER - 1e-9:
        ring = (beyond >= reach) & (beyond < reach + BORDER_STEP)
        seen = ring & valid
        if seen.sum() < max(8, 0.5 * ring.sum()) or board_like[seen].mean() < BORDER_FILL:
            break
        reach += BORDER_STEP
    return reach


def _board_homography(corners: np.ndarray, ids: np.ndarray, board: Board, params: np.ndarray) -> np.ndarray | None:
    """The board plane (metres) to the corners' coordinates undistorted by ``params``' lens: how
    the squares' pixels are found (None where the corners are degenerate)."""
    H, _ = cv2.findHomography(board.object_points(ids)[:, :2], undistort_normalized(corners, params), 0)
    return H


def squares_moved(corners: np.ndarray, ids: np.ndarray, board: Board, before: np.ndarray, after: np.ndarray,
                  shape: tuple[int, int]) -> float:
    """How far (in squares) the board point ``square_pixels`` sees at a pixel of the squared area
    moves from lens ``before`` to lens ``after``: beyond the samples' margin, the squares chosen
    through ``before`` take in their neighbours or the wall. Each lens maps the board through its
    own homography of the corners, so a lens that fits the corners moves nothing."""
    steps = 4   # points a square
    u, v = np.meshgrid(np.arange(-steps, board.cols * steps + 1), np.arange(-steps, board.rows * steps + 1))
    points = np.column_stack([u.ravel(), v.ravel()]) * board.square / steps
    H_after, H_before = (_board_homography(corners, ids, board, lens) for lens in (after, before))
    if H_after is None or H_before is None:
        return 0.0
    xy = cv2.perspectiveTransform(points[None], H_after)[0]
    pix = project(np.column_stack([xy, np.ones(len(xy))]), after).pixels
    h, w = shape
    seen = (pix[:, 0] >= 0) & (pix[:, 0] <= w - 1) & (pix[:, 1] >= 0) & (pix[:, 1] <= h - 1)
    if not seen.any():
        return 0.0
    back = cv2.perspectiveTransform(undistort_normalized(pix[seen], before)[None], np.linalg.inv(H_before))[0]
    moved = np.linalg.norm(back - points[seen], axis=1) / board.square
    return float(np.max(moved, initial=0.0, where=np.isfinite(moved)))


@lru_cache(maxsize=4)
def _normalized_grid(params: tuple[float, ...], h: int, w: int) -> np.ndarray:
    """Undistorted coordinates of every pixel, row-major: computed once for all views."""
    xs, ys = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    return undistort_normalized(np.column_stack([xs.ravel(), ys.ravel()]), np.array(params))


def _steep(depth: np.ndarray, pix: np.ndarray) -> np.ndarray:
    """Which of the pixels sit on a depth gradient far above the board's typical one: edges and
    flying pixels. The typical gradient is taken over these pixels only, not the background."""
    gy, gx = np.gradient(depth)
    g = np.hypot(gx, gy)[pix[:, 1], pix[:, 0]]
    finite = np.isfinite(g)
    if not finite.any():
        return np.ones(len(pix), dtype=bool)
    med = np.median(g[finite])
    mad = np.median(np.abs(g[finite] - med))
    # The floor (4 x the median) keeps a noiseless tilted plane, whose gradient barely varies.
    return ~finite | (g > 4 * med + 6 * 1.4826 * mad)


def ransac_inliers(points: np.ndarray, rng: np.random.Generator, iterations: int = 200) -> np.ndarray:
    """Points on the dominant plane: RANSAC over point triples, then SVD refits at 3 sigma (a
    consensus, which ``on_surface`` refines)."""
    n = len(points)
    normal, offset = svd_plane(points)
    d0 = points @ normal - offset
    tau = 3 * max(1.4826 * np.median(np.abs(d0 - np.median(d0))), 1e-9)
    tri = rng.integers(0, n, size=(iterations, 3))
    a, b, c = points[tri[:, 0]], points[tri[:, 1]], points[tri[:, 2]]
    normals = np.cross(b - a, c - a)
    lengths = np.linalg.norm(normals, axis=1)
    ok = lengths > 1e-12
    best = np.ones(n, dtype=bool)
    if ok.any():
        normals = normals[ok] / lengths[ok, None]
        dist = np.abs(points @ normals.T - np.einsum("ij,ij->i", a[ok], normals))
        counts = (dist < tau).sum(0)
        best = dist[:, np.argmax(counts)] < tau
        if best.sum() < 3:
            best = np.ones(n, dtype=bool)
    for _ in range(3):
        normal, offset = svd_plane(points[best])
        dist = points @ normal - offset
        sigma = max(1.4826 * np.median(np.abs(dist[best])), 1e-12)
        best = np.abs(dist) < 3 * sigma
    return best


def on_surface(directions: np.ndarray, depth: np.ndarray, start: np.ndarray, rounds: int = 3) -> np.ndarray:
    """The samples within 3 sigmas of a smooth surface through the ``start`` ones: the plane in
    depth plus a cubic over the rays, refitted ``rounds`` times. A cut about the plane meets a
    board that bows (a ToF wiggle's curvature) nearer its rim on one side and keeps that rim's
    noise on one side only: near frontal with the modulation frequency given and 2 mm of depth
    noise it put fx 1 px (4 of its sigmas) off. The surface is fitted over the rays, which are
    exact: fitted to the points in 3D, their own noise along the rays tilts it. One sigma for
    all trims the noisiest samples (the black squares' tails), on both sides alike."""
    cubic = _cubic(directions[:, 0] / directions[:, 2], directions[:, 1] / directions[:, 2])
    keep = start.copy()
    for _ in range(rounds):
        if keep.sum() <= cubic.shape[1]:
            return start
        coef = np.linalg.lstsq(directions[keep], 1.0 / depth[keep], rcond=None)[0]
        r = depth - 1.0 / (directions @ coef)
        r = r - cubic @ np.linalg.lstsq(cubic[keep], r[keep], rcond=None)[0]
        keep = np.abs(r) < 3 * max(1.4826 * np.median(np.abs(r[keep])), 1e-12)
    return keep


def _cubic(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(N, 10) the monomials of a cubic in two coordinates: a board's smooth bow over its rays."""
    return np.column_stack([x ** i * y ** j for i in range(4) for j in range(4 - i)])


def svd_plane(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Total least squares plane (unit normal, offset): geometric, for the outlier search and
    rough tilts only (the fit is in depth, where the noise is)."""
    centroid = points.mean(0)
    q = points - centroid
    normal = np.linalg.eigh(q.T @ q)[1][:, 0]
    return normal, float(normal @ centroid)


@dataclass
class DepthSamples:
    """One view's board pixels with usable depth: chosen once, re-fitted as K changes."""

    pixels: np.ndarray   # (M, 2) float pixel coordinates (x, y)
    depth: np.ndarray    # (M,) metres, measured
    black: np.ndarray    # (M,) bool: on a black square (only with squares="all")

    def subset(self, keep: np.ndarray) -> DepthSamples:
        return DepthSamples(self.pixels[keep], self.depth[keep], self.black[keep])


def board_samples(depth: np.ndarray, corners: np.ndarray, ids: np.ndarray, board: Board, params: np.ndarray,
                  amplitude: np.ndarray | None = None, margin: float = SQUARE_MARGIN, squares: str = "white",
                  border: float = 0.0) -> DepthSamples:
    """The squares' pixels (and the border's, to ``border`` squares beyond the outline) that are
    valid (not 0 or NaN) and not on a depth step."""
    pix, black = square_pixels(depth.shape, corners, ids, board, params, margin, amplitude, squares, border)
    if len(pix):
        d = depth[pix[:, 1], pix[:, 0]]
        keep = np.isfinite(d) & (d > 0) & ~_steep(depth, pix)
        pix, d, black = pix[keep], d[keep], black[keep]
    if np.sum(~black) < MIN_PLANE_PIXELS:
        raise CalibrationError(
            f"only {np.sum(~black)} valid depth pixels on the white squares (need {MIN_PLANE_PIXELS}): "
            "depth invalid (0 or NaN) over the board, or the board is too small in the image")
    return DepthSamples(pix.astype(float), d.astype(float), black)


def directions(pixels: np.ndarray, params: np.ndarray, convention: str) -> np.ndarray:
    """Rays scaled so that the point at depth d is d times the ray."""
    r = rays(pixels, params)
    return r if convention == "z" else r / np.linalg.norm(r, axis=1, keepdims=True)


def _fit_depth_plane(u: np.ndarray, depth: np.ndarray, black: np.ndarray,
                     iterations: int = 5) -> tuple[np.ndarray, np.ndarray, float]:
    """Least squares in depth (ToF noise is along the ray, not isotropic as a 3D fit assumes):
    Gauss-Newton on depth - 1 / (coef . u), started from the linear fit of 1 / depth. Black
    squares, when sampled, return less light: each colour counts with its own noise, taken
    from its residuals at every step. Returns the white squares' noise."""
    A = u * (depth ** 2)[:, None]
    weighted = black.any()
    try:
        coef = np.linalg.solve(A.T @ A, A.T @ depth)  # 3 unknowns: normal equations are well posed
        for _ in range(iterations):
            s = u @ coef
            J = u / s[:, None] ** 2          # d(depth - 1/s)/d(coef)
            r = depth - 1.0 / s
            Jw = J / _colour_noise(r, black)[:, None] ** 2 if weighted else J
            step = np.linalg.solve(Jw.T @ J, -Jw.T @ r)
            coef = coef + step
            if np.linalg.norm(step) < 1e-12 * np.linalg.norm(coef):
                break
    except np.linalg.LinAlgError:   # rays all along one line: the intrinsics have diverged
        raise CalibrationError("a view's depth samples do not determine a plane (degenerate rays)") from None
    s = u @ coef
    r = depth - 1.0 / s
    J = u / s[:, None] ** 2
    sigma = _colour_noise(r, black)
    cov = np.linalg.pinv((J / sigma[:, None] ** 2).T @ J)
    return coef, cov, float(np.max(sigma, initial=0.0, where=~black))


def _colour_noise(r: np.ndarray, black: np.ndarray) -> np.ndarray:
    """Each sample's depth noise: its colour's residual RMS, less the plane's 3 degrees of
    freedom (shared by the colours in proportion to their counts)."""
    n = len(r)
    sigma = np.empty(n)
    for colour in (~black, black):
        m = int(colour.sum())
        if m:
            sigma[colour] = np.sqrt(r[colour] @ r[colour] / max(m * (n - 3) / n, 1))
    return np.maximum(sigma, 1e-15)


def fit_samples(samples: DepthSamples, params: np.ndarray, convention: str, seed: int = 0) -> Plane:
    """The board plane through the samples: RANSAC in 3D against outliers (flying pixels,
    multipath), then the least-squares fit in depth."""
    u = directions(samples.pixels, params, convention)
    inliers = on_surface(u, samples.depth, ransac_inliers(u * samples.depth[:, None], np.random.default_rng(seed)))
    plane = fit_plane_to(u[inliers], samples.depth[inliers], samples.pixels[inliers], samples.black[inliers])
    plane.inliers = inliers
    return plane


def fit_plane_to(directions: np.ndarray, depth: np.ndarray, pixels: np.ndarray, black: np.ndarray) -> Plane:
    """The least-squares plane in depth through samples along known directions (``black``:
    which lie on black squares)."""
    coef, cov, sigma = _fit_depth_plane(directions, depth, black)
    return Plane(coef, cov, sigma, pixels.astype(int), np.ones(len(depth), dtype=bool))


def off_plane(plane: Plane, directions: np.ndarray, depth: np.ndarray, black: np.ndarray,
              basis: np.ndarray, scatter: tuple[Plane, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """What the samples' depth off their fitted plane says of small depth terms (``basis`` (M, K),
    each term's depth at the samples) that curve across the board: the information (K, K) and
    the moment (K,) of the residuals' part the plane's three parameters cannot absorb, each
    sample weighted by its colour's noise. The terms' estimate from them is information^-1 moment.
    A plane keeps only a term's planar part; this is the rest, which near frontal is most of
    what the depth says of a wiggle. Noise shared between neighbouring pixels (a driver's
    smoothing filter) makes the samples worth fewer: both are divided by ``noise_spread``.
    ``scatter``: another plane and depth whose residuals give the noise instead."""
    r, J, w = _weighted_jacobian(plane, directions, depth, black)
    noise, _, w = (r, J, w) if scatter is None else _weighted_jacobian(scatter[0], directions, scatter[1], black)
    off = basis - J @ _plane_change(J, w, basis)
    offw = off * w[:, None] / noise_spread(plane.pixels, noise * np.sqrt(w))
    return offw.T @ off, offw.T @ r


def planar_part(plane: Plane, directions: np.ndarray, depth: np.ndarray, black: np.ndarray,
                basis: np.ndarray, at: np.ndarray) -> np.ndarray:
    """(N, K) how far the plane fitted to ``depth`` moves along the directions ``at`` when each
    term of ``basis`` (M, K) is added to the samples' depth: the part of a term a plane keeps.
    To first order (the fit's normal equations), which is exact for the millimetres a wiggle
    has and takes one solve instead of a refit per term."""
    _, J, w = _weighted_jacobian(plane, directions, depth, black)
    s = at @ plane.coef
    return (at / s[:, None] ** 2) @ _plane_change(J, w, basis)


def _weighted_jacobian(plane: Plane, directions: np.ndarray, depth: np.ndarray,
                       black: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The residuals of depth off the plane, their Jacobian in its coefficients and each sample's
    weight, as the plane fit has them at its solution."""
    s = directions @ plane.coef
    r = depth - 1.0 / s
    return r, directions / s[:, None] ** 2, 1 / _colour_noise(r, black) ** 2


def _plane_change(J: np.ndarray, w: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """(3, K) minus the change of the plane's coefficients when each term of ``basis`` is added
    to the depth (the weighted least-squares projection)."""
    Jw = J * w[:, None]
    return np.linalg.solve(Jw.T @ J, Jw.T @ basis)


def noise_spread(pixels: np.ndarray, noise: np.ndarray, lags: int = 3) -> float:
    """How many times its independent share the variance of a smooth fit to a pixel grid's
    ``noise`` is: the summed correlations of samples 1 to ``lags`` pixels apart, across and down
    (pooled), in each of the two directions, (1 + 2 sum rho)^2; 1 for independent noise, 9 for
    a 3 x 3 box filter's."""
    pixels = np.rint(pixels).astype(int)
    width = int(pixels[:, 0].max(initial=0)) + lags + 1
    keys = pixels[:, 1] * width + pixels[:, 0]
    order = np.argsort(keys)
    ranked = keys[order]
    total = 0.0
    for lag in range(1, lags + 1):
        num = den = 0.0
        for step in (lag, lag * width):
            at = np.minimum(np.searchsorted(ranked, keys + step), len(keys) - 1)
            hit = ranked[at] == keys + step
            a, b = noise[hit], noise[order[at[hit]]]
            num, den = num + a @ b, den + (a @ a + b @ b) / 2
        total += num / den if den > 0 else 0.0
    return max(1.0 + 2.0 * total, 1.0) ** 2


def smoothed(plane: Plane, directions: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """The samples' depth with their noise taken out and their curvature kept: the plane plus a
    cubic over the rays fitted to what it leaves. A term placed by the depth it reads (a wiggle,
    by the distance) is placed here: at each sample's own depth, the noise enters the term and
    biases what is fitted with it; at the plane's, the curvature it leaves out misplaces it."""
    fitted = 1.0 / (directions @ plane.coef)
    cubic = _cubic(directions[:, 0], directions[:, 1])
    return fitted + cubic @ np.linalg.lstsq(cubic, depth - fitted, rcond=None)[0]


def corner_depth(plane: Plane, corners: np.ndarray, params: np.ndarray,
                 convention: str) -> tuple[np.ndarray, np.ndarray]:
    """Each corner's depth where its ray meets the plane, and that depth's standard error."""
    return corner_depth_along(plane, directions(corners, params, convention))


def corner_depth_along(plane: Plane, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depth where the directions ``u`` meet the plane, and its standard error.

    The error is the fitted plane's own at that point, so it tells how much the denoised
    depth can be trusted, which the residuals of a smooth plane cannot."""
    s = u @ plane.coef
    g = u / s[:, None] ** 2
    se = np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", g, plane.covariance, g), 0.0))
    return 1.0 / s, se


def planarize(depth: np.ndarray, corners: np.ndarray, ids: np.ndarray, board: Board, params: np.ndarray,
              convention: str, amplitude: np.ndarray | None = None, margin: float = 0.15,
              seed: int = 0, squares: str = "white") -> tuple[np.ndarray, Plane]:
    """Denoised depth at each corner (metres, the given convention) and the fitted plane."""
    samples = board_samples(depth, corners, ids, board, params, amplitude, margin, squares)
    plane = fit_samples(samples, params, convention, seed)
    return corner_depth(plane, corners, params, convention)[0], plane


def sample_depth(depth: np.ndarray, corners: np.ndarray, radius: int = 1) -> np.ndarray:
    """Raw depth at each corner: the median of valid pixels in a small window (NaN if none)."""
    h, w = depth.shape
    c = np.rint(corners).astype(int)
    off = np.arange(-radius, radius + 1)
    xs = c[:, 0, None, None] + off[None, None, :]
    ys = c[:, 1, None, None] + off[None, :, None]
    inside = (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
    win = np.where(inside, depth[np.clip(ys, 0, h - 1), np.clip(xs, 0, w - 1)], np.nan).reshape(len(c), -1)
    win[~(np.isfinite(win) & (win > 0))] = np.nan
    # The median of each row's valid values (np.sort puts NaN last), a tenth of np.nanmedian's time.
    win.sort(axis=1)
    n = np.isfinite(win).sum(axis=1)
    rows = np.arange(len(c))
    upper, lower = win[rows, n // 2], win[rows, np.maximum(n - 1, 0) // 2]
    return np.where(n > 0, 0.5 * (upper + lower), np.nan)
