"""The view collector against rendered streams: what it keeps, what it rejects and why."""
import re
from dataclasses import dataclass

import cv2
import numpy as np
import pytest

from tof_calib_ros import Board, calibrate, sim
from tof_calib_ros.collect import collector, motion, replay, tracking
from tof_calib_ros.collect.collector import AXES, CollectorConfig, ViewCollector
from tof_calib_ros.core.camera import rays
from tof_calib_ros.core.detection import Detection

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
    # the first frame is sharp (its edges say so): no need to wait for a second one
    assert [o.accepted for o in out] == [True] + [False] * 7
    assert all("too similar" in o.reason for o in out[1:])
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
    assert not p["good_enough"]  # 8 poses at 0.5..0.85 m: too few views
    assert p["axes"]["depth"]["progress"] > 0.8   # 1.7:1 in distance, where 1.8:1 fills it
    # what is still short, the least covered first, says what to do about it
    least = sorted((a["progress"], name) for name, a in p["axes"].items())[:2]
    assert collector.still_short(p) == "; ".join(
        f"{collector.LABELS[name]} {share:.0%}: {collector.WHAT_TO_DO[name]}" for share, name in least), \
        collector.still_short(p)


@pytest.mark.parametrize("near, far, full", [(0.5, 0.95, True), (0.75, 1.4, True), (0.7, 1.1, False)])
def test_the_distance_axis_is_full_at_distances_1_8_to_1_apart(near, far, full):
    # the focal-length error a depth offset leaves goes with the ratio of the boards' distances:
    # a 1.8:1 ratio fills the axis near or far, a smaller one does not
    col = ViewCollector(BOARD)
    out = _feed(col, [_frame(_pose((100, 100), z), seed=i) for i, z in enumerate((near, far))], dt=2.0)
    assert all(o.accepted for o in out), [o.reason for o in out]
    progress = col.progress()["axes"]["depth"]["progress"]
    assert (progress == 1.0) == full, progress
    assert progress > 0.5


def test_a_board_filling_most_of_the_image_can_cover_x_and_y():
    # a wide board (8x6 corners, 146x114 px at 0.7 m in 200x200) slid from side to side and top
    # to bottom: camera_calibration's centre less half a square of its area spans 0.57 of X (0.7 fills it)
    col = ViewCollector(BOARD, CollectorConfig(stills=True))
    frames = [_frame(_pose((u, v), 0.7), seed=i) for i, (u, v) in
              enumerate((u, v) for u in range(70, 131, 12) for v in range(50, 151, 20))]
    out = _feed(col, frames)
    assert sum(o.accepted for o in out) >= 8
    axes = col.progress()["axes"]
    assert axes["x"]["progress"] == 1.0 and axes["y"]["progress"] == 1.0, axes


def test_tilt_is_measured_from_the_depth():
    still = [_frame(_pose((100, 100), 0.6, 35, (0, 1)), seed=s) for s in (1, 2)]
    out = _feed(ViewCollector(BOARD), still)
    assert out[0].accepted
    assert out[0].params[AXES.index("tilt")] * 60 == pytest.approx(35, abs=2)


def test_a_fast_board_is_rejected_by_its_speed_at_any_frame_rate():
    # 5 px between frames: 50 px/s at 10 frames/s blurs 0.25 px in the default 5 ms (a view), 500 px/s
    # at 100 frames/s 2.5 px (not a view), whatever each frame shows
    for dt, accepted in ((0.1, True), (1 / 100, False)):
        frames = [_frame(_pose((100 + 5 * k, 100), 0.7), seed=k) for k in range(3)]
        out = _feed(ViewCollector(BOARD), frames, dt=dt)
        assert out[0].accepted and out[2].accepted == accepted, (dt, out[2].reason)
        if not accepted:   # the fastest corner's speed (distortion stretches the board's edge)
            speed, blur = map(float, re.match(r"board moving: (\d+) px/s blurs it by ([\d.]+) px in a 5 ms exposure",
                                              out[2].reason).groups())
            assert 500 <= speed < 550 and blur == pytest.approx(speed / 200, abs=0.05)


