"""Bags read and written with rosbags: topic choice, the frame stream, and every kind of broken message."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tof_calib_ros.collect.replay import FrameError, Skip
from tof_calib_ros.files.bag_io import (
    CAMERA_INFO,
    IMAGE,
    STORAGES,
    BagError,
    BagFrame,
    BagSource,
    BagWriter,
    TopicError,
    choose_topics,
    stamp_parts,
)

AMP, DEPTH, INFO = "/tof/amplitude/image_raw", "/tof/depth/image_raw", "/tof/camera_info"
K = np.array([[280.0, 0, 99.5], [0, 281.0, 100.5], [0, 0, 1]])


def _images(i: int, h: int = 6, w: int = 8) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(i)
    return (rng.integers(0, 65535, (h, w), dtype=np.uint16),
            rng.integers(500, 3000, (h, w), dtype=np.uint16))


def _bag(tmp_path: Path, storage: str, frames: int = 5, info: bool = True, name: str = "bag",
         size: tuple[int, int] = (6, 8)) -> Path:
    path = tmp_path / (name + (".bag" if storage == "ros1" else ""))
    with BagWriter(path, storage) as bag:
        for i in range(frames):
            stamp = 100.0 + 0.1 * i
            amplitude, depth = _images(i, *size)
            bag.write(AMP, bag.image_message(amplitude, "mono16", stamp, "tof"), stamp)
            bag.write(DEPTH, bag.image_message(depth, "16UC1", stamp + 0.001, "tof"), stamp + 0.001)
            if info:
                bag.write(INFO, bag.camera_info_message(K, [0.1, 0, 0, 0, 0], (8, 6), stamp, "tof"), stamp)
    return path


def _frames(source: BagSource) -> tuple[list[BagFrame], list[Skip]]:
    frames, skips = [], []
    for item in source.frames():
        (skips if isinstance(item, Skip) else frames).append(item)
    return frames, skips


# -- choosing topics ----------------------------------------------------------------------------
def test_topics_are_found_by_type_and_name():
    types = {AMP: IMAGE, DEPTH: IMAGE, INFO: CAMERA_INFO, "/tf": "tf2_msgs/msg/TFMessage"}
    t = choose_topics(types)
    assert (t.amplitude, t.depth, t.camera_info) == (AMP, DEPTH, INFO)
    assert t.how == {"amplitude": "by name", "depth": "by name", "camera_info": "by type"}


def test_kinect_style_names_and_the_raw_image_before_the_rectified_one():
    types = {"/kinect2/sd/image_ir": IMAGE, "/kinect2/sd/image_depth": IMAGE, "/kinect2/sd/image_depth_rect": IMAGE,
             "/kinect2/sd/image_ir_rect": IMAGE, "/kinect2/sd/camera_info": CAMERA_INFO}
    t = choose_topics(types)
    assert (t.amplitude, t.depth) == ("/kinect2/sd/image_ir", "/kinect2/sd/image_depth")


def test_camera_info_beside_the_amplitude_topic_wins():
    types = {"/cam/ir/image": IMAGE, "/cam/depth/image": IMAGE, "/cam/ir/camera_info": CAMERA_INFO,
             "/cam/depth/camera_info": CAMERA_INFO}
    t = choose_topics(types)
    assert t.camera_info == "/cam/ir/camera_info" and t.how["camera_info"] == "by namespace"


def test_an_unnamed_amplitude_topic_is_the_other_image_topic():
    t = choose_topics({"/tof/depth": IMAGE, "/tof/signal": IMAGE})
    assert t.amplitude == "/tof/signal" and t.how["amplitude"] == "the other image topic"
    assert t.camera_info is None


def test_topics_that_are_missing_wrong_or_ambiguous_are_named():
    types = {AMP: IMAGE, DEPTH: IMAGE, INFO: CAMERA_INFO}
    with pytest.raises(TopicError, match="--depth-topic /nope: no such topic.*image topics in the bag: "):
        choose_topics(types, depth="/nope")
    with pytest.raises(TopicError, match="carries sensor_msgs/msg/CameraInfo, not sensor_msgs/msg/Image"):
        choose_topics(types, amplitude=INFO)
    with pytest.raises(TopicError, match="no depth image topic found"):
        choose_topics({AMP: IMAGE, "/a/b": IMAGE, "/c": IMAGE})
    with pytest.raises(TopicError, match="several depth topics: /a/depth, /b/depth; choose one with --depth-topic"):
        choose_topics({AMP: IMAGE, "/a/depth": IMAGE, "/b/depth": IMAGE})
    with pytest.raises(TopicError, match="must differ"):
        choose_topics(types, amplitude=DEPTH, depth=DEPTH)
    t = choose_topics({AMP: IMAGE, "/a/depth": IMAGE, "/b/depth": IMAGE}, depth="/b/depth")
    assert t.depth == "/b/depth" and t.how["depth"] == "given"


# -- reading and writing ------------------------------------------------------------------------
@pytest.mark.parametrize("storage", STORAGES)
def test_round_trip_in_every_storage(tmp_path, storage):
    path = _bag(tmp_path, storage)
    with BagSource(path) as source:
        assert source.frame_count == 5 and storage.replace("ros1", "ROS 1") in source.storage
        info = source.camera_info
        assert (info.width, info.height) == (8, 6)
        np.testing.assert_array_equal(info.K, K)
        np.testing.assert_array_equal(info.D, [0.1, 0, 0, 0, 0])
        frames, skips = _frames(source)
    assert skips == [] and len(frames) == 5 and source.unpaired == {"amplitude": 0, "depth": 0}
    for i, frame in enumerate(frames):
        amplitude, depth = frame.decode()
        expected_amplitude, expected_depth = _images(i)
        np.testing.assert_array_equal(amplitude, expected_amplitude)
        np.testing.assert_allclose(depth, expected_depth * 0.001, rtol=1e-12)
        np.testing.assert_array_equal(frame.amplitude_source().load(), expected_amplitude)   # a worker's part
        assert frame.stamp == pytest.approx(100.0 + 0.1 * i + 0.001, abs=1e-6)   # the depth's stamp


def test_a_stamp_whose_nanoseconds_round_to_a_second_carries_it(tmp_path):
    # Wrapped to 0 without the carry, 1,700,000,000.9999999997 s went back to ...000.0.
    assert stamp_parts(1_700_000_000.9999999997) == (1_700_000_001, 0)
    assert stamp_parts(100.25) == (100, 250_000_000) and stamp_parts(7.0) == (7, 0)
    path = tmp_path / "bag"
    with BagWriter(path, "sqlite3") as bag:
        for stamp in (99.9, 99.9999999997):
            amplitude, depth = _images(0)
            bag.write(AMP, bag.image_message(amplitude, "mono16", stamp, "tof"), stamp)
            bag.write(DEPTH, bag.image_message(depth, "16UC1", stamp, "tof"), stamp)
    with BagSource(path) as source:
        frames, skips = _frames(source)
    assert skips == [] and [f.stamp for f in frames] == pytest.approx([99.9, 100.0], abs=1e-6)


def test_frames_are_paired_by_stamp_and_the_unpaired_counted(tmp_path):
    path = tmp_path / "bag"
    with BagWriter(path) as bag:
        for i in range(4):
            a, d = _images(i)
            bag.write(AMP, bag.image_message(a, "mono16", 10.0 + i, "tof"), 10.0 + i)
            if i != 2:   # a dropped depth frame
                bag.write(DEPTH, bag.image_message(d, "16UC1", 10.005 + i, "tof"), 10.005 + i)
        a, d = _images(9)
        bag.write(DEPTH, bag.image_message(d, "16UC1", 20.0, "tof"), 20.0)   # too far from any amplitude frame
    with BagSource(path) as source:
        frames, _ = _frames(source)
    assert [f.stamp for f in frames] == pytest.approx([10.005, 11.005, 13.005])
    assert source.unpaired == {"amplitude": 1, "depth": 1}


def test_depth_scale_and_32fc1_depth(tmp_path):
    path = tmp_path / "bag"
    depth = np.array([[0.5, 0.0], [np.nan, 2.25]], np.float32)
    with BagWriter(path) as bag:
        bag.write(AMP, bag.image_message(np.ones((2, 2), np.uint8), "mono8", 1.0, "tof"), 1.0)
        bag.write(DEPTH, bag.image_message(depth, "32FC1", 1.0, "tof"), 1.0)
    with BagSource(path, depth_scale=0.1) as source:   # the scale is for integer depth only
        (frame,), _ = _frames(source)
    np.testing.assert_array_equal(frame.decode()[1], [[0.5, np.nan], [np.nan, 2.25]])


def test_the_stream_reads_one_message_at_a_time(tmp_path, monkeypatch):
    path = _bag(tmp_path, "sqlite3", frames=50)
    with BagSource(path) as source:
        reads = []
        messages = source._reader.messages

        def counted(*args, **kwargs):
            for m in messages(*args, **kwargs):
                reads.append(m[1])
                yield m

        monkeypatch.setattr(source._reader, "messages", counted)
        stream = source.frames()
        next(stream)
        assert len(reads) <= 3   # the first pair needs its two messages, not the whole bag


# -- broken bags and messages -------------------------------------------------------------------
def test_bags_that_cannot_be_opened(tmp_path):
    with pytest.raises(BagError, match="no such bag"):
        BagSource(tmp_path / "missing").__enter__()
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    with pytest.raises(BagError, match="junk: cannot open the bag"):
        BagSource(tmp_path / "junk").__enter__()
    (tmp_path / "x.bag").write_bytes(b"#ROSBAG V2.0\n" + bytes(range(256)) * 4)
    with pytest.raises(BagError, match="x.bag: cannot open the bag"):
        BagSource(tmp_path / "x.bag").__enter__()
    (tmp_path / "empty").mkdir()
    with pytest.raises(BagError, match="empty: cannot open the bag"):
        BagSource(tmp_path / "empty").__enter__()
    damaged = _bag(tmp_path, "sqlite3", name="damaged")
    db = next(damaged.glob("*.db3"))
    db.write_bytes(db.read_bytes()[:2048])   # the recording cut short
    with pytest.raises(BagError, match="damaged: cannot open the bag.*it holds no message either"):
        BagSource(damaged).__enter__()
    only = tmp_path / "only"
    with BagWriter(only) as bag:
        bag.write(AMP, bag.image_message(np.ones((2, 2), np.uint16), "mono16", 1.0, "tof"), 1.0)
    with pytest.raises(TopicError, match="no depth image topic found"):
        BagSource(only).__enter__()


def _broken_bag(tmp_path: Path, storage: str) -> Path:
    """Good frames 0..9 at 1 s steps, with one broken message of each kind among them."""
    path = tmp_path / (f"broken_{storage}" + (".bag" if storage == "ros1" else ""))
    with BagWriter(path, storage) as bag:
        def image(i, which, **changes):
            a, d = _images(i)
            msg = bag.image_message(a, "mono16", float(i), "tof") if which == "a" else \
                bag.image_message(d, "16UC1", float(i), "tof")
            return replace(msg, **changes)

        for i in range(10):
            t = float(i)
            bag.write(AMP, image(i, "a"), t)
            bag.write(DEPTH, image(i, "d"), t)
            good = bag.typestore.serialize_ros1 if storage == "ros1" else bag.typestore.serialize_cdr
            if i == 1:
                rgb = bag.image_message(np.zeros((6, 8, 3), np.uint8), "rgb8", t + 0.5, "tof")
                bag.write(AMP, rgb, t + 0.5)                                   # encoding
                bag.write(DEPTH, image(i, "d", encoding="bgr8",
                                       header=bag.header(t + 0.5, "tof")), t + 0.5)   # encoding
            if i == 3:
                raw = bytes(good(image(i, "a", header=bag.header(t + 0.5, "tof")), IMAGE))
                bag.write_raw(AMP, IMAGE, t + 0.5, raw[:len(raw) // 2])        # truncated
                bag.write_raw(DEPTH, IMAGE, t + 0.5, bytes(np.random.default_rng(3).integers(
                    0, 256, len(raw), dtype=np.uint8)))                          # garbage
            if i == 5:   # a pair with a wrong data length, then a pair of another size
                short = image(i, "a", header=bag.header(t + 0.5, "tof"))
                bag.write(AMP, replace(short, data=short.data[:-16]), t + 0.5)
                bag.write(DEPTH, image(i, "d", header=bag.header(t + 0.5, "tof")), t + 0.5)
                a, d = _images(50, h=5, w=8)
                bag.write(AMP, bag.image_message(a, "mono16", t + 0.7, "tof"), t + 0.7)
                bag.write(DEPTH, bag.image_message(d, "16UC1", t + 0.7, "tof"), t + 0.7)
            if i == 7:   # a message stamped before the previous one on its topic
                bag.write(DEPTH, image(i, "d", header=bag.header(t - 0.5, "tof")), t + 0.5)
    return path


@pytest.mark.parametrize("storage", STORAGES)
def test_every_kind_of_broken_message_is_skipped_and_named(tmp_path, storage):
    with BagSource(_broken_bag(tmp_path, storage)) as source:
        frames, skips = _frames(source)
    kinds = sorted(s.kind for s in skips)
    assert kinds == ["encoding", "encoding", "stamp_order", "undecodable", "undecodable"]
    assert any("'rgb8'" in s.reason for s in skips) and any("'bgr8'" in s.reason for s in skips)
    assert all(s.where.startswith(("/tof/amplitude", "/tof/depth")) for s in skips)
    # the data and size problems show on decoding (in a worker)
    decoded, problems = [], []
    for f in frames:
        try:
            decoded.append(f.decode())
        except FrameError as exc:
            problems.append((exc.kind, f.stamp))
    assert len(decoded) == 11   # ten good pairs and the 5x8 one (its size is the replay's to judge)
    assert sorted(problems) == [("layout", 5.5)]
    assert sum(a.shape == (5, 8) for a, _ in decoded) == 1


def test_a_bag_damaged_midway_gives_the_frames_before_the_damage(tmp_path):
    path = _bag(tmp_path, "ros1", frames=40, info=False)
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 2000] = bytes(2000)
    path.write_bytes(bytes(data))
    with BagSource(path) as source:
        frames, skips = _frames(source)
    assert 5 < len(frames) < 40
    assert [s.kind for s in skips] == ["read_error"] and "reading stopped" in skips[0].reason


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
@pytest.mark.parametrize("metadata", [True, False])
def test_a_cut_off_recording_gives_every_frame_before_the_cut(tmp_path, storage, metadata):
    """A recorder killed mid-recording: the MCAP file ends mid-chunk, without its summary, the
    sqlite3 file mid-page, and (when it died before closing) neither has metadata.yaml."""
    path = _bag(tmp_path, storage, frames=40, info=True, size=(200, 200))   # 160 kB a frame: a few a chunk
    file = next(path.glob("*.mcap" if storage == "mcap" else "*.db3"))
    whole = file.read_bytes()
    with BagSource(path) as source:
        every, _ = _frames(source)
    assert len(every) == 40
    if not metadata:
        (path / "metadata.yaml").unlink()
        with BagSource(path) as source:   # not cut: every frame
            assert "up to where it ends" in source.storage and len(_frames(source)[0]) == 40
    seen = []
    for fraction in (0.3, 0.55, 0.8, 0.97):
        file.write_bytes(whole[:int(len(whole) * fraction)])
        with BagSource(path) as source:
            assert "up to where it ends" in source.storage and source.camera_info is not None
            frames, skips = _frames(source)
        assert [s.kind for s in skips] == ["read_error"] and "every message before the cut" in skips[0].reason
        # the frames before the cut, each exactly as written
        assert [f.stamp for f in frames] == [f.stamp for f in every[:len(frames)]]
        for got, want in zip(frames, every):
            assert all(np.array_equal(a, b) for a, b in zip(got.decode(), want.decode()))
        seen.append(len(frames))
    # all but the frames of the MCAP chunk that was cut (the writer's chunks hold 1 MB)
    assert seen == sorted(seen) and seen[0] >= 5 and seen[-1] >= 32
    file.write_bytes(whole[:20])   # the magic and a few bytes: no message at all
    with pytest.raises(BagError, match="read as far as it goes, it holds no message either"):
        BagSource(path).__enter__()


def test_unstamped_images_are_paired_by_the_recorders_time(tmp_path):
    """A driver that leaves header stamps at 0: every message would be "not after the previous";
    the bag's receive times pair and order them instead, and the count says so."""
    path = tmp_path / "unstamped"
    with BagWriter(path, "mcap") as bag:
        for i in range(6):
            amplitude, depth = _images(i)
            bag.write(AMP, bag.image_message(amplitude, "mono16", 0.0, "tof"), 10.0 + i)
            bag.write(DEPTH, bag.image_message(depth, "16UC1", 0.0, "tof"), 10.0 + i + 0.002)
    with BagSource(path) as source:
        frames, skips = _frames(source)
        assert source.unstamped == 12
    assert skips == [] and [f.stamp for f in frames] == pytest.approx([10.0 + i for i in range(6)], abs=0.01)
    assert all(np.array_equal(f.decode()[0], _images(i)[0]) for i, f in enumerate(frames))


