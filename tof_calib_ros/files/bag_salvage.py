"""Every message of a recording up to where it was cut off.

rosbags opens an MCAP file from its summary, at the end of the file, a sqlite3 file through
SQLite, which refuses a file shorter than its header says, and a bag's folder from its
metadata.yaml, which rosbag2 writes when it closes: a recorder killed mid-recording leaves
none of these, and rosbags refuses the whole recording. What was written before the cut is
still there:

- MCAP's records follow one another from the start, schemas and channels before the messages
  that use them: they are read in order with the mcap library's stream reader, decompressing
  chunks as it goes, until the cut. The chunk the cut falls in is lost with it (rosbag2 writes
  chunks of about 1 MB: a few frames).
- A sqlite3 file is pages: the table leaf pages that are whole hold the rows, the topics' and
  the messages' (``id, topic_id, timestamp, data``), each message's data continued on overflow
  pages. They are read from the file as SQLite lays them out (sqlite.org/fileformat2.html);
  a message whose overflow chain reaches past the cut is lost.

Only what ``bag_io.BagSource`` asks of a reader is provided.
"""
from __future__ import annotations

import mmap
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


def storage_files(path: Path, suffix: str) -> list[Path]:
    """A bag's files of one storage (``.mcap``, ``.db3``; a folder, or one file), in name order
    (rosbag2's split order)."""
    if path.is_file():
        return [path] if path.suffix == suffix else []
    return sorted(path.glob(f"*{suffix}"))


class _Salvage:
    """What both readers give ``BagSource``: ``connections``, ``topics`` (with their message
    counts), ``deserialize`` and ``cut``, the reason reading stopped early (None: it did not)."""

    is2 = True

    def __init__(self, files: Iterable[Path]) -> None:
        self.files = list(files)
        self.typestore = get_typestore(Stores.ROS2_JAZZY)
        self.connections: list[Connection] = []
        self.topics: dict[str, TopicInfo] = {}
        self.cut: str | None = None

    def _count(self, counts: dict[int, int]) -> None:
        """``topics`` from the messages counted per connection id."""
        for conn in self.connections:
            info = self.topics.setdefault(conn.topic, TopicInfo(conn.msgtype, 0))
            info.msgcount += counts.get(conn.id, 0)

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        return self.typestore.deserialize_cdr(raw, msgtype)


class McapSalvage(_Salvage):
    """Reads a bag's MCAP files record by record, as far as they go. Opening reads the files
    once (to learn the topics and count the messages); ``messages`` reads them again."""

    def __init__(self, files: Iterable[Path]) -> None:
        super().__init__(files)
        counts: dict[int, int] = {}
        for record in self._records():
            counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
        self._count(counts)

    def _records(self) -> Iterator[Message]:
        """Every message up to the first damage, learning the schemas and channels on the way."""
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
                            yield record
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
        for record in self._records():
            conn = by_id.get(record.channel_id)
            if conn is not None:
                yield conn, record.log_time, record.data

    def close(self) -> None:
        pass


class SqliteSalvage(_Salvage):
    """Reads the rows of a bag's sqlite3 files from their whole table leaf pages. Opening scans
    the pages once for the topics and an index of the messages (file, page, cell; not their
    data), which ``messages`` then reads in timestamp order."""

    def __init__(self, files: Iterable[Path]) -> None:
        super().__init__(files)
        cuts = []
        topics: dict[int, tuple[str, str]] = {}
        found: dict[int, tuple[int, int, int, int, int]] = {}   # rowid -> (timestamp, topic, file, page, cell)
        self._pages: list[_Pages] = []
        lost = 0
        for k, file in enumerate(self.files):
            pages = _Pages(file)
            self._pages.append(pages)
            if pages.torn:
                cuts.append(f"{file.name}: the file ends inside page {pages.count + 1}")
            for page in range(1, pages.count + 1):
                for cell in pages.leaf_cells(page):
                    row = pages.row(page, cell, with_blob=False)
                    if row is None:
                        lost += 1
                        continue
                    rowid, values = row
                    if _is_topic(values):
                        topics[rowid] = (values[1], values[2])
                    elif _is_message(values):
                        found[(k << 48) | rowid] = (values[2], values[1], k, page, cell)
        if lost:
            cuts.append(f"{lost} rows reach past the end")
        self.cut = "; ".join(cuts) or None
        self.connections = [Connection(i, name, msgtype) for i, (name, msgtype) in sorted(topics.items())]
        self._index = sorted(found.values())
        counts: dict[int, int] = {}
        for _stamp, topic, *_ in self._index:
            counts[topic] = counts.get(topic, 0) + 1
        self._count(counts)

    def messages(self, connections: Iterable[Connection]) -> Iterator[tuple[Connection, int, bytes]]:
        by_id = {c.id: c for c in connections}
        for stamp, topic, k, page, cell in self._index:
            conn = by_id.get(topic)
            if conn is not None:
                row = self._pages[k].row(page, cell, with_blob=True)
                if row is not None:
                    yield conn, stamp, row[1][3]

    def close(self) -> None:
        for pages in self._pages:
            pages.close()