def test_a_sharp_frame_after_a_long_gap_is_a_view():
    # a sparse recording (or a throttled stream): no speed to judge by, the frame itself is sharp
    col = ViewCollector(BOARD)
    first, later = _frame(_pose((100, 100), 0.7), seed=1), _frame(_pose((60, 70), 0.9, 20), seed=2)
    assert col.add(first.amplitude, first.depth, 0.0).accepted
    assert col.add(later.amplitude, later.depth, 5.0).accepted


def _moving(blur_px, seed, direction=(1.0, 0.0), pixel=(100, 100), z=0.7, closer=0.0, turn_deg=0.0):
    """A frame whose board slides ``blur_px`` pixels (at its centre) during the exposure, and
    comes ``closer`` metres nearer while turning ``turn_deg`` about the image's x axis."""
    start = _pose(pixel, z)
    end = _pose((pixel[0] + blur_px * direction[0], pixel[1] + blur_px * direction[1]), z - closer, turn_deg)
    return sim.render(CAM, BOARD, *start, noise=NOISE, rng=seed, moving_to=end)


def _blur(frame, sharp):
    across, _ = motion.edge_blur_px(frame.amplitude, frame.corners, BOARD)
    return np.sqrt(max(across ** 2 - sharp ** 2, 0.0))


def test_edge_widths_measure_the_blur_across_the_motion():
    still = _moving(0.0, 1)
    for pose in (((100, 100), 0.7, 0), ((60, 60), 0.9, 30), ((100, 100), 0.6, 35, (0, 1)), ((130, 80), 0.8, 25)):
        frame = _frame(_pose(*pose), seed=1)
        # sharp edges read 1 px wherever they fall on the pixels, in both directions, at any tilt
        assert motion.edge_blur_px(frame.amplitude, frame.corners, BOARD) == pytest.approx((1.0, 1.0), abs=0.1)
    _, sharp = motion.edge_blur_px(still.amplitude, still.corners, BOARD)
    assert _blur(still, sharp) < 0.5 and _blur(_moving(1.0, 2), sharp) < 1.0
    for direction in ((1.0, 0.0), (0.0, 1.0)):
        estimates = [_blur(_moving(b, 2, direction), sharp) for b in (2.0, 3.0, 4.0)]
        # measured on rendered frames: half to 0.8 of the blur, rising with it (an underestimate,
        # so that a sharp board is never taken for a blurred one)
        assert np.all(np.diff(estimates) > 0.5), estimates
        for b, e in zip((2.0, 3.0, 4.0), estimates):
            assert 0.5 * b < e < 1.05 * b, (direction, b, e)
        _, along = motion.edge_blur_px(_moving(4.0, 2, direction).amplitude, still.corners, BOARD)
        assert along < 1.1   # edges along the motion stay sharp


def test_a_blurred_still_is_refused_and_a_sharp_one_kept():
    col = ViewCollector(BOARD, CollectorConfig(stills=True))
    blurred = _moving(3.0, 3)
    out = col.add(blurred.amplitude, blurred.depth, 0.0)
    assert not out.accepted and out.reason.startswith("motion blur: the board's edges are"), out.reason
    sharp = _moving(0.3, 4)
    assert col.add(sharp.amplitude, sharp.depth, 1.0).accepted


def test_the_depth_on_a_moving_boards_edges_is_off_its_plane():
    # 3 cm nearer and 3 degrees turned in a 10 ms exposure: a quick wave of the board
    still, moved = _moving(0.0, 5), _moving(3.0, 5, closer=0.03, turn_deg=3.0)
    edges, centres = motion.edge_depth_error(still.depth, still.corners, BOARD)
    assert edges < 3 * centres + 0.002      # noise only: the edges are as near the plane as the centres
    edges, centres = motion.edge_depth_error(moved.depth, moved.corners, BOARD)
    assert edges > collector.ARTEFACT_MIN_M and edges > collector.ARTEFACT_RATIO * centres


def test_frames_without_a_board_are_rejected_with_the_reason():
    col = ViewCollector(BOARD)
    blank = col.add(np.zeros((200, 200), np.uint16), np.full((200, 200), np.nan, np.float32), 0.0)
    assert not blank.accepted and "constant" in blank.reason and blank.params is None
    away = sim.render(CAM, BOARD, np.zeros(3), np.array([5.0, 0.0, 0.6]), noise=NOISE, rng=1)
    out = col.add(away.amplitude, away.depth, 0.1)
    assert not out.accepted and "no 8x6 board found" in out.reason
    assert col.progress()["last_reason"] == out.reason and col.progress()["frames"] == 2


