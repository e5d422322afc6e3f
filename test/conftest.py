"""Shared test fixtures: the real Kinect v2 recordings in ../shared, when present. The tests that
start ROS processes are in ros/, with their fixtures."""
from __future__ import annotations

from pathlib import Path

import pytest

KINECT_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "kinect_v2_tof"


@pytest.fixture(scope="session")
def kinect_dir() -> Path:
    if not KINECT_DIR.is_dir():
        pytest.skip(f"real Kinect v2 data not found at {KINECT_DIR} (the shared/ folder beside the checkout)")
    return KINECT_DIR
