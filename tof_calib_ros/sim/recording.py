"""A recording of the simulated ToF camera in a bag, with its ground truth in a sidecar file:
for demos, tests and bug reports, with no camera and no ROS.

Two ways to move the board. ``motion="hold"``: as a person who knows the tool moves it, held
still at a pose for ``hold`` frames, then carried to the next over ``transit`` frames.
``motion="continuous"``: as most people record, the board never stops: it enters the image from
the side (the first frames are partial), then sweeps from pose to pose, one every ``segment``
seconds, faster between poses than near them; each frame is exposed for ``exposure`` seconds
while the board moves, so the fast frames are blurred and their depth smeared as a multi-phase
ToF camera smears it (``sim.render(moving_to=...)``). ``lead_in`` frames without a board come
first in either mode. The truth file lists, per frame, whether the whole board is in view and by
how many pixels its corners moved during the exposure.

The scene is the one ``tof_sim_node`` publishes: the same renderer, noise, distances and tilts,
and a camera_info with the true intrinsics, a factory calibration 4 % off, or none.
"""
from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np

from .. import sim
from ..core.board import Board
from ..core.camera import project, transform
from ..core.errors import CalibrationError
from ..files.bag_io import BagWriter
from ..files.image_decode import DEPTH_ENCODINGS
from . import stream
from .stream import CAMERAS

CAMERA_INFO_MODES = ("factory", "true", "none")
MOTIONS = ("hold", "continuous")
TOPICS = {"amplitude": "/tof/amplitude/image_raw", "depth": "/tof/depth/image_raw",
          "camera_info": "/tof/camera_info"}
FRAME_ID = "tof_optical_frame"
START = 1_700_000_000.0   # stamp of the first frame, s


@dataclass(frozen=True)
class Scene:
    camera: str = "pmd"
    board: Board = field(default_factory=lambda: Board(5, 7, 0.03))
    frames: int = 400
    rate: float = 15.0
    hold: int = 8
    transit: int = 8
    motion: str = "hold"
    segment: float = 1.5
    exposure: float = 0.01
    lead_in: int = 0
    depth_convention: str = "z"
    depth_encoding: str = "16UC1"
    depth_offset: float = 0.02
    camera_info: str = "factory"
    seed: int = 0

    def __post_init__(self) -> None:
        checks = [
            (self.camera in CAMERAS, f"camera must be one of {', '.join(CAMERAS)}, not {self.camera!r}"),
            (self.frames >= 1, f"frames must be at least 1, not {self.frames}"),
            (self.rate > 0, f"rate must be positive, not {self.rate}"),
            (self.hold >= 1, f"hold must be at least 1 frame, not {self.hold}"),
            (self.transit >= 0, f"transit must not be negative, not {self.transit}"),
            (self.motion in MOTIONS, f"motion must be one of {', '.join(MOTIONS)}, not {self.motion!r}"),
            (self.segment > 0, f"segment must be positive seconds, not {self.segment}"),
            (0 <= self.exposure < 1 / self.rate if self.rate > 0 else False,
             f"exposure must be at least 0 and shorter than a frame (1/rate), not {self.exposure}"),
            (self.lead_in >= 0, f"lead_in must not be negative, not {self.lead_in}"),
            (self.depth_convention in ("z", "radial"),
             f"depth convention must be 'z' or 'radial', not {self.depth_convention!r}"),
            (self.depth_encoding in DEPTH_ENCODINGS,
             f"depth encoding must be one of {', '.join(DEPTH_ENCODINGS)}, not {self.depth_encoding!r}"),
            (self.camera_info in CAMERA_INFO_MODES,
             f"camera_info must be one of {', '.join(CAMERA_INFO_MODES)}, not {self.camera_info!r}"),
        ]
        for ok, reason in checks:
            if not ok:
                raise CalibrationError(reason)

    @property
    def sim_camera(self) -> sim.SimCamera:
        return CAMERAS[self.camera]()


# The board's outline this many squares beyond the outer corners, this many pixels inside the
# image, is "the whole board" in the truth file: the collector's own rule (EDGE_SQUARES, border_px).
WHOLE_EDGE_SQUARES = 0.5
WHOLE_MARGIN_PX = 2.0
# Continuous motion: the speed along a segment varies as 1 - SWEEP_VARIATION cos(2 pi s), never 0.
SWEEP_VARIATION = 0.7
Pose = tuple[np.ndarray, np.ndarray]


def _key_poses(scene: Scene, rng: np.random.Generator) -> list[Pose]:
    camera, board = scene.sim_camera, scene.board
    n = (scene.frames // (scene.hold + scene.transit) + 2 if scene.motion == "hold"
         else int(scene.frames / scene.rate / scene.segment) + 3)
    poses = stream.poses(camera, board, n, rng)
    if scene.motion == "continuous":   # the board comes in from the side: one field of view away
        rvec, tvec = poses[0]
        side = rng.choice([-1.0, 1.0]) * tvec[2] * camera.width / camera.K[0, 0]
        poses.insert(0, (rvec, tvec + np.array([side, 0.0, 0.0])))
    return poses


def _pose_at(scene: Scene, keys: list[Pose], t: float) -> Pose:
    """Continuous motion: the pose ``t`` seconds after the board started moving."""
    k, tau = divmod(t / scene.segment, 1.0)
    s = tau - SWEEP_VARIATION * np.sin(2 * np.pi * tau) / (2 * np.pi)
    return sim.between(keys[int(k)], keys[int(k) + 1], s)