def test_a_lost_board_is_searched_by_the_detector_on_small_images_only(monkeypatch):
    """Offline (thorough), a lost board is searched for by ``detect`` too where the quick search
    misses boards held still (small images), not on larger ones, where the frames it misses are
    mostly of a moving board and ``detect`` took about 1 s each at 640x576."""
    searched = []
    monkeypatch.setattr(tracking, "detect", lambda image, board, **_: searched.append(image.shape)
                        or Detection(None, "no board"))
    for shape in ((170, 205), (576, 640)):
        gradient = np.zeros(shape, np.uint16) + np.arange(shape[1], dtype=np.uint16) * 50
        assert tracking.BoardTracker(BOARD).locate(gradient, thorough=True).corners is None
        assert tracking.BoardTracker(BOARD).locate(gradient, thorough=False).corners is None
    assert searched == [(170, 205)]


@pytest.mark.parametrize("cols, rows", [(3, 3), (4, 3), (7, 5), (11, 8)])
def test_a_corner_stuck_off_the_grid_is_never_followed(cols, rows):
    """Following a board checks that every corner lies on the grid a homography through all of
    them predicts, robustly (LMEDS), or a corner stuck on the wrong saddle would pass; the
    least-squares fit alone decides only where no stuck corner could hide in it (a corner
    displaced by e stands at least (1 - its leverage) e off that fit: checked here one by one)."""
    board = Board(cols, rows, 0.04)
    grid = tracking._grid(cols, rows)
    leverage = tracking._grid_leverage(cols, rows)
    rng = np.random.default_rng(cols * rows)
    for _ in range(200):
        square = rng.uniform(8, 40)
        H = np.diag([square, square, 1.0])
        H[:2, :2] = cv2.Rodrigues(np.array([0, 0, rng.uniform(-np.pi, np.pi)]))[0][:2, :2] * square
        H[:2, 2], H[2, :2] = rng.uniform(50, 300, 2), rng.uniform(-0.01, 0.01, 2)
        points = cv2.perspectiveTransform(grid[None], H)[0] + rng.normal(0, 0.05, (len(grid), 2))
        tolerance = tracking.FOLLOW_GRID_TOLERANCE * square
        assert tracking._grid_homography(board, points, tolerance) is not None
        stuck = points.copy()
        k = rng.choice(len(grid), rng.integers(1, 3), replace=False)
        direction = rng.normal(size=(len(k), 2))
        far = rng.uniform(1.1, 4, (len(k), 1)) * tolerance
        stuck[k] += direction / np.linalg.norm(direction, axis=1)[:, None] * far
        assert tracking._grid_homography(board, stuck, tolerance) is None
        one = points.copy()
        i = rng.integers(len(grid))
        one[i] += rng.normal(size=2)
        fit, _ = cv2.findHomography(grid, one, 0)
        moved = np.linalg.norm(one[i] - points[i])
        assert np.linalg.norm(cv2.perspectiveTransform(grid[None], fit)[0][i] - one[i]) >= (1 - leverage) * moved - 0.2


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
    col = ViewCollector(BOARD, CollectorConfig(max_views=3, min_views=3))
    history = []
    for i, f in enumerate(sweep_frames):
        col.add(f.amplitude, f.depth, 0.1 * i)
        history.append([col.progress()["axes"][a]["progress"] for a in AXES])
        assert len(col.views) <= 3
    assert len(col.views) == 3
    assert np.all(np.diff(history, axis=0) >= 0)   # a view that ends an axis is never replaced
    col.reset()
    p = col.progress()
    assert col.views == [] and p["views"] == 0 and p["frames"] == 0
    assert all(a["progress"] == 0 for a in p["axes"].values())


