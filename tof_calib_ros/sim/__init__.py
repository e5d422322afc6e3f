"""A synthetic time-of-flight camera looking at the calibration checkerboard.

Tests and demos need frames whose truth is known exactly: the corner pixels, the corner depths
and the board pose. ``render`` draws the amplitude (IR) and depth images of a ``Board`` seen by a
plumb_bob or rational_polynomial camera by inverse mapping: every pixel (and every sub-sample,
for anti-aliasing) is traced back along its viewing ray to the board plane, so the geometry is
that of ``core.camera`` to rounding error and nothing is re-projected or resampled.

Pixel ``(u, v)`` is centred on image coordinate ``(u, v)``, as in OpenCV, so the corners that
``cv2.findChessboardCornersSB`` returns are directly comparable with ``Frame.corners``.

The simulator package: this renderer (numpy and OpenCV, importing ``core`` only),
``sim.recording``, which films scenes into bags for the offline tool (importing ``files`` for
the bag writer), and ``sim.bound``, the least error any calibration can make on a rendered scene
(its Cramér-Rao bound), which the benchmarks measure methods against. The ROS driver that
streams it is ``ros.sim_node``; nothing here imports rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np

from ..core import camera as cam
from ..core.board import Board
from ..core.errors import CalibrationError

RngLike = np.random.Generator | int | None
# ``render``'s scene unless told otherwise (``sim.bound`` describes the same scene): the white
# margin in squares, the far wall (m), the sub-samples a pixel side, and the albedos of the white
# squares, the black ones and the wall.
BORDER, BACKGROUND, SUPERSAMPLE, REFLECTIVITY = 1.0, 3.0, 4, (0.9, 0.1, 0.05)


@dataclass(frozen=True)
class SimCamera:
    """Intrinsics packed as in ``core.camera`` ([fx, fy, cx, cy, k1, k2, p1, p2, k3], and k4, k5,
    k6 for a rational lens) and the image size in pixels."""

    params: np.ndarray
    width: int
    height: int

    def __post_init__(self) -> None:
        p = np.asarray(self.params, dtype=float).ravel()
        if p.size not in (4 + cam.PLUMB_BOB, cam.N_INTRINSICS) or not np.all(np.isfinite(p)):
            raise CalibrationError(f"camera params must be {4 + cam.PLUMB_BOB} or {cam.N_INTRINSICS} finite numbers")
        if p[0] <= 0 or p[1] <= 0:
            raise CalibrationError("focal lengths must be positive")
        if int(self.width) < 2 or int(self.height) < 2:
            raise CalibrationError(
                f"image must be at least 2x2 pixels, got {self.width}x{self.height}")
        object.__setattr__(self, "params", p)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    @property
    def K(self) -> np.ndarray:
        return cam.split_intrinsics(self.params)[0]

    @property
    def D(self) -> np.ndarray:
        return cam.split_intrinsics(self.params)[1]

    @property
    def size(self) -> tuple[int, int]:
        """(width, height), the order OpenCV wants."""
        return (self.width, self.height)


def pmd_camera() -> SimCamera:
    """A PMD CamCube-like sensor (200x200, f = 284.4 px), with mild barrel distortion."""
    return SimCamera(np.array([284.4, 284.4, 100.0, 100.0, -0.1, 0.02, 0.0, 0.0, 0.0]), 200, 200)


def pico_flexx_camera() -> SimCamera:
    """A pmd pico flexx-like sensor (224x171, f = 212 px), with strong barrel distortion."""
    return SimCamera(np.array([212.0, 212.0, 111.3, 86.6, -0.25, 0.08, 0.0, 0.0, 0.0]), 224, 171)


def azure_kinect_camera() -> SimCamera:
    """An Azure Kinect NFOV-unbinned-like sensor (640x576), the large case for speed."""
    return SimCamera(np.array([504.0, 504.0, 320.0, 288.0, -0.08, 0.015, 0.0005, -0.0003, 0.0]),
                     640, 576)


@dataclass(frozen=True)
class Noise:
    """Sensor errors added to a rendered frame. All zero: a noiseless frame.

    ``depth`` is the depth standard deviation (m) of a white square 1 m away facing the camera;
    elsewhere it grows as sqrt(that amplitude / pixel amplitude), because ToF depth noise is
    shot noise, so dark squares and far or tilted boards are noisier. ``depth_const`` (m) is
    added in quadrature to every pixel (the paper's protocol: 10 mm white noise). ``offset`` (m)
    is a systematic bias (a Kinect v2 reads about +25 mm). The wiggling error is
    ``wiggle_amplitude * sin(2 pi r / wiggle_period + wiggle_phase)`` of the true radial distance
    ``r`` (the light's path, which the phase measures), carried into the frame's convention.
    ``invalid_fraction`` of pixels, drawn at random, lose their depth.
    ``amplitude`` is the amplitude standard deviation as a fraction of full scale. ``dark_offset``
    (m): dark surfaces read farther, by this much times (1 - albedo / white's), as real ToF
    cameras read the black squares (about 0.89 of it on a black square).
    """

    depth: float = 0.0
    depth_const: float = 0.0
    offset: float = 0.0
    wiggle_amplitude: float = 0.0
    wiggle_period: float = 0.5
    wiggle_phase: float = 0.0
    invalid_fraction: float = 0.0
    amplitude: float = 0.0
    dark_offset: float = 0.0

    def __post_init__(self) -> None:
        for name in ("depth", "depth_const", "wiggle_amplitude", "amplitude"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise CalibrationError(f"noise {name} must be a non-negative number, got {v}")
        if not (np.isfinite(self.wiggle_period) and self.wiggle_period > 0):
            raise CalibrationError(f"wiggle period must be positive, got {self.wiggle_period}")
        if not (0.0 <= self.invalid_fraction <= 1.0):
            raise CalibrationError(
                f"invalid fraction must be in [0, 1], got {self.invalid_fraction}")
        if not (np.isfinite(self.offset) and np.isfinite(self.wiggle_phase) and np.isfinite(self.dark_offset)):
            raise CalibrationError("noise offset, dark offset and wiggle phase must be finite")


@dataclass
class Frame:
    """One rendered frame and its exact truth.

    ``depth`` is what the sensor reports (float32 m, noisy, invalid pixels NaN or 0);
    ``depth_true`` is the noiseless float64 depth (with flying pixels, if rendered) so tests can
    measure the noise; ``coverage`` is the fraction of each pixel covered by the board.
    ``corners`` (N,2) and ``corner_depth`` (N,) are the true corner pixels and depths, in the
    board's corner order and the frame's depth convention.
    """

    amplitude: np.ndarray
    depth: np.ndarray
    corners: np.ndarray
    corner_depth: np.ndarray
    rvec: np.ndarray
    tvec: np.ndarray
    K: np.ndarray
    D: np.ndarray
    convention: str
    depth_true: np.ndarray = field(repr=False)
    coverage: np.ndarray = field(repr=False)


def _rng(rng: RngLike) -> np.random.Generator:
    # None means seed 0, not OS entropy: a forgotten seed must not make a test flaky.
    return np.random.default_rng(0 if rng is None else rng)


def _interp_axis(values: np.ndarray, pos: np.ndarray, axis: int) -> np.ndarray:
    """Linear interpolation of a regular grid along ``axis`` at index positions ``pos``,
    extrapolating linearly past the ends (sub-samples of edge pixels lie outside the centres)."""
    n = values.shape[axis]
    i0 = np.clip(np.floor(pos).astype(int), 0, n - 2)
    t = pos - i0
    a = np.take(values, i0, axis=axis)
    b = np.take(values, i0 + 1, axis=axis)
    shape = [1] * values.ndim
    shape[axis] = -1
    t = t.reshape(shape)
    return a + (b - a) * t


@lru_cache(maxsize=8)
def _centre_normalized(params_bytes: bytes, width: int, height: int) -> np.ndarray:
    """Normalised coordinates (H, W, 2) of every pixel centre, exact to 1e-9 px.

    ``undistort_normalized`` on every pixel of a 640x576 image takes most of a second, so it
    runs on a coarse grid; bilinear interpolation then starts a Newton polish on
    ``camera.project`` with a frozen finite-difference Jacobian (one projection per step).
    """
    params = np.frombuffer(params_bytes, dtype=float)
    step = 8
    gx = np.unique(np.r_[np.arange(0, width, step), width - 1]).astype(float)
    gy = np.unique(np.r_[np.arange(0, height, step), height - 1]).astype(float)
    GX, GY = np.meshgrid(gx, gy)
    coarse = cam.undistort_normalized(np.stack([GX.ravel(), GY.ravel()], 1), params)
    coarse = coarse.reshape(gy.size, gx.size, 2)
    u = np.arange(width, dtype=float)
    v = np.arange(height, dtype=float)
    xy = _interp_axis(_interp_axis(coarse, np.interp(u, gx, np.arange(gx.size)), 1),
                      np.interp(v, gy, np.arange(gy.size)), 0).reshape(-1, 2)
    U, V = np.meshgrid(u, v)
    target = np.stack([U.ravel(), V.ravel()], 1)

    def proj(p: np.ndarray) -> np.ndarray:
        return cam.project(np.column_stack([p, np.ones(len(p))]), params).pixels

    h = 1e-6
    f0 = proj(xy)
    jx = (proj(xy + [h, 0.0]) - f0) / h
    jy = (proj(xy + [0.0, h]) - f0) / h
    det = jx[:, 0] * jy[:, 1] - jy[:, 0] * jx[:, 1]
    err = f0 - target
    # past a fold the polish runs off to infinity: the exact path below then says so
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(30):
            if np.max(np.abs(err)) < 1e-9:
                break
            xy = xy - np.stack([(jy[:, 1] * err[:, 0] - jy[:, 0] * err[:, 1]) / det,
                                (-jx[:, 1] * err[:, 0] + jx[:, 0] * err[:, 1]) / det], 1)
            err = proj(xy) - target
        else:
            # Distortion too strong for the polish: fall back to the exact, slow path rather than
            # return rays that are off; where that finds none either, the lens folds inside the image
            xy = cam.undistort_normalized(target, params)
            off = np.linalg.norm(proj(xy) - target, axis=1)
            if not np.all(off < 1e-6):
                far = np.hypot(*(target[~(off < 1e-6)] - params[2:4]).T).min()
                raise CalibrationError(f"the lens folds back inside the {width}x{height} image: no ray reaches the "
                                       f"pixels {far:.0f} px and more from the principal point, as none of a real "
                                       "lens's would")
    out = xy.reshape(height, width, 2)
    out.setflags(write=False)
    return out


def _plane(rvec: np.ndarray, tvec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float).reshape(3, 1))
    return R, np.asarray(tvec, dtype=float).reshape(3)


def _intersect(x: np.ndarray, y: np.ndarray, R: np.ndarray, t: np.ndarray):
    """Ray (x, y, 1) / board plane: ray parameter s (= z of the hit), board-plane coordinates,
    and |n . d| for the incidence angle. s is NaN where the ray misses the front half-space."""
    n = R[:, 2]
    nd = n[0] * x + n[1] * y + n[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = float(n @ t) / nd
    s = np.where(np.isfinite(s) & (s > 0), s, np.nan)
    r1t = float(R[:, 0] @ t)
    r2t = float(R[:, 1] @ t)
    bx = s * (R[0, 0] * x + R[1, 0] * y + R[2, 0]) - r1t
    by = s * (R[0, 1] * x + R[1, 1] * y + R[2, 1]) - r2t
    return s, bx, by, np.abs(nd)


def render(camera: SimCamera, board: Board, rvec: np.ndarray, tvec: np.ndarray, *,
           convention: str = "z", noise: Noise | None = None, rng: RngLike = None,
           border: float = BORDER, background: float | None = BACKGROUND, flying_pixels: bool = True,
           supersample: int = SUPERSAMPLE, reflectivity: tuple[float, float, float] = REFLECTIVITY,
           gain: float = 0.6, dtype: type = np.uint16, invalid: float = np.nan,
           moving_to: tuple[np.ndarray, np.ndarray] | None = None) -> Frame:
    """Render the board at pose (rvec, tvec) (board frame -> camera frame, metres).

    ``moving_to``: the pose at the end of the exposure, for a board that moves while the frame
    is taken. A multi-phase ToF camera takes ``PHASES`` correlation samples one after another
    and computes amplitude and depth from all of them (``_demodulate``): the amplitude is
    blurred along the motion, and where a sample sees another surface or another brightness
    than the rest (the squares' edges, the board's outline) the depth is wrong, as on real
    sensors. The frame's truth (``corners``, ``rvec``, ``tvec``) is the mid-exposure pose.

    ``border``: white margin around the squares, in squares. ``background``: distance (m) of a
    frontal far wall, or None for no return (amplitude 0, depth invalid). ``reflectivity``:
    (white, black, wall) albedo. ``gain``: fraction of full scale a white square at 1 m facing
    the camera reaches (0.6 by default; about 0.05 mimics the Kinect's dark IR image, to
    exercise tone mapping). ``dtype``: uint16, uint8 or a float type (fraction of full scale).
    ``invalid``: the depth value of invalid pixels (NaN or 0). Depth is sampled at the pixel
    centre; with ``flying_pixels`` a pixel straddling the board's outer edge reads the
    coverage-weighted mean of the board and wall depths, like a real ToF mixed pixel.
    """
    conv = cam.check_convention(convention)
    noise = Noise() if noise is None else noise
    gen = _rng(rng)
    S = int(supersample)
    if S < 1:
        raise CalibrationError(f"supersample must be at least 1, got {supersample}")
    if not (np.isfinite(border) and border >= 0):
        raise CalibrationError(f"border must be a non-negative number of squares, got {border}")
    if background is not None and not (np.isfinite(background) and background > 0):
        raise CalibrationError(f"background must be a positive distance or None, got {background}")
    if not (np.isfinite(gain) and gain > 0):
        raise CalibrationError(f"gain must be positive, got {gain}")
    if not (np.isnan(invalid) or invalid == 0):
        raise CalibrationError(f"invalid depth must be NaN or 0, got {invalid}")
    if moving_to is None:
        amp, depth_true, cov, albedo = _surfaces(camera, board, rvec, tvec, conv, border, background,
                                                 flying_pixels, S, reflectivity)
        pose = (np.asarray(rvec, dtype=float).reshape(3), np.asarray(tvec, dtype=float).reshape(3))
    else:
        n = PHASES * INSTANTS
        instants = [_surfaces(camera, board, *between((rvec, tvec), moving_to, (k + 0.5) / n), conv, border,
                              background, flying_pixels, S, reflectivity) for k in range(n)]
        samples = [_integrate(instants[k * INSTANTS:(k + 1) * INSTANTS]) for k in range(PHASES)]
        amp, depth_true = _demodulate(samples)
        cov = np.mean([c for _, _, c, _ in samples], axis=0)
        albedo = np.mean([al for *_, al in samples], axis=0)
        pose = between((rvec, tvec), moving_to, 0.5)
    return _sense(camera, board, pose, conv, (amp, depth_true, cov, albedo), noise, gen, reflectivity[0], gain,
                  dtype, invalid)


def between(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray],
            t: float) -> tuple[np.ndarray, np.ndarray]:
    """The pose a fraction ``t`` of the way from a to b (rotation along the shortest arc)."""
    Ra, Rb = cv2.Rodrigues(np.asarray(a[0], dtype=float).reshape(3, 1))[0], \
        cv2.Rodrigues(np.asarray(b[0], dtype=float).reshape(3, 1))[0]
    step = cv2.Rodrigues(Ra.T @ Rb)[0].ravel() * t
    return (cv2.Rodrigues(Ra @ cv2.Rodrigues(step)[0])[0].ravel(),
            (1 - t) * np.asarray(a[1], dtype=float).reshape(3) + t * np.asarray(b[1], dtype=float).reshape(3))


# A multi-phase ToF camera: four correlation samples per frame, taken one after another, at a
# modulation frequency whose unambiguous range (c / 2f = 5 m) covers the scene. Each sample
# integrates the scene over its part of the exposure, rendered at INSTANTS moments.
PHASES = 4
INSTANTS = 2
UNAMBIGUOUS_RANGE_M = 5.0


def _integrate(instants: list[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    """One correlation sample's amplitude, depth, coverage and albedo from the moments it
    integrates: the depth is the amplitude-weighted phasor mean of what each moment saw."""
    amps = np.stack([a for a, *_ in instants])
    depths = np.stack([d for _, d, *_ in instants])
    seen = np.isfinite(depths)
    phasor = np.sum(np.where(seen, amps * np.exp(2j * np.pi * np.where(seen, depths, 0.0) / UNAMBIGUOUS_RANGE_M),
                             0.0), axis=0)
    depth = np.mod(np.angle(phasor), 2 * np.pi) * UNAMBIGUOUS_RANGE_M / (2 * np.pi)
    return (amps.mean(axis=0), np.where(seen.any(axis=0), depth, np.nan),
            np.mean([c for _, _, c, _ in instants], axis=0), np.mean([al for *_, al in instants], axis=0))


def _demodulate(samples: list[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude and depth from ``PHASES`` samples (amplitude, depth) taken at different times:
    sample k correlates a * cos(phi + k 2 pi / PHASES), phi = 2 pi d / range; the camera reads
    phi back from all of them, so a pixel whose samples disagree gets a depth no surface has."""
    amps = np.stack([a for a, *_ in samples])
    depths = np.stack([d for _, d, *_ in samples])
    seen = np.isfinite(depths)
    a = np.where(seen, amps, 0.0)
    phi = 2 * np.pi * np.where(seen, depths, 0.0) / UNAMBIGUOUS_RANGE_M
    shift = 2 * np.pi * np.arange(PHASES)[:, None, None] / PHASES
    c = a * np.cos(phi + shift)
    real = np.sum(c * np.cos(shift), axis=0)
    imag = -np.sum(c * np.sin(shift), axis=0)
    depth = np.mod(np.arctan2(imag, real), 2 * np.pi) * UNAMBIGUOUS_RANGE_M / (2 * np.pi)
    return amps.mean(axis=0), np.where(seen.any(axis=0), depth, np.nan)


def _surfaces(camera: SimCamera, board: Board, rvec: np.ndarray, tvec: np.ndarray, conv: str, border: float,
              background: float | None, flying_pixels: bool, S: int,
              reflectivity: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Noiseless amplitude (albedo * cos / r^2, anti-aliased), depth (NaN: no return), board
    coverage and albedo at the centre of each pixel at a pose."""
    refl_w, refl_b, refl_bg = (float(r) for r in reflectivity)
    R, t = _plane(rvec, tvec)
    W, H = camera.width, camera.height
    sq = board.square
    x_lo, x_hi = -sq * (1 + border), sq * (board.cols + border)
    y_lo, y_hi = -sq * (1 + border), sq * (board.rows + border)
    wall = np.inf if background is None else float(background)

    def shade(x, y):
        """Class (0 wall, 1 black, 2 white), ray parameter and amplitude
        (albedo * cos(incidence) / r^2) of rays (x, y, 1)."""
        s, bx, by, nd = _intersect(x, y, R, t)
        hit = (bx >= x_lo) & (bx <= x_hi) & (by >= y_lo) & (by <= y_hi) & (s < wall)
        squares = (bx >= -sq) & (bx < board.cols * sq) & (by >= -sq) & (by < board.rows * sq)
        white = board.is_white(bx, by) | ~squares
        cls = np.where(hit, np.where(white, 2, 1), 0).astype(np.int8)
        d2 = x * x + y * y + 1.0
        d3 = d2 * np.sqrt(d2)
        with np.errstate(invalid="ignore"):
            amp_board = np.where(white, refl_w, refl_b) * nd / (d3 * s * s)
        amp_wall = 0.0 if background is None else refl_bg / (d3 * wall * wall)
        return cls, s, np.where(hit, amp_board, amp_wall)

    # Pixel centres: exact rays, for the depth and for pixels that one surface fills.
    xy = _centre_normalized(camera.params.tobytes(), W, H)
    xc, yc = xy[..., 0], xy[..., 1]
    cls_c, s_c, amp = shade(xc, yc)
    hit_c = cls_c > 0
    cov = hit_c.astype(float)

    # Anti-aliasing only where a pixel's corners and centre do not all see the same surface
    # (square edges, the board outline): supersampling every pixel of a 640x576 image costs
    # most of a second, and elsewhere the sub-samples would only average a smooth falloff.
    # Sub-sample rays are bilinear between the pixel's corner rays, which are interpolated
    # from the exact centre rays (error ~1e-4 px at the worst corner).
    xy_k = _interp_axis(_interp_axis(xy, np.arange(W + 1) - 0.5, 1), np.arange(H + 1) - 0.5, 0)
    cls_k, _, _ = shade(xy_k[..., 0], xy_k[..., 1])
    c00, c01, c10, c11 = cls_k[:-1, :-1], cls_k[:-1, 1:], cls_k[1:, :-1], cls_k[1:, 1:]
    mixed = (c00 != cls_c) | (c01 != cls_c) | (c10 != cls_c) | (c11 != cls_c)
    # A board or square corner can poke into a pixel without reaching any of its corners; such a
    # pixel always touches a mixed one, so the mixed set is grown by one pixel.
    mixed = cv2.dilate(mixed.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    rows, cols = np.nonzero(mixed)
    if rows.size and S > 1:
        f = (np.arange(S) + 0.5) / S
        fy, fx = f[None, :, None, None], f[None, None, :, None]
        k00 = xy_k[rows, cols][:, None, None, :]
        k01 = xy_k[rows, cols + 1][:, None, None, :]
        k10 = xy_k[rows + 1, cols][:, None, None, :]
        k11 = xy_k[rows + 1, cols + 1][:, None, None, :]
        sub = ((1 - fy) * ((1 - fx) * k00 + fx * k01) + fy * ((1 - fx) * k10 + fx * k11))
        cls_s, _, amp_s = shade(sub[..., 0], sub[..., 1])
        amp[rows, cols] = amp_s.mean(axis=(1, 2))
        cov[rows, cols] = (cls_s > 0).mean(axis=(1, 2))

    # Depth at the pixel centre, in the frame's convention.
    scale = 1.0 if conv == "z" else np.sqrt(xc * xc + yc * yc + 1.0)
    board_depth = s_c * scale  # NaN where the ray misses the plane
    if background is None:
        depth_true = np.where(hit_c, board_depth, np.nan)
    else:
        wall_depth = wall * scale
        depth_true = np.where(hit_c, board_depth, wall_depth)
        if flying_pixels:
            mixed = (cov > 0) & (cov < 1) & np.isfinite(board_depth)
            depth_true = np.where(mixed, cov * board_depth + (1 - cov) * wall_depth, depth_true)
    albedo = np.choose(cls_c, [refl_bg, refl_b, refl_w])
    return amp, depth_true, cov, albedo


def _sense(camera: SimCamera, board: Board, pose: tuple[np.ndarray, np.ndarray], conv: str,
           surfaces: tuple[np.ndarray, ...], noise: Noise, gen: np.random.Generator,
           a_ref: float, gain: float, dtype: type, invalid: float) -> Frame:
    """The sensor's errors on the noiseless images (``_surfaces``), and the frame's truth at ``pose``.

    ``a_ref``: the amplitude of a white square 1 m away, facing the camera."""
    amp, depth_true, cov, albedo = surfaces
    H, W = amp.shape
    rvec, tvec = pose
    valid = np.isfinite(depth_true)
    # Draws happen in a fixed order so a seed always gives the same frame.
    depth = depth_true + noise.offset + noise.dark_offset * (1 - albedo / a_ref)
    if noise.wiggle_amplitude > 0:
        xy = _centre_normalized(camera.params.tobytes(), W, H)
        per_depth = np.sqrt(xy[..., 0] ** 2 + xy[..., 1] ** 2 + 1.0) if conv == "z" else 1.0   # r / depth
        depth = depth + noise.wiggle_amplitude * np.sin(
            2 * np.pi * depth_true * per_depth / noise.wiggle_period + noise.wiggle_phase) / per_depth
    if noise.depth > 0 or noise.depth_const > 0:
        sigma2 = noise.depth_const ** 2 + noise.depth ** 2 * a_ref / np.maximum(amp, 1e-9 * a_ref)
        depth = depth + gen.standard_normal((H, W)) * np.sqrt(sigma2)
    if noise.invalid_fraction > 0:
        valid &= gen.random((H, W)) >= noise.invalid_fraction
    depth = np.where(valid, depth, invalid).astype(np.float32)

    level = gain * amp / a_ref
    if noise.amplitude > 0:
        level = level + gen.standard_normal((H, W)) * noise.amplitude
    level = np.clip(level, 0.0, 1.0)
    dt = np.dtype(dtype)
    if dt.kind == "u":
        top = np.iinfo(dt).max
        amplitude = np.round(level * top).astype(dt)
    elif dt.kind == "f":
        amplitude = level.astype(dt)
    else:
        raise CalibrationError(f"amplitude dtype must be unsigned or float, got {dt}")

    X, _ = cam.transform(rvec, tvec, board.object_points())
    corners = cam.project(X, camera.params).pixels
    corner_depth, _ = cam.depth_of(X, conv)
    return Frame(amplitude=amplitude, depth=depth, corners=corners, corner_depth=corner_depth,
                 rvec=np.asarray(rvec, dtype=float).reshape(3).copy(), tvec=np.asarray(tvec, dtype=float).copy(),
                 K=camera.K, D=camera.D, convention=conv, depth_true=depth_true,
                 coverage=cov.astype(np.float32))


def in_view(camera: SimCamera, points: np.ndarray, margin_px: float = 0.0) -> bool:
    """True when all camera-frame points are in front of the camera and project at least
    ``margin_px`` inside the image. Points beyond the field of view are rejected even when the
    distortion polynomial folds them back into the image."""
    P = np.asarray(points, dtype=float)
    if np.any(P[:, 2] <= 0):
        return False
    W, H = camera.width, camera.height
    edge = np.array([[0, 0], [W - 1, 0], [0, H - 1], [W - 1, H - 1], [(W - 1) / 2, 0],
                     [(W - 1) / 2, H - 1], [0, (H - 1) / 2], [W - 1, (H - 1) / 2]])
    r_max = np.max(np.linalg.norm(cam.undistort_normalized(edge, camera.params), axis=1))
    if np.any(np.hypot(P[:, 0] / P[:, 2], P[:, 1] / P[:, 2]) > r_max):
        return False
    pix = cam.project(P, camera.params).pixels
    return bool(np.all((pix[:, 0] >= margin_px) & (pix[:, 0] <= W - 1 - margin_px)
                       & (pix[:, 1] >= margin_px) & (pix[:, 1] <= H - 1 - margin_px)))


def random_poses(camera: SimCamera, board: Board, n: int, rng: RngLike = None, *,
                 distance: tuple[float, float] = (0.5, 1.5), max_tilt_deg: float = 40.0,
                 max_roll_deg: float = 10.0, margin_px: float = 5.0, view_border: float = 1.0,
                 max_tries: int = 2000) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` random board poses (rvec, tvec) with the whole pattern in view.

    The board centre lies at a uniformly drawn pixel, its z uniform in ``distance`` (m); the
    tilt (angle between board normal and optical axis) is uniform in [0, ``max_tilt_deg``] about
    a random in-plane axis, and the in-plane rotation is uniform within +-``max_roll_deg``.
    Poses are kept only when the board outline ``view_border`` squares beyond the interior
    corners (1: the outer squares' edges) is ``margin_px`` inside the image; ``max_tries``
    rejections per pose are allowed before the request is declared impossible.
    """
    gen = _rng(rng)
    lo, hi = (float(d) for d in distance)
    if not (0 < lo <= hi):
        raise CalibrationError(f"distance range must be positive and ordered, got {distance}")
    if not (0 <= max_tilt_deg < 90):
        raise CalibrationError(f"max tilt must be in [0, 90) degrees, got {max_tilt_deg}")
    outline = board.outline(view_border)
    centre = np.array([(board.cols - 1) / 2 * board.square, (board.rows - 1) / 2 * board.square, 0])
    W, H = camera.width, camera.height
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    for _ in range(int(n)):
        for _ in range(max_tries):
            tilt = np.radians(gen.uniform(0.0, max_tilt_deg))
            phi = gen.uniform(0.0, 2 * np.pi)
            roll = np.radians(gen.uniform(-max_roll_deg, max_roll_deg))
            Rt, _ = cv2.Rodrigues(np.array([np.cos(phi), np.sin(phi), 0.0]) * tilt)
            Rr, _ = cv2.Rodrigues(np.array([0.0, 0.0, roll]))
            R = Rt @ Rr
            target = np.array([[gen.uniform(0, W - 1), gen.uniform(0, H - 1)]])
            z = gen.uniform(lo, hi)
            tvec = cam.rays(target, camera.params)[0] * z - R @ centre
            rvec = cv2.Rodrigues(R)[0].ravel()
            if in_view(camera, outline @ R.T + tvec, margin_px):
                poses.append((rvec, tvec))
                break
        else:
            raise CalibrationError(
                f"no pose with the whole board in view after {max_tries} tries: the board is too "
                f"large for distances {distance} or the tilt/margin too demanding")
    return poses