def exposures(scene: Scene, rng: np.random.Generator) -> Iterator[tuple[Pose | None, Pose | None]]:
    """Per frame, the board's pose when the exposure starts and, if it moves, when it ends
    (None, None: no board in the frame)."""
    keys = _key_poses(scene, rng)
    period = scene.hold + scene.transit
    for i in range(scene.frames):
        if i < scene.lead_in:
            yield None, None
            continue
        j = i - scene.lead_in
        if scene.motion == "hold":
            k, phase = divmod(j, period)
            yield (keys[k] if phase < scene.hold else
                   sim.between(keys[k], keys[k + 1], (phase - scene.hold + 1) / (scene.transit + 1))), None
        else:
            t = j / scene.rate
            yield _pose_at(scene, keys, t), (_pose_at(scene, keys, t + scene.exposure) if scene.exposure > 0
                                             else None)


def render_frames(scene: Scene) -> Iterator[tuple[sim.Frame, dict]]:
    """The scene's frames in order, rendered one at a time, each with its truth: ``board`` is
    "whole", "partial" or "none", ``blur_px`` how far the corners moved during the exposure."""
    camera, board = scene.sim_camera, scene.board
    rng = np.random.default_rng(scene.seed)
    sensor = stream.noise(scene.depth_offset)
    outline = board.outline(WHOLE_EDGE_SQUARES)
    absent = (np.zeros(3), np.array([0.0, 0.0, 100.0]))   # far behind the wall: not seen
    for start, end in exposures(scene, rng):
        pose = absent if start is None else start
        frame = stream.frame(camera, board, pose, sensor, rng, scene.depth_convention, end)
        if start is None:
            truth = {"board": "none", "blur_px": 0.0}
        else:
            R = cv2.Rodrigues(frame.rvec)[0]
            points = board.object_points()
            whole = sim.in_view(camera, outline @ R.T + frame.tvec, WHOLE_MARGIN_PX)
            inside = (frame.corners >= 0) & (frame.corners <= [camera.width - 1, camera.height - 1])
            seen = bool(np.any(np.all(inside, axis=1)))   # a corner in the image, both coordinates
            blur = 0.0 if end is None else float(np.max(np.linalg.norm(
                _project(camera, end, points) - _project(camera, start, points), axis=1)))
            truth = {"board": "whole" if whole else "partial" if seen else "none", "blur_px": round(blur, 4)}
        yield frame, truth


def _project(camera: sim.SimCamera, pose: Pose, points: np.ndarray) -> np.ndarray:
    """Board points in the image at ``pose``, as the renderer's truth corners are projected."""
    return project(transform(*pose, points)[0], camera.params).pixels


def truth_path(bag: str | Path) -> Path:
    """Where the ground truth of a simulated bag is written: beside it, ``<bag>.truth.json``."""
    bag = Path(bag)
    return bag.with_name(bag.name + ".truth.json")


def published_K(scene: Scene) -> np.ndarray | None:
    """The camera_info's K: the truth, the factory's (focal lengths 4 % off) or none."""
    if scene.camera_info == "none":
        return None
    return stream.factory_K(scene.sim_camera) if scene.camera_info == "factory" else scene.sim_camera.K.copy()


def write_recording(path: str | Path, scene: Scene, storage: str = "sqlite3",
                    frames: Iterable[tuple[sim.Frame, dict]] | None = None,
                    progress: Callable[[int], None] | None = None) -> Path:
    """Write the scene's frames (rendered, or ``frames`` given, e.g. a few cycled for a long
    benchmark bag) to a new bag and its truth beside it; returns the truth file's path."""
    camera = scene.sim_camera
    K = published_K(scene)
    frames = render_frames(scene) if frames is None else frames
    written = 0
    per_frame = []
    with BagWriter(path, storage) as bag:
        for i, (frame, truth) in enumerate(frames):
            per_frame.append({"stamp": START + i / scene.rate, **truth})
            stamp = START + i / scene.rate
            depth = stream.encoded_depth(frame.depth, scene.depth_encoding)
            bag.write(TOPICS["amplitude"], bag.image_message(frame.amplitude, "mono16", stamp, FRAME_ID), stamp)
            bag.write(TOPICS["depth"], bag.image_message(depth, scene.depth_encoding, stamp, FRAME_ID), stamp)
            if K is not None:
                bag.write(TOPICS["camera_info"], bag.camera_info_message(K, np.zeros(5), camera.size, stamp,
                                                                         FRAME_ID), stamp)
            written += 1
            if progress:
                progress(written)
    b = scene.board
    truth = {
        "image_width": camera.width, "image_height": camera.height,
        "camera_matrix": camera.K.tolist(), "distortion_coefficients": camera.D.tolist(),
        "depth_offset_m": scene.depth_offset, "depth_convention": scene.depth_convention,
        "depth_encoding": scene.depth_encoding,
        "board": {"cols": b.cols, "rows": b.rows, "square_m": b.square},
        "camera_info": {"mode": scene.camera_info, "camera_matrix": None if K is None else K.tolist()},
        "topics": TOPICS if K is not None else {k: v for k, v in TOPICS.items() if k != "camera_info"},
        "frames": written, "storage": storage, "per_frame": per_frame,
        "scene": {k: v for k, v in asdict(scene).items() if k not in ("board", "frames")},
    }
    out = truth_path(path)
    out.write_text(json.dumps(truth, indent=1) + "\n")
    return out