def test_enough_views_by_their_number_where_the_board_cannot_fill_the_size_axis():
    # A small board far away (1.3 to 2.6 m; as a 5x7 board on a wide-angle ToF camera, whose
    # depth fails before the board is near enough) never fills Size: as camera_calibration, 40
    # views are enough all the same, and fewer are not; a full set of fewer is enough too.
    frames = [_frame(pose, seed=i) for i, pose in
              enumerate(sim.random_poses(CAM, BOARD, 70, np.random.default_rng(3), distance=(1.3, 2.6)))]
    col = ViewCollector(BOARD, CollectorConfig(stills=True))
    good_at = []
    for i, f in enumerate(frames):
        col.add(f.amplitude, f.depth, float(i))
        good_at.append((len(col.views), col.progress()["good_enough"]))
    p = col.progress()
    assert p["views"] > collector.ENOUGH_VIEWS, p["views"]
    assert p["axes"]["size"]["progress"] < 0.8 and collector.still_short(p).startswith("Size"), p["axes"]
    assert all(good == (n >= collector.ENOUGH_VIEWS) for n, good in good_at), good_at
    full = ViewCollector(BOARD, CollectorConfig(stills=True, max_views=12))
    good_at = []
    for i, f in enumerate(frames[:20]):
        full.add(f.amplitude, f.depth, float(i))
        good_at.append((len(full), full.progress()["good_enough"]))
    assert all(good == (n == 12) for n, good in good_at) and good_at[-1] == (12, True), good_at


def test_a_full_set_swaps_its_most_redundant_view_for_a_new_one():
    # three views near one pose and one far: the fourth pose replaces one of the close three
    poses = [((100, 100), 0.7, 0), ((102, 100), 0.7, 0), ((100, 102), 0.7, 0), ((60, 60), 0.9, 30),
             ((130, 80), 0.8, 25)]
    frames = [_frame(_pose(*p), seed=i) for i, p in enumerate(poses)]
    col = ViewCollector(BOARD, CollectorConfig(max_views=4, min_views=4))
    out = _feed(col, frames, dt=1.0)
    assert all(o.accepted for o in out), [o.reason for o in out]
    assert out[-1].reason.startswith("accepted in place of a more redundant view")
    kept = {tuple(np.round(v.corners.mean(axis=0))) for v in col.views}
    assert len(col.views) == 4 and len(kept) == 4


def test_accurate_corners_are_found_for_the_views_kept_only_and_a_view_they_lose_is_dropped(monkeypatch):
    """Frames are judged by their quick corners; the accurate ones (tens of ms) are found when the
    views are read, so a view swapped out before then never costs them."""
    poses = [((100, 100), 0.7, 0), ((102, 100), 0.7, 0), ((100, 102), 0.7, 0), ((60, 60), 0.9, 30),
             ((130, 80), 0.8, 25)]
    frames = [_frame(_pose(*p), seed=i) for i, p in enumerate(poses)]
    looked_at = []

    def counted(amplitude, board, quick):
        looked_at.append(tracking.accurate_detect(amplitude, board, quick))
        return looked_at[-1]

    monkeypatch.setattr(collector, "accurate_detect", counted)
    col = ViewCollector(BOARD, CollectorConfig(max_views=4, min_views=4))
    out = _feed(col, frames, dt=1.0)
    assert all(o.accepted for o in out) and "in place of" in out[-1].reason and looked_at == []
    assert len(col) == 4 and len(col.unsharpened()) == 4
    views = col.views
    assert len(looked_at) == 4 and col.unsharpened() == [] and col.dropped == []
    # each view holds its accurate corners, not the quick ones it was judged by
    assert all(np.array_equal(v.corners, found.corners) for v, found in zip(views, looked_at))
    assert not any(np.array_equal(v.corners, o.corners) for v in views for o in out)
    col.views
    assert len(looked_at) == 4   # once each

    # found elsewhere (another thread, the workers) and handed in; a lost board drops its view
    col = ViewCollector(BOARD)
    _feed(col, frames[:3], dt=1.0)
    (k0, a0, q0), (k1, *_), (k2, *_) = col.unsharpened()
    dropped = col.sharpen({k1: Detection(None, "no board"), k0: tracking.accurate_detect(a0, BOARD, q0),
                           k2 + 1000: Detection(None, "a view no longer kept")})
    assert dropped == ["the view taken at 1.000 s dropped: board lost by the accurate detector: no board"]
    assert col.dropped == dropped and len(col) == 2 and [k for k, *_ in col.unsharpened()] == [k2]
    assert len(col.views) == 2 and col.stamps == [0.0, 2.0]


