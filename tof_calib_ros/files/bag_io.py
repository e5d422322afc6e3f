"""ToF recordings in bags, read and written with rosbags: no ROS install needed.

Reading streams: one message at a time is read, deserialised, checked and paired by header
stamp (``StampSync``, as the node pairs live topics), so memory does not depend on the bag's
length. rosbag2 (sqlite3 and mcap storage) and ROS 1 ``.bag`` files are read alike.
Deserialised images are handed on as ``ImageFields``, the few fields ``decode_image`` reads, so
they can be decoded in a worker process.

A message that cannot be used is skipped with a ``replay.Skip`` naming the kind: undecodable
(truncated or garbage bytes), an unsupported encoding, a header stamp not after the previous
one on its topic; its image data is checked when decoded (``BagFrame.decode``).
"""
from __future__ import annotations

import math
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from ..collect.replay import FrameError, Skip
from ..collect.stamp_sync import StampSync
from ..core.errors import CalibrationError
from .bag_salvage import McapSalvage, SqliteSalvage, storage_files
from .calibration_file import monocular_fields
from .image_decode import DEPTH_ENCODINGS, ENCODINGS, ImageError, ImageTooLarge, decode_image, depth_to_metres


def stamp_parts(stamp: float) -> tuple[int, int]:
    """A stamp in seconds as a message's (sec, nanosec): the nanoseconds rounded, and carried
    into the seconds when they round up to a whole one (wrapped to 0, a stamp went back 1 s)."""
    sec = math.floor(stamp)
    nanosec = round((stamp - sec) * 1e9)
    return (sec + 1, 0) if nanosec >= 1_000_000_000 else (sec, nanosec)

IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
STORAGES = ("sqlite3", "mcap", "ros1")
# Topic-name words that say what an image topic carries (names are split at '/', '_', ...).
DEPTH_WORDS = frozenset({"depth", "distance", "range"})
AMPLITUDE_WORDS = frozenset({"amplitude", "ir", "intensity", "infrared", "infra", "gray", "grey"})
# Words of derived images: among several candidates, the raw one is what calibration needs.
DERIVED_WORDS = frozenset({"rect", "rectified", "registered", "filtered", "colorized", "color"})


class BagError(CalibrationError):
    """A bag that cannot be opened or read."""


class TopicError(BagError):
    """A topic the bag lacks, or that cannot be told apart from others."""


@dataclass(frozen=True)
class ImageFields:
    """What ``decode_image`` reads of a sensor_msgs/Image, detached from rosbags' generated
    message class (which a worker process could not unpickle); ``data`` views the raw bytes."""

    encoding: str
    height: int
    width: int
    step: int
    is_bigendian: int
    data: np.ndarray
    frame_id: str = ""

    @classmethod
    def of(cls, msg: Any) -> ImageFields:
        return cls(msg.encoding, msg.height, msg.width, msg.step, msg.is_bigendian, msg.data, msg.header.frame_id)

    @property
    def nbytes(self) -> int:
        return int(self.data.nbytes)

    def load(self) -> np.ndarray:
        try:
            return decode_image(self)
        except ImageTooLarge as exc:
            raise FrameError("too_large", str(exc)) from None
        except ImageError as exc:   # the encodings were checked on reading: the data is at fault
            raise FrameError("layout", str(exc)) from None

    def saved_corners(self) -> None:
        return None   # a recorded image comes with no corners


@dataclass(frozen=True)
class BagFrame:
    """A paired amplitude and depth message; a worker decodes the amplitude to find the board."""

    stamp: float
    where: str
    amplitude: ImageFields
    depth: ImageFields
    depth_scale: float

    def amplitude_source(self) -> ImageFields:
        return self.amplitude

    def decode(self) -> tuple[np.ndarray, np.ndarray]:
        amplitude, depth = self.amplitude.load(), self.depth.load()
        if amplitude.shape != depth.shape:
            raise FrameError("size", f"amplitude {amplitude.shape[1]}x{amplitude.shape[0]} and depth "
                                     f"{depth.shape[1]}x{depth.shape[0]} differ in size")
        return amplitude, depth_to_metres(depth, self.depth.encoding, self.depth_scale)


@dataclass(frozen=True)
class Topics:
    amplitude: str
    depth: str
    camera_info: str | None
    how: dict[str, str]     # per role, how the topic was chosen


@dataclass(frozen=True)
class CameraInfo:
    """The first usable camera_info of the bag (the driver's calibration)."""

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray


FLAGS = {"amplitude": "--amplitude-topic", "depth": "--depth-topic", "camera_info": "--camera-info-topic"}


