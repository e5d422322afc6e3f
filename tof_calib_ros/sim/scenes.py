"""Scenes of sensors unlike the one the method was tuned on, shared by the tests and the
benchmarks so that both measure the same views."""
from __future__ import annotations

import numpy as np

from ..core import depth_bias
from ..core.board import Board
from . import Frame, Noise, pico_flexx_camera, random_poses, render

PICO_BOARD = Board(5, 7, 0.03)
PICO_MODULATION_HZ = 80e6


def pico_flexx(seed: int) -> list[Frame]:
    """Eight views of a 30 mm board 0.25-0.6 m from a pico flexx class camera, tilted up to 45
    degrees: a short wiggle (15 mm, the 0.47 m period of 80 MHz, its phase drawn), a 10 mm
    offset, black squares 3.6 mm farther (4 mm times 1 - their albedo over white's), and white
    squares that clip the amplitude, as they do at that distance at a usual exposure. Frames,
    not views, so that a caller can score the detected corners against the true ones."""
    camera = pico_flexx_camera()
    rng = np.random.default_rng(seed)
    noise = Noise(depth=0.004, offset=0.01, wiggle_amplitude=0.015,
                  wiggle_period=depth_bias.wiggle_period(PICO_MODULATION_HZ),
                  wiggle_phase=rng.uniform(0, 2 * np.pi), amplitude=0.01, dark_offset=0.004)
    poses = random_poses(camera, PICO_BOARD, 8, rng, distance=(0.25, 0.6), max_tilt_deg=45)
    return [render(camera, PICO_BOARD, *pose, noise=noise, rng=rng, invalid=0.0) for pose in poses]
