"""The view collector against rendered streams: what it keeps, what it rejects and why."""
import cv2
import numpy as np
import pytest

from tof_calib_ros import Board, calibrate, sim, tracking
from tof_calib_ros.collector import AXES, CollectorConfig, ViewCollector
from tof_calib_ros.core.camera import rays

BOARD = Board(8, 6, 0.04)
CAM = sim.pmd_camera()
NOISE = sim.Noise(depth=0.003, amplitude=0.003)
CENTRE = np.array([(BOARD.cols - 1) / 2, (BOARD.rows - 1) / 2, 0.0]) * BOARD.square
# Board centre pixel, distance (m), tilt (deg) and tilt axis: across X, Y, size and tilt.
SWEEP = [((100, 100), 0.60, 0, (1, 0)), ((70, 75), 0.85, 0, (1, 0)), ((130, 75), 0.85, 0, (1, 0)),
         ((70, 125), 0.85, 0, (1, 0)), ((130, 125), 0.85, 0, (1, 0)), ((100, 100), 0.60, 35, (1, 0)),
         ((100, 100), 0.60, 35, (0, 1)), ((100, 100), 0.50, 0, (1, 0))]


def _pose(pixel, z, tilt_deg=0.0, axis=(1, 0)):
    R = cv2.Rodrigues(np.array([*axis, 0.0]) * np.radians(tilt_deg))[0]
    tvec = rays(np.array([pixel], float), CAM.params)[0] * z - R @ CENTRE
    return cv2.Rodrigues(R)[0].ravel(), tvec


def _frame(pose, seed):
    return sim.render(CAM, BOARD, *pose, noise=NOISE, rng=seed)


def _feed(col, frames, t0=0.0, dt=0.1):
    return [col.add(f.amplitude, f.depth, t0 + i * dt) for i, f in enumerate(frames)]


@pytest.fixture(scope="module")
def sweep_frames():
    """Each sweep pose held still for two frames (different noise), as a user would."""
    return [_frame(_pose(*p), seed=10 * i + k) for i, p in enumerate(SWEEP) for k in range(2)]


def test_a_static_board_gives_exactly_one_view():
    frames = [_frame(_pose((100, 100), 0.7, 20), seed=i) for i in range(8)]
    col = ViewCollector(BOARD)
    out = _feed(col, frames)
    assert [o.accepted for o in out] == [False, True] + [False] * 6
    assert "still" in out[0].reason
    assert all("too similar" in o.reason for o in out[2:])
    assert len(col.views) == 1


def test_a_sweep_adds_views_and_progress_only_rises(sweep_frames):
    col = ViewCollector(BOARD)
    history = []
    for i, f in enumerate(sweep_frames):
        col.add(f.amplitude, f.depth, 0.1 * i)
        history.append([col.progress()["axes"][a]["progress"] for a in AXES])
    history = np.array(history)
    assert len(col.views) >= 6
    assert np.all(np.diff(history, axis=0) >= 0)
    for a in ("x", "y", "size", "tilt"):
        assert history[-1, AXES.index(a)] > 0.3, a
    p = col.progress()
    assert p["frames"] == len(sweep_frames) and p["views"] == len(col.views)
    assert not p["good_enough"]  # 8 poses at 0.5..0.85 m: too few views, too little depth range


def test_tilt_is_measured_from_the_depth():
    still = [_frame(_pose((100, 100), 0.6, 35, (0, 1)), seed=s) for s in (1, 2)]
    out = _feed(ViewCollector(BOARD), still)
    assert out[1].accepted
    assert out[1].params[AXES.index("tilt")] * 60 == pytest.approx(35, abs=2)


def test_a_moving_board_is_rejected():
    frames = [_frame(_pose((100, 100), 0.7), seed=s) for s in (1, 2)]
    frames.append(_frame(_pose((105, 100), 0.7), seed=3))
    out = _feed(ViewCollector(BOARD), frames)
    assert out[1].accepted
    assert not out[2].accepted and out[2].reason.startswith("board moving")


def test_a_long_gap_breaks_the_stillness_check():
    f = _frame(_pose((100, 100), 0.7), seed=1)
    col = ViewCollector(BOARD)
    col.add(f.amplitude, f.depth, 0.0)
    out = col.add(f.amplitude, f.depth, 5.0)
    assert not out.accepted and "cannot tell whether the board is still" in out.reason


def test_frames_without_a_board_are_rejected_with_the_reason():
    col = ViewCollector(BOARD)
    blank = col.add(np.zeros((200, 200), np.uint16), np.full((200, 200), np.nan, np.float32), 0.0)
    assert not blank.accepted and "constant" in blank.reason and blank.params is None
    away = sim.render(CAM, BOARD, np.zeros(3), np.array([5.0, 0.0, 0.6]), noise=NOISE, rng=1)
    out = col.add(away.amplitude, away.depth, 0.1)
    assert not out.accepted and "no 8x6 board found" in out.reason
    assert col.progress()["last_reason"] == out.reason and col.progress()["frames"] == 2


