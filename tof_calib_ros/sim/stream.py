"""The simulated ToF camera as it streams, defined once: what ``tof_sim_node`` publishes, what a
simulated recording holds (``sim.recording``) and what the node's benchmark replays."""
from __future__ import annotations

import numpy as np

from ..core.board import Board
from . import Frame, Noise, SimCamera, azure_kinect_camera, pmd_camera, random_poses, render

CAMERAS = {"pmd": pmd_camera, "azure": azure_kinect_camera}
FACTORY_ERROR = 1.04   # the factory camera_info's focal lengths are 4 % off, as a miscalibrated driver's
Pose = tuple[np.ndarray, np.ndarray]


def factory_K(camera: SimCamera) -> np.ndarray:
    """The K a driver would publish before calibration."""
    K = camera.K.copy()
    K[0, 0] *= FACTORY_ERROR
    K[1, 1] *= FACTORY_ERROR
    return K


def noise(depth_offset: float) -> Noise:
    return Noise(depth=0.004, offset=depth_offset, amplitude=0.002, invalid_fraction=0.002)


def poses(camera: SimCamera, board: Board, n: int, rng: np.random.Generator) -> list[Pose]:
    """Board poses 0.4 to 0.88 m away for a 200 px wide image, farther in proportion to the width
    (1.28 to 2.8 m at 640 px): the wider ToF sensors are used farther out."""
    near = camera.width / 200 * 0.4
    return random_poses(camera, board, n, rng, distance=(near, 2.2 * near), max_tilt_deg=40)


def frame(camera: SimCamera, board: Board, pose: Pose, sensor: Noise, rng: np.random.Generator,
          convention: str = "z", moving_to: Pose | None = None) -> Frame:
    """A frame as the camera sends it: invalid depth as 0, as drivers do."""
    return render(camera, board, *pose, convention=convention, noise=sensor, rng=rng, gain=0.3, invalid=0.0,
                  moving_to=moving_to)


def encoded_depth(depth: np.ndarray, encoding: str) -> np.ndarray:
    """Depth in metres as the camera sends it (REP 118): 16UC1 millimetres or 32FC1 metres,
    0 where invalid."""
    metres = np.nan_to_num(depth, nan=0.0)
    if encoding == "16UC1":
        return np.clip(np.rint(metres * 1000), 0, 65535).astype(np.uint16)
    return metres.astype(np.float32)