def _is_topic(values: list) -> bool:
    """A row of rosbag2's topics table: id, name, type, serialization_format, ... ."""
    return (len(values) >= 5 and all(isinstance(v, str) for v in values[1:5]) and values[3] == "cdr"
            and "/msg/" in values[2])


def _is_message(values: list) -> bool:
    """A row of the messages table: id (the rowid), topic_id, timestamp, data."""
    return (len(values) == 4 and values[0] is None and all(isinstance(v, int) for v in values[1:3])
            and isinstance(values[3], (bytes, int)))


class _Pages:
    """A sqlite3 file read page by page, as far as its pages are whole."""

    def __init__(self, file: Path) -> None:
        with open(file, "rb") as f:
            self._map = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) if file.stat().st_size else b""
        head = self._map[:100]
        if len(head) < 100 or not head.startswith(b"SQLite format 3\x00"):
            self.size = self.usable = self.count = 0
            self.torn = True
            return
        size = int.from_bytes(head[16:18], "big")
        self.size = 65536 if size == 1 else size
        self.usable = self.size - head[20]
        self.count, self.torn = len(self._map) // self.size, len(self._map) % self.size != 0

    def close(self) -> None:
        if isinstance(self._map, mmap.mmap):
            self._map.close()

    def page(self, number: int) -> bytes | None:
        if not 1 <= number <= self.count:
            return None
        return self._map[(number - 1) * self.size:number * self.size]

    def leaf_cells(self, number: int) -> list[int]:
        """Offsets of the cells of a table leaf page (type 13), none for any other page."""
        data = self.page(number)
        start = 100 if number == 1 else 0
        if data is None or data[start] != 13:
            return []
        n = int.from_bytes(data[start + 3:start + 5], "big")
        cells = [int.from_bytes(data[start + 8 + 2 * i:start + 10 + 2 * i], "big") for i in range(n)]
        return [c for c in cells if start + 8 + 2 * n <= c < self.size]

    def row(self, number: int, cell: int, with_blob: bool) -> tuple[int, list] | None:
        """(rowid, column values) of one cell; a blob is its length unless ``with_blob``. None
        when the row's overflow pages are missing or the cell is garbage."""
        data = self.page(number)
        try:
            length, i = _varint(data, cell)
            rowid, i = _varint(data, i)
            local = _local_size(length, self.usable)
            payload = data[i:i + local]
            if local < length:
                need = length if with_blob else min(length, local + 4096)   # the record header, at least
                next_page = int.from_bytes(data[i + local:i + local + 4], "big")
                parts = [payload]
                have = local
                while have < need:
                    page = self.page(next_page)
                    if page is None:
                        return None
                    parts.append(page[4:self.usable])
                    have += self.usable - 4
                    next_page = int.from_bytes(page[:4], "big")
                payload = b"".join(parts)[:need]
            return rowid, _record(payload, length, with_blob)
        except (IndexError, ValueError, UnicodeDecodeError):
            return None


def _local_size(length: int, usable: int) -> int:
    """How much of a table leaf cell's payload is on its page (the rest on overflow pages)."""
    most = usable - 35
    if length <= most:
        return length
    least = (usable - 12) * 32 // 255 - 23
    k = least + (length - least) % (usable - 4)
    return k if k <= most else least


def _varint(data: bytes, i: int) -> tuple[int, int]:
    value = 0
    for k in range(8):
        b = data[i + k]
        value = (value << 7) | (b & 0x7F)
        if b < 0x80:
            return value, i + k + 1
    return (value << 8) | data[i + 8], i + 9


_INT_BYTES = {1: 1, 2: 2, 3: 3, 4: 4, 5: 6, 6: 8}


def _record(payload: bytes, length: int, with_blob: bool) -> list:
    """The column values of a record; a blob beyond ``payload`` (not read), unless ``with_blob``, as its length."""
    header, i = _varint(payload, 0)
    types = []
    while i < header:
        t, i = _varint(payload, i)
        types.append(t)
    values, at = [], header
    for t in types:
        if t == 0:
            values.append(None)
        elif t in _INT_BYTES:
            n = _INT_BYTES[t]
            values.append(int.from_bytes(payload[at:at + n], "big", signed=True))
            at += n
        elif t == 7:
            at += 8
            values.append(float("nan"))   # no float column is read
        elif t in (8, 9):
            values.append(t - 8)
        elif t >= 12:
            n = (t - 12) // 2
            if t % 2 == 0:
                values.append(payload[at:at + n] if with_blob or at + n <= len(payload) else n)
            else:
                values.append(payload[at:at + n].decode())
            at += n
        else:
            raise ValueError(f"serial type {t}")
    if at > length:
        raise ValueError("record longer than its cell")
    return values
