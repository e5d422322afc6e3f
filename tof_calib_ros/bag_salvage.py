"""Every message of an MCAP recording up to where it was cut off.

rosbags opens an MCAP file from its summary, at the end of the file, and a bag's folder from its
metadata.yaml, which rosbag2 writes when it closes: a recorder killed mid-recording leaves
neither, and rosbags refuses the whole recording. MCAP's records follow one another from the
start, schemas and channels before the messages that use them, so this reads them in order with
the mcap library's stream reader, decompressing chunks as it goes, until the cut; the chunk the
cut falls in is lost with it (rosbag2 writes chunks of about 1 MB: a few frames). Only what
``bag_io.BagSource`` asks of a reader is provided.

(A cut-off sqlite3 file cannot be read this way: SQLite refuses a file shorter than its header
says, before any row.)
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.msg import get_types_from_msg

# rosbag2 names its message definitions' encoding so; the types are ROS 2 Jazzy's otherwise
_ROS2_MSG = "ros2msg"


@dataclass(frozen=True)
class Connection:
    id: int
    topic: str
    msgtype: str


@dataclass
class TopicInfo:
    msgtype: str
    msgcount: int


def mcap_files(path: Path) -> list[Path]:
    """The MCAP files of a bag (a folder, or one file), in name order (rosbag2's split order)."""
    if path.is_file():
        return [path] if path.suffix == ".mcap" else []
    return sorted(path.glob("*.mcap"))


class SalvageReader:
    """Reads a bag's MCAP files record by record, as far as they go.

    ``cut`` says where reading stopped early ("file.mcap: ..."), or is None when every file
    ended as MCAP files end. Opening reads the files once (to learn the topics and count the
    messages); ``messages`` reads them again.
    """

    is2 = True

    def __init__(self, files: Iterable[Path]) -> None:
        self.files = list(files)
        self.typestore = get_typestore(Stores.ROS2_JAZZY)
        self.connections: list[Connection] = []
        self.topics: dict[str, TopicInfo] = {}
        self.cut: str | None = None
        counts: dict[int, int] = {}
        for _file, record in self._records():
            if isinstance(record, Message):
                counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
        for conn in self.connections:
            info = self.topics.setdefault(conn.topic, TopicInfo(conn.msgtype, 0))
            info.msgcount += counts.get(conn.id, 0)

    def _records(self) -> Iterator[tuple[Path, Any]]:
        """(file, record) of every schema, channel and message, up to the first damage."""
        schemas: dict[int, Schema] = {}
        known = {c.id for c in self.connections}
        for file in self.files:
            with open(file, "rb") as f:
                try:
                    for record in StreamReader(f, record_size_limit=1 << 30).records:
                        if isinstance(record, Schema):
                            schemas[record.id] = record
                            self._register(record)
                        elif isinstance(record, Channel) and record.id not in known and record.schema_id in schemas:
                            known.add(record.id)
                            self.connections.append(
                                Connection(record.id, record.topic, schemas[record.schema_id].name))
                        elif isinstance(record, Message):
                            yield file, record
                except Exception as exc:  # noqa: BLE001 - a cut shows as many kinds of error
                    self.cut = f"{file.name}: {type(exc).__name__}: {' '.join(str(exc).split())}"[:200]
                    return

    def _register(self, schema: Schema) -> None:
        """Teach the typestore a type the recording defines and Jazzy's does not know."""
        if schema.encoding != _ROS2_MSG or schema.name in self.typestore.fielddefs:
            return
        try:
            self.typestore.register(get_types_from_msg(schema.data.decode(), schema.name))
        except Exception:  # noqa: BLE001 - an unreadable definition: its messages will not deserialise
            pass

    def messages(self, connections: Iterable[Connection]) -> Iterator[tuple[Connection, int, bytes]]:
        by_id = {c.id: c for c in connections}
        for _file, record in self._records():
            conn = by_id.get(record.channel_id)
            if conn is not None:
                yield conn, record.log_time, record.data

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        return self.typestore.deserialize_cdr(raw, msgtype)

    def close(self) -> None:
        pass