def _words(topic: str) -> set[str]:
    return set(re.split(r"[^a-z0-9]+", topic.lower())) - {""}


def _pick(role: str, candidates: list[str], flag: str) -> str:
    """The one candidate, or the one raw one among derived ones; else a TopicError."""
    if len(candidates) > 1:
        raw = [t for t in candidates if not _words(t) & DERIVED_WORDS]
        candidates = raw if len(raw) == 1 else candidates
    if len(candidates) > 1:
        raise TopicError(f"several {role} topics: {', '.join(candidates)}; choose one with {flag}")
    return candidates[0]


def choose_topics(types: dict[str, str], amplitude: str | None = None, depth: str | None = None,
                  camera_info: str | None = None, flags: dict[str, str] = FLAGS) -> Topics:
    """The amplitude, depth and camera_info topics among ``types`` (topic -> message type):
    those given, checked, or found by message type and name. ``flags``: how the caller's user
    gives each (named in the errors)."""
    images = sorted(t for t, m in types.items() if m == IMAGE)
    infos = sorted(t for t, m in types.items() if m == CAMERA_INFO)
    listing = f"image topics in the bag: {', '.join(images) or 'none'}"

    def given(topic: str, msgtype: str, flag: str) -> str:
        if topic not in types:
            raise TopicError(f"{flag} {topic}: no such topic in the bag ({listing})")
        if types[topic] != msgtype:
            raise TopicError(f"{flag} {topic} carries {types[topic]}, not {msgtype}")
        return topic

    if amplitude is not None and amplitude == depth:
        raise TopicError(f"{flags['amplitude']} and {flags['depth']} are both {amplitude}: they must differ")
    how = {}
    if depth is not None:
        depth, how["depth"] = given(depth, IMAGE, flags["depth"]), "given"
    if amplitude is not None:
        amplitude, how["amplitude"] = given(amplitude, IMAGE, flags["amplitude"]), "given"
    if depth is None:
        named = [t for t in images if _words(t) & DEPTH_WORDS and t != amplitude]
        if named:
            depth, how["depth"] = _pick("depth", named, flags["depth"]), "by name"
        elif amplitude is not None and len(images) == 2:
            depth, how["depth"] = next(t for t in images if t != amplitude), "the other image topic"
        else:
            raise TopicError(f"no depth image topic found (none is named depth, distance or range; "
                             f"{listing}); give it with {flags['depth']}")
    if amplitude is None:
        named = [t for t in images if _words(t) & AMPLITUDE_WORDS and not _words(t) & DEPTH_WORDS
                 and t != depth]
        others = [t for t in images if t != depth]
        if named:
            amplitude, how["amplitude"] = _pick("amplitude", named, flags["amplitude"]), "by name"
        elif len(others) == 1:
            amplitude, how["amplitude"] = others[0], "the other image topic"
        else:
            raise TopicError(f"no amplitude image topic found (none is named amplitude, ir, intensity "
                             f"or gray; {listing}); give it with {flags['amplitude']}")
    if camera_info is not None:
        camera_info, how["camera_info"] = given(camera_info, CAMERA_INFO, flags["camera_info"]), "given"
    elif infos:
        # the one sharing the longest namespace with the amplitude topic (the intrinsics are its)
        def shared(topic: str) -> int:
            a, b = amplitude.split("/"), topic.split("/")
            return next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), min(len(a), len(b)))
        best = max(map(shared, infos))
        camera_info = _pick("camera_info", [t for t in infos if shared(t) == best], flags["camera_info"])
        how["camera_info"] = "by type" if len(infos) == 1 else "by namespace"
    return Topics(amplitude, depth, camera_info, how)