@dataclass
class _Stream:
    """A replayed frame held in memory (``replay.Frame``), and its amplitude (``replay.ImageSource``)."""

    amplitude: np.ndarray
    depth: np.ndarray
    stamp: float
    where: str = "memory"
    nbytes: int = 0

    def amplitude_source(self):
        return self

    def load(self):
        return self.amplitude

    def saved_corners(self):
        return None

    def decode(self):
        return self.amplitude, self.depth


def test_a_replay_finds_the_accurate_corners_once_its_views_are_known_and_counts_those_lost(monkeypatch):
    frames = [_frame(_pose(*p), seed=i) for i, p in enumerate(SWEEP[:4])]
    calls, accepted = [], []

    def second_lost(amplitude, board, quick):
        calls.append(len(accepted))
        return Detection(None, "lost") if len(calls) == 2 else tracking.accurate_detect(amplitude, board, quick)

    monkeypatch.setattr(replay, "accurate_detect", second_lost)
    run = replay.Replay(BOARD, CollectorConfig(), on_outcome=lambda _f, _a, o: accepted.append(o.accepted))
    summary = run.run(_Stream(f.amplitude, f.depth, float(i)) for i, f in enumerate(frames))
    assert accepted == [True] * 4 and calls == [4] * 4   # after every frame was judged
    assert summary.rejections == {"board lost by the accurate detector": 1}
    assert len(run.collector) == 3 and summary.view_stamps == run.collector.stamps == [0.0, 2.0, 3.0]
    assert run.collector.unsharpened() == [] and run.collector.dropped[0].endswith("lost")


def test_a_replay_tells_its_caller_of_every_skip_the_source_s_and_its_own(sweep_frames):
    # The node warns of what its on_skip hears: a message the bag could not decode (the source's
    # skip) as well as a frame of another size (the replay's own) must reach it, counted once each.
    heard = []
    f = sweep_frames[0]
    items = [_Stream(f.amplitude, f.depth, 0.0), replay.Skip("undecodable", "bag@3", "truncated message"),
             _Stream(f.amplitude[:-8], f.depth[:-8], 1.0)]
    summary = replay.Replay(BOARD, CollectorConfig(), on_skip=heard.append).run(iter(items))
    assert [s.kind for s in heard] == ["undecodable", "size"], heard
    assert dict(summary.skipped) == {"undecodable": 1, "size": 1} and summary.frames == 1


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


@pytest.mark.slow
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
    assert col.add(frame.amplitude, frame.depth, 0.0).accepted

    def rms(corners):   # against the rendered truth
        return float(np.sqrt(np.mean(np.sum((corners - frame.corners) ** 2, axis=1))))

    # found in the region around the quick corners: as accurate as the whole image's, or more
    kept, whole = rms(col.views[0].corners), rms(detect_corners(frame.amplitude, BOARD))
    assert kept < 0.1 and kept <= 1.1 * whole, (kept, whole)


@pytest.mark.parametrize("accepted", [True, False])
def test_the_board_picture_rings_a_corner_under_the_reason_text(accepted):
    """A board at the top of the frame: its corners' rings are drawn over the reason's dark band
    (drawn under it, they were hidden and the picture looked as if the corner was not found)."""
    from tof_calib_ros.collect.board_picture import KEPT, REFUSED, TEXT_BAND_PX, draw, enlarged, scale_for

    amplitude = np.tile(np.linspace(100, 2000, 200), (200, 1)).astype(np.uint16)
    corners = np.array([[60.0, 4.0], [120.0, 150.0]])
    progress = {"views": 0, "axes": {name: {"progress": 0.0} for name in AXES}}
    picture = draw(amplitude, collector.Outcome(accepted, "a long reason " * 8, corners=corners), progress)
    colour = np.array(KEPT if accepted else REFUSED)
    k = scale_for(200)
    for x, y in np.rint(enlarged(corners, k)).astype(int):
        ring = picture[y - k - 3:y + k + 4, x - k - 3:x + k + 4].astype(int)
        assert (np.abs(ring - colour).max(axis=2) < 40).any(), (x, y)
    assert enlarged(corners, k)[0, 1] < TEXT_BAND_PX   # the first corner does lie under the band


