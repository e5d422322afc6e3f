"""Shared test fixtures: the real Kinect v2 recordings in ../shared, when present. The tests that
start ROS processes are in ros/, with their fixtures."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

KINECT_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "kinect_v2_tof"


@pytest.fixture(scope="session")
def kinect_dir() -> Path:
    if not KINECT_DIR.is_dir():
        pytest.skip(f"real Kinect v2 data not found at {KINECT_DIR} (the shared/ folder beside the checkout)")
    return KINECT_DIR


@pytest.fixture
def four_corner_views():
    """Three near-frontal views of an 8x6 board of 40 mm, four corners each, where OpenCV refuses;
    the camera (f = 284.4) has no lens distortion, which four corners cannot tell from the focal
    length."""
    import numpy as np

    from tof_calib_ros import Board, View, sim

    board = Board(8, 6, 0.04)
    cam = sim.SimCamera(np.array([284.4, 284.4, 99.5, 99.5, 0, 0, 0, 0, 0]), 200, 200)
    rng = np.random.default_rng(2)
    ids = np.array([0, board.cols - 1, board.n_corners - board.cols, board.n_corners - 1])
    poses = sim.random_poses(cam, board, 3, rng, distance=(0.55, 0.9), max_tilt_deg=5)
    frames = [sim.render(cam, board, r, t, noise=sim.Noise(depth_const=0.01), rng=rng) for r, t in poses]
    return [View(f.depth, f.corners[ids] + rng.normal(0, 0.01, (4, 2)), ids) for f in frames]


# In CI nothing may be skipped: the real data and the ROS wheels are there, and a test skipped
# for want of them would leave the run green with that part of the product untested.
_skipped: list[str] = []


def pytest_collectreport(report: pytest.CollectReport) -> None:
    if report.skipped:
        _skipped.append(f"{report.nodeid}: {report.longrepr}")


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if report.skipped and not hasattr(report, "wasxfail"):
        _skipped.append(f"{report.nodeid}: {report.longrepr}")


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    if os.environ.get("CI") == "true" and _skipped and exitstatus == 0:
        reporter = session.config.pluginmanager.get_plugin("terminalreporter")
        for line in [f"{len(_skipped)} skipped, which CI does not allow:", *_skipped]:
            reporter.write_line(line)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
