"""A recording of the simulated ToF camera in a bag, with its ground truth in a sidecar file:
for demos, tests and bug reports, with no camera and no ROS.

The board moves as a person moves it for calibration: held still at a pose for ``hold`` frames,
then carried to the next over ``transit`` frames (the collector rejects those as moving). The
scene is the one ``tof_sim_node`` publishes: the same renderer, noise, distances and tilts, and
a camera_info with the true intrinsics, a factory calibration 4 % off, or none.
"""
from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np

from . import sim
from .bag_io import BagWriter
from .core.board import Board
from .core.errors import CalibrationError

CAMERAS = {"pmd": sim.pmd_camera, "azure": sim.azure_kinect_camera}
CAMERA_INFO_MODES = ("factory", "true", "none")
DEPTH_ENCODINGS = ("16UC1", "32FC1")
FACTORY_ERROR = 1.04   # the factory camera_info's focal length is 4 % off, as sim_node's
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


def _between(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray], t: float):
    """The pose a fraction ``t`` of the way from a to b (rotation along the shortest arc)."""
    Ra, Rb = cv2.Rodrigues(a[0])[0], cv2.Rodrigues(b[0])[0]
    step = cv2.Rodrigues(Ra.T @ Rb)[0].ravel() * t
    return cv2.Rodrigues(Ra @ cv2.Rodrigues(step)[0])[0].ravel(), (1 - t) * a[1] + t * b[1]


def render_frames(scene: Scene) -> Iterator[sim.Frame]:
    """The scene's frames in order, rendered one at a time."""
    camera, board = scene.sim_camera, scene.board
    rng = np.random.default_rng(scene.seed)
    noise = sim.Noise(depth=0.004, offset=scene.depth_offset, amplitude=0.002, invalid_fraction=0.002)
    f = camera.width / 200 * 0.4   # sim_node's distances: the board fills a similar part of the image
    period = scene.hold + scene.transit
    poses = sim.random_poses(camera, board, scene.frames // period + 2, rng, distance=(f, 2.2 * f),
                             max_tilt_deg=40)
    for i in range(scene.frames):
        k, phase = divmod(i, period)
        pose = poses[k] if phase < scene.hold else _between(poses[k], poses[k + 1],
                                                            (phase - scene.hold + 1) / (scene.transit + 1))
        yield sim.render(camera, board, *pose, convention=scene.depth_convention, noise=noise, rng=rng,
                         gain=0.3, background=3.0, invalid=0.0)


def truth_path(bag: str | Path) -> Path:
    """Where the ground truth of a simulated bag is written: beside it, ``<bag>.truth.json``."""
    bag = Path(bag)
    return bag.with_name(bag.name + ".truth.json")


def published_K(scene: Scene) -> np.ndarray | None:
    """The camera_info's K: the truth, the factory's (focal lengths 4 % off) or none."""
    if scene.camera_info == "none":
        return None
    K = scene.sim_camera.K.copy()
    if scene.camera_info == "factory":
        K[0, 0] *= FACTORY_ERROR
        K[1, 1] *= FACTORY_ERROR
    return K


def write_recording(path: str | Path, scene: Scene, storage: str = "sqlite3",
                    frames: Iterable[sim.Frame] | None = None,
                    progress: Callable[[int], None] | None = None) -> Path:
    """Write the scene's frames (rendered, or ``frames`` given, e.g. a few cycled for a long
    benchmark bag) to a new bag and its truth beside it; returns the truth file's path."""
    camera = scene.sim_camera
    K = published_K(scene)
    frames = render_frames(scene) if frames is None else frames
    written = 0
    with BagWriter(path, storage) as bag:
        for i, frame in enumerate(frames):
            stamp = START + i / scene.rate
            depth = np.nan_to_num(frame.depth, nan=0.0)
            depth = (np.clip(np.rint(depth * 1000), 0, 65535).astype(np.uint16) if scene.depth_encoding == "16UC1"
                     else depth.astype(np.float32))
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
        "frames": written, "storage": storage,
        "scene": {k: v for k, v in asdict(scene).items() if k not in ("board", "frames")},
    }
    out = truth_path(path)
    out.write_text(json.dumps(truth, indent=1) + "\n")
    return out