# -- property: whatever a bag holds, reading it yields frames or named skips ---------------------
def _hostile_messages():
    from hypothesis import strategies as st

    encodings = st.sampled_from(["mono8", "mono16", "16UC1", "32FC1", "8UC1", "rgb8", "", "16uc1", "64FC1"])
    image = st.fixed_dictionaries({
        "kind": st.just("image"), "encoding": encodings, "height": st.integers(0, 9), "width": st.integers(0, 9),
        "step": st.integers(0, 40), "bigendian": st.integers(0, 1), "data": st.binary(max_size=160)})
    garbage = st.fixed_dictionaries({"kind": st.just("bytes"), "data": st.binary(max_size=120)})
    flipped = st.fixed_dictionaries({"kind": st.just("flipped"), "cut": st.integers(0, 300),
                                     "flips": st.lists(st.integers(0, 10 ** 6), max_size=4)})
    message = st.tuples(st.sampled_from([AMP, DEPTH]), st.floats(0.0, 20.0), st.one_of(image, garbage, flipped))
    return st.lists(message, max_size=12)


def test_any_sequence_of_messages_gives_frames_or_named_skips(tmp_path_factory):
    """Property: broken fields, garbage bytes, truncated or bit-flipped serializations and any
    stamp order: the stream ends, each item is a frame or a Skip of a known kind with a reason,
    and a frame decodes to equal-sized finite-or-NaN images or raises FrameError."""
    from hypothesis import given, settings

    from tof_calib_ros.collect.replay import SKIP_KINDS

    @settings(max_examples=60, deadline=None)
    @given(_hostile_messages())
    def check(messages):
        path = tmp_path_factory.mktemp("hostile") / "bag"
        with BagWriter(path, "mcap") as bag:
            a, d = _images(0)   # one good pair first: the topics exist with their types
            bag.write(AMP, bag.image_message(a, "mono16", 0.0, "tof"), 0.0)
            bag.write(DEPTH, bag.image_message(d, "16UC1", 0.0, "tof"), 0.0)
            for topic, t, m in messages:
                if m["kind"] == "bytes":
                    bag.write_raw(topic, IMAGE, t, m["data"])
                    continue
                base = bag.image_message(d if topic == DEPTH else a, "16UC1" if topic == DEPTH else "mono16", t, "tof")
                if m["kind"] == "image":
                    msg = replace(base, encoding=m["encoding"], height=m["height"], width=m["width"], step=m["step"],
                                  is_bigendian=m["bigendian"], data=np.frombuffer(m["data"], np.uint8))
                    bag.write(topic, msg, t)
                    continue
                raw = bytearray(bag.typestore.serialize_cdr(base, IMAGE))
                for f in m["flips"]:
                    raw[f % len(raw)] ^= 0xFF
                bag.write_raw(topic, IMAGE, t, bytes(raw[:max(m["cut"], 1)] if m["cut"] < len(raw) else raw))
        with BagSource(path) as source:
            for item in source.frames():
                if isinstance(item, Skip):
                    assert item.kind in SKIP_KINDS and item.reason and item.where, item
                    continue
                try:
                    amplitude, depth = item.decode()
                except FrameError as exc:
                    assert exc.kind in SKIP_KINDS and str(exc)
                    continue
                assert amplitude.shape == depth.shape and amplitude.ndim == 2
                assert depth.dtype.kind == "f" and not np.any(depth[np.isfinite(depth)] < 0)

    check()