class BagSource:
    """An open bag: its topics, the driver's camera_info, and the stream of paired frames.

    Use as a context manager. Raises BagError when the bag cannot be opened, TopicError when
    the topics are missing or ambiguous.
    """

    def __init__(self, path: str | Path, *, amplitude: str | None = None, depth: str | None = None,
                 camera_info: str | None = None, slop: float = 0.02, depth_scale: float = 0.001,
                 flags: dict[str, str] = FLAGS) -> None:
        self.path = Path(path)
        self.slop, self.depth_scale = slop, depth_scale
        self._requested = (amplitude, depth, camera_info)
        self._flags = flags
        self._reader: AnyReader | McapSalvage | SqliteSalvage | None = None
        self.unpaired = {"amplitude": 0, "depth": 0}
        self.unstamped = 0   # messages whose header stamp was 0, stamped with the bag's time instead

    def __enter__(self) -> BagSource:
        if not self.path.exists():
            raise BagError(f"{self.path}: no such bag")
        try:
            # A ROS 2 bag from before Iron stores no message definitions: Jazzy's are the same.
            self._reader = AnyReader([self.path], default_typestore=get_typestore(Stores.ROS2_JAZZY))
            self._reader.open()
        except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds on a damaged file
            self._reader = self._salvage(exc)
        try:
            types = {t: info.msgtype for t, info in self._reader.topics.items()}
            self.topics = choose_topics(types, *self._requested, flags=self._flags)
            self.camera_info = self._first_camera_info()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def _salvage(self, exc: Exception) -> McapSalvage | SqliteSalvage:
        """A recording rosbags cannot open: one cut off (a recorder killed mid-way leaves no MCAP
        summary, a sqlite3 file SQLite refuses, no metadata.yaml) is read up to the cut."""
        why = f"{self.path}: cannot open the bag ({_describe(exc)})"
        for suffix, salvage in ((".mcap", McapSalvage), (".db3", SqliteSalvage)):
            files = storage_files(self.path, suffix)
            if files:
                reader = salvage(files)
                if not reader.connections:
                    raise BagError(f"{why}; read as far as it goes, it holds no message either"
                                   + (f" ({reader.cut})" if reader.cut else "")) from None
                return reader
        raise BagError(why) from None

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None

    @property
    def storage(self) -> str:
        if not self._reader.is2:
            return "ROS 1 bag"
        if isinstance(self._reader, McapSalvage):
            return "mcap, read in order up to where it ends (no summary or metadata.yaml)"
        if isinstance(self._reader, SqliteSalvage):
            return "sqlite3, read page by page up to where it ends (SQLite refuses it, or no metadata.yaml)"
        return "rosbag2 " + ("mcap" if any(self.path.glob("*.mcap*")) else "sqlite3")

    @property
    def frame_count(self) -> int:
        """Amplitude messages in the bag: at most this many frames."""
        return self._reader.topics[self.topics.amplitude].msgcount

    def _connections(self, topic: str) -> list:
        return [c for c in self._reader.connections if c.topic == topic]

    def _first_camera_info(self) -> CameraInfo | None:
        if self.topics.camera_info is None:
            return None
        for conn, _t, raw in self._reader.messages(connections=self._connections(self.topics.camera_info)):
            try:
                msg = self._reader.deserialize(raw, conn.msgtype)
                # ROS 1 spells the matrices in capitals
                K = np.array(msg.k if hasattr(msg, "k") else msg.K, dtype=float).reshape(3, 3)
                D = np.array(msg.d if hasattr(msg, "d") else msg.D, dtype=float)
            except Exception:  # noqa: BLE001 - a broken camera_info: try the next one
                continue
            if msg.width > 0 and msg.height > 0 and K[0, 0] > 0 and K[1, 1] > 0:
                return CameraInfo(int(msg.width), int(msg.height), K, D)
        return None

    def frames(self) -> Iterator[BagFrame | Skip]:
        """Paired frames in recording order, and a Skip for each message left out."""
        topics = self.topics
        sync = StampSync(self.slop)
        last: dict[str, float] = {}
        used = {topics.amplitude: 0, topics.depth: 0}
        pairs = 0
        conns = self._connections(topics.amplitude) + self._connections(topics.depth)
        messages = self._reader.messages(connections=conns)
        while True:
            try:
                conn, t_ns, raw = next(messages)
            except StopIteration:
                break
            except Exception as exc:  # noqa: BLE001 - a damaged file fails in many ways mid-way
                yield Skip("read_error", str(self.path), f"reading stopped: {_describe(exc)}")
                break
            where = f"{conn.topic} at {t_ns * 1e-9:.3f} s (bag time)"
            try:
                msg = self._reader.deserialize(raw, conn.msgtype)
                stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
                fields = ImageFields.of(msg)
                if stamp == 0.0:   # a driver that leaves its images unstamped: the recorder's time pairs them
                    stamp = t_ns * 1e-9
                    self.unstamped += 1
            except Exception as exc:  # noqa: BLE001 - garbage bytes raise many kinds
                yield Skip("undecodable", where, _describe(exc))
                continue
            is_depth = conn.topic == topics.depth
            allowed = DEPTH_ENCODINGS if is_depth else tuple(ENCODINGS)
            if fields.encoding not in allowed:
                yield Skip("encoding", where, f"{'depth' if is_depth else 'amplitude'} encoding "
                                              f"{fields.encoding!r} is not one of {', '.join(allowed)}")
                continue
            previous = last.get(conn.topic)
            if previous is not None and stamp <= previous:
                yield Skip("stamp_order", where, f"header stamp {stamp:.6f} s is not after the previous "
                                                 f"{previous:.6f} s")
                continue
            last[conn.topic] = stamp
            used[conn.topic] += 1
            pair = sync.add(int(is_depth), stamp, fields)
            if pair is not None:
                pairs += 1
                yield BagFrame(stamp, f"frame at {stamp:.3f} s", pair[0], pair[1], self.depth_scale)
        self.unpaired = {"amplitude": used[topics.amplitude] - pairs, "depth": used[topics.depth] - pairs}
        if isinstance(self._reader, (McapSalvage, SqliteSalvage)) and self._reader.cut:
            yield Skip("read_error", str(self.path), f"the recording is cut off, every message before the cut was "
                                                     f"read ({self._reader.cut})")