def test_a_board_at_the_image_border_is_partial():
    f = _frame(_pose((100, 100), 0.7), seed=1)
    col = ViewCollector(BOARD, CollectorConfig(border_px=60))  # a wide margin puts the board in it
    out = col.add(f.amplitude, f.depth, 0.0)
    assert not out.accepted and out.reason.startswith("partial board") and out.corners is not None


def test_no_depth_on_the_board_is_rejected():
    f = _frame(_pose((100, 100), 0.7), seed=1)
    out = ViewCollector(BOARD).add(f.amplitude, np.full_like(f.depth, np.nan), 0.0)
    assert not out.accepted and out.reason.startswith("no valid depth on the board")


def test_max_views_and_reset(sweep_frames):
    col = ViewCollector(BOARD, CollectorConfig(max_views=3))
    out = _feed(col, sweep_frames)
    assert len(col.views) == 3 and sum(o.accepted for o in out) == 3
    assert any("view limit reached (3 views kept)" in o.reason for o in out)
    col.reset()
    p = col.progress()
    assert col.views == [] and p["views"] == 0 and p["frames"] == 0
    assert all(a["progress"] == 0 for a in p["axes"].values())


def test_another_image_size_is_rejected_until_reset(sweep_frames):
    col = ViewCollector(BOARD)
    _feed(col, sweep_frames[:2])
    out = col.add(np.zeros((100, 120), np.uint16), np.zeros((100, 120), np.float32), 1.0)
    assert not out.accepted and "120x100" in out.reason and "reset" in out.reason


def test_memory_is_bounded_and_views_are_copies(sweep_frames, monkeypatch):
    cache, detect = {}, tracking.detect

    def cached_detect(image, board, **options):  # the same few images 500 times: detect each once
        key = (image.tobytes(), image.shape, tuple(sorted(options.items())))
        if key not in cache:
            cache[key] = detect(image, board, **options)
        return cache[key]

    monkeypatch.setattr(tracking, "detect", cached_detect)
    frames = sweep_frames[:10]  # 5 poses
    col = ViewCollector(BOARD)
    for i in range(500):
        f = frames[(i // 50) * 2 % 10 + i % 2]  # each pose for 50 frames, alternating two noise draws
        amp, depth = f.amplitude.copy(), f.depth.copy()
        out = col.add(amp, depth, 0.1 * i)
        if out.accepted:
            amp[:] = 0
            depth[:] = 9.0
            out.corners[:] = 0
    assert 1 <= len(col.views) <= 5
    assert col.progress()["frames"] == 500
    for v in col.views:
        src = next(f for f in frames if np.array_equal(f.amplitude, v.amplitude))
        np.testing.assert_array_equal(v.depth, src.depth)
        assert v.corners.min() > 0 and v.depth.dtype == np.float32 and v.amplitude.dtype == np.uint16


def test_collected_views_calibrate_the_camera():
    rng = np.random.default_rng(7)
    poses = sim.random_poses(CAM, BOARD, 30, rng, distance=(0.5, 1.0), max_tilt_deg=40)
    noise = sim.Noise(depth=0.003, amplitude=0.003, offset=0.02)
    frames = [sim.render(CAM, BOARD, r, t, noise=noise, rng=int(rng.integers(1 << 31)))
              for r, t in poses for _ in range(2)]
    col = ViewCollector(BOARD)
    _feed(col, frames, dt=1 / 30)
    assert len(col.views) >= 15
    res = calibrate(col.views, BOARD)
    assert res.K[0, 0] == pytest.approx(CAM.params[0], rel=0.01)


def test_kept_views_hold_the_accurate_corners():
    from tof_calib_ros.core.detection import detect_corners

    rng = np.random.default_rng(12)
    (rvec, tvec), = sim.random_poses(CAM, BOARD, 1, rng, distance=(0.6, 0.7), max_tilt_deg=20)
    frame = sim.render(CAM, BOARD, rvec, tvec, rng=rng, gain=0.2)
    col = ViewCollector(BOARD)
    col.add(frame.amplitude, frame.depth, 0.0)
    assert col.add(frame.amplitude, frame.depth, 0.05).accepted

    def rms(corners):   # against the rendered truth
        return float(np.sqrt(np.mean(np.sum((corners - frame.corners) ** 2, axis=1))))

    # found in the region around the quick corners: as accurate as the whole image's, or more
    kept, whole = rms(col.views[0].corners), rms(detect_corners(frame.amplitude, BOARD))
    assert kept < 0.1 and kept <= 1.1 * whole, (kept, whole)