def test_the_board_picture_says_what_to_do_next_until_the_views_are_enough():
    from tof_calib_ros.collect.board_picture import BAR_STEP, COUNT_PX, KEPT, PANEL_WIDTH, REFUSED, draw

    amplitude = np.tile(np.linspace(100, 2000, 200), (200, 1)).astype(np.uint16)
    below_bars = slice(COUNT_PX + len(AXES) * BAR_STEP + 16, None)   # the panel under its last bar

    def panel_colours(depth_progress: float, good: bool) -> tuple[bool, bool]:
        progress = {"views": 12, "good_enough": good,
                    "axes": {name: {"progress": depth_progress if name == "depth" else 1.0} for name in AXES}}
        panel = draw(amplitude, collector.Outcome(False, "x"), progress)[below_bars, -PANEL_WIDTH:].astype(int)
        return tuple(bool((np.abs(panel - np.array(c)).max(axis=2) < 40).any()) for c in (REFUSED, KEPT))

    assert panel_colours(0.3, False) == (True, False)   # "next: hold it at more distances, near and far"
    assert panel_colours(1.0, True) == (False, True)    # "enough to calibrate"
    assert panel_colours(1.0, False) == (False, False)  # every axis full, too few views: the count says so


def test_the_board_picture_of_a_blank_frame_says_why_it_is_no_view():
    from tof_calib_ros.collect.board_picture import TEXT_BAND_PX, draw, scale_for

    blank = np.zeros((200, 200), np.uint16)   # a covered lens
    outcome = ViewCollector(BOARD).add(blank, blank, 0.0)
    assert not outcome.accepted and "constant" in outcome.reason, outcome.reason
    progress = {"views": 0, "good_enough": False, "axes": {name: {"progress": 0.0} for name in AXES}}
    frame = draw(blank, outcome, progress)[:, :200 * scale_for(200)]
    assert frame[:TEXT_BAND_PX].max() == 255 and frame[TEXT_BAND_PX:].max() == 0   # its reason, over black


@pytest.mark.parametrize("axis", AXES)
def test_the_board_picture_s_advice_for_each_axis_fits_a_200x200_sensor_s_picture(axis):
    from tof_calib_ros.collect.board_picture import PANEL_WIDTH, REFUSED, draw

    amplitude = np.tile(np.linspace(100, 2000, 200), (200, 1)).astype(np.uint16)
    progress = {"views": 3, "good_enough": False,
                "axes": {name: {"progress": 0.2 if name == axis else 1.0} for name in AXES}}
    panel = draw(amplitude, collector.Outcome(False, "x"), progress)[:, -PANEL_WIDTH:].astype(int)
    rows = np.flatnonzero((np.abs(panel - np.array(REFUSED)).max(axis=2) < 60).any(axis=1))
    # the advice's lines, under the short axis' orange bar, end above the picture's last rows
    assert len(rows) and rows[-1] < panel.shape[0] - 3, (axis, rows[-5:], panel.shape)


def test_a_view_whose_white_squares_clip_is_kept_and_the_person_told():
    """Kept (leaving the near views out moved the real Kinect v2 calibration no closer between its
    halves: docs/measurements.md, 2026-12-01), but the person holding the board hears that its
    white squares clip and what to do; the same board within the amplitude's range is not told."""
    pose = _pose((100, 100), 0.6)
    said = {}
    for gain in (0.6, 0.1):   # a white square at 1.7 and 0.3 of full scale
        frame = sim.render(CAM, BOARD, *pose, noise=NOISE, rng=1, gain=gain)
        out = ViewCollector(BOARD).add(frame.amplitude, frame.depth, 0.0)
        assert out.accepted, out.reason
        said[gain] = out.reason
    assert re.fullmatch(r"accepted as view 1; its white squares clip \(\d\d% of the board at the amplitude's full "
                        r"scale\), .* lower the exposure, or hold the board farther", said[0.6]), said[0.6]
    assert said[0.1] == "accepted as view 1"