def _describe(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class BagWriter:
    """Writes Image and CameraInfo messages (or raw bytes, to test broken messages) to a new
    bag: rosbag2 with sqlite3 or mcap storage, or a ROS 1 .bag."""

    def __init__(self, path: str | Path, storage: str = "sqlite3") -> None:
        if storage not in STORAGES:
            raise CalibrationError(f"storage must be one of {', '.join(STORAGES)}, got {storage!r}")
        self.path, self.storage = Path(path), storage
        if storage == "ros1":
            self.typestore = get_typestore(Stores.ROS1_NOETIC)
            self._writer = Writer1(self.path)
        else:
            self.typestore = get_typestore(Stores.ROS2_JAZZY)
            plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
            self._writer = Writer2(self.path, version=Writer2.VERSION_LATEST, storage_plugin=plugin)
        self._connections: dict[str, Any] = {}

    def __enter__(self) -> BagWriter:
        try:
            self._writer.open()
        except Exception as exc:  # noqa: BLE001 - rosbags' writer errors, and OSError
            raise BagError(f"{self.path}: cannot create the bag ({_describe(exc)})") from None
        return self

    def __exit__(self, *_exc: object) -> None:
        self._writer.close()

    def _types(self, name: str) -> Any:
        return self.typestore.types[name]

    def header(self, stamp: float, frame_id: str) -> Any:
        sec, nanosec = stamp_parts(stamp)
        time = self._types("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)
        if self.storage == "ros1":
            return self._types("std_msgs/msg/Header")(seq=0, stamp=time, frame_id=frame_id)
        return self._types("std_msgs/msg/Header")(stamp=time, frame_id=frame_id)

    def image_message(self, array: np.ndarray, encoding: str, stamp: float, frame_id: str) -> Any:
        a = np.ascontiguousarray(array)
        a = a.astype(a.dtype.newbyteorder("<"))
        return self._types(IMAGE)(header=self.header(stamp, frame_id), height=a.shape[0], width=a.shape[1],
                                  encoding=encoding, is_bigendian=0, step=a.shape[1] * a.itemsize * (
                                      a.shape[2] if a.ndim == 3 else 1), data=a.view(np.uint8).reshape(-1))

    def camera_info_message(self, K: np.ndarray, D: np.ndarray, size: tuple[int, int], stamp: float,
                            frame_id: str) -> Any:
        fields = monocular_fields(K, D, size)
        matrices = {k: np.array(fields.pop(k)) for k in ("k", "d", "r", "p")}
        if self.storage == "ros1":
            matrices = {k.upper(): v for k, v in matrices.items()}
        roi = self._types("sensor_msgs/msg/RegionOfInterest")(x_offset=0, y_offset=0, height=0, width=0,
                                                              do_rectify=False)
        return self._types(CAMERA_INFO)(header=self.header(stamp, frame_id), binning_x=0, binning_y=0, roi=roi,
                                        **fields, **matrices)

    def write(self, topic: str, msg: Any, stamp: float) -> None:
        """A message (from ``image_message``, ``camera_info_message`` or the typestore)."""
        msgtype = msg.__msgtype__
        if self.storage == "ros1":
            data = self.typestore.serialize_ros1(msg, msgtype)
        else:
            data = self.typestore.serialize_cdr(msg, msgtype)
        self.write_raw(topic, msgtype, stamp, data)

    def write_raw(self, topic: str, msgtype: str, stamp: float, data: bytes | memoryview) -> None:
        """Bytes as they are, recorded at ``stamp`` (seconds): what a broken driver might write."""
        if topic not in self._connections:
            self._connections[topic] = self._writer.add_connection(topic, msgtype, typestore=self.typestore)
        self._writer.write(self._connections[topic], int(round(stamp * 1e9)), data)
