"""Replaying recorded frames (a bag, a folder of images) through the node's view collector.

The collector's judgment is sequential (whether a view is new depends on the views kept so
far), but most of the cost is per frame: finding the board. That part runs in worker processes,
on chunks of consecutive frames, in order; the collector judges the results one by one in this
process. Only the amplitude images go to the workers and only the corners come back: this
process decodes the images it judges itself. At most one chunk more than there are workers is
under way, so memory does not grow with the recording. Within a chunk the board is followed
from frame to frame (``quick_locate(near=...)``): a board held still for calibration is where
it was. The kept views' accurate corners are found in the workers too, once every frame is
judged (``Replay._sharpen``). The chunking is the same for any number of workers, so one worker
and two give the same views.

Frames that cannot be used (undecodable, wrong encoding, bad layout, another size, stamps out
of order, unreadable files) are skipped and counted by kind, never raised.
"""
from __future__ import annotations

import itertools
import multiprocessing
import os
import re
from collections import Counter, deque
from collections.abc import Callable, Iterable, Iterator
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field, replace
from multiprocessing.pool import Pool
from typing import Protocol

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

from ..core.board import Board
from ..core.detection import Detection
from ..core.errors import CalibrationError
from ..core.threads import single_threaded
from .collector import CollectorConfig, Outcome, ViewCollector
from .tracking import BoardTracker, accurate_detect, quick_locate

# kind -> what it means, for the summary
SKIP_KINDS = {
    "undecodable": "serialized data could not be decoded (truncated or garbage)",
    "encoding": "unsupported image encoding",
    "layout": "image data does not match its step x height (or a bad step)",
    "size": "image of another size",
    "too_large": "image beyond the pixel limit (image_decode.MAX_PIXELS), not decoded",
    "stamp_order": "header stamp not after the previous one on its topic",
    "unreadable": "image file missing or unreadable",
    "read_error": "the rest of the bag could not be read",
}
# A chunk of a stream holds up to this many frames, or fewer once its images reach CHUNK_BYTES:
# the first frame of a chunk has no previous one to follow the board from, so chunks are long.
CHUNK_FRAMES = 32
CHUNK_BYTES = 24 << 20
EXAMPLES_PER_KIND = 3


class FrameError(CalibrationError):
    """A frame that cannot be used; ``kind`` is one of ``SKIP_KINDS``."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


@dataclass(frozen=True)
class Skip:
    """A message or frame left out, and why."""

    kind: str
    where: str
    reason: str


class ImageSource(Protocol):
    """An image to read in a worker process: it must pickle small (the message bytes or a path)."""

    nbytes: int

    def load(self) -> np.ndarray:
        """The image; raises FrameError."""

    def saved_corners(self) -> np.ndarray | None:
        """The whole board's corners saved with the image (a calibration's ``views/``), if any;
        raises FrameError."""


class Frame(Protocol):
    """A pair of amplitude and depth images. A worker reads the amplitude to find the board in
    it; this process reads both for the collector (so the images never travel back)."""

    stamp: float
    where: str

    def amplitude_source(self) -> ImageSource: ...

    def decode(self) -> tuple[np.ndarray, np.ndarray]:
        """(amplitude, depth in float metres with NaN invalid); raises FrameError."""


@dataclass(frozen=True)
class Located:
    """A frame's quick corners and, for stills, its accurate ones."""

    found: Detection
    accurate: Detection | None = None


def _locate_chunk(sources: list[ImageSource], board: Board, config: CollectorConfig) -> list[Located | Skip]:
    """The per-frame work, in a worker: read the amplitude image and find the board, followed
    through a stream as the node does (``BoardTracker``), and searched for on every frame where it
    is lost (thoroughly on small images, ``BoardTracker``): offline there is time, and a lost view
    is lost for good. A still (a folder of images) has no such history, and nearly every still
    with a board is a view worth keeping, so it is searched for thoroughly at any size and its
    accurate corners are found here too. A Skip's ``where`` is left for the caller to fill."""
    out: list[Located | Skip] = []
    tracker = BoardTracker(board)
    for source in sources:
        try:
            amplitude = source.load()
            saved = source.saved_corners() if config.stills else None
        except FrameError as exc:
            out.append(Skip(exc.kind, "", str(exc)))
            tracker.forget()
            continue
        if saved is not None:   # a view the node or tof_calib kept: the corners it was calibrated with
            known = Detection(saved, "the corners saved with the view")
            out.append(Located(known, known))
            continue
        if config.stills:
            out.append(locate_still(amplitude, board, config))
            continue
        out.append(Located(tracker.locate(amplitude, thorough=True)))
    return out


def locate_still(amplitude: np.ndarray, board: Board, config: CollectorConfig) -> Located:
    """A still's board, searched for in the whole image, and its accurate corners."""
    found = quick_locate(amplitude, board, thorough=True)
    return Located(found, None if found.corners is None else
                   accurate_detect(amplitude, board, found.corners))


def worker_context() -> multiprocessing.context.BaseContext:
    """Workers from a fresh process, not forked from this one: a fork copies OpenCV's and the
    BLAS's thread pools in a state the child cannot use (once this process has calibrated, a
    forked worker hangs in its first detection). The fork server is started once, with the
    worker's modules loaded, and forks the workers from there."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload([__name__])
    return context


def init_worker() -> None:
    # Each worker has one core's worth of work: threads would only contend.
    cv2.setNumThreads(1)
    threadpool_limits(1)


def _chunks(frames: Iterable[Frame | Skip], on_skip: Callable[[Skip], None], most: int) -> Iterator[list[Frame]]:
    chunk: list[Frame] = []
    size = 0
    for item in frames:
        if isinstance(item, Skip):
            on_skip(item)
            continue
        chunk.append(item)
        size += item.amplitude_source().nbytes
        if len(chunk) >= most or size >= CHUNK_BYTES:
            yield chunk
            chunk, size = [], 0
    if chunk:
        yield chunk


def default_workers() -> int:
    """Two (the issue's 'both cores'), or one on a single-core machine."""
    return max(1, min(2, os.cpu_count() or 1))


def reason_key(reason: str) -> str:
    """A rejection reason without its details and measured values, to count reasons by kind."""
    return re.sub(r"[-+]?\d+\.\d+", "N", re.split(r"[:(]", reason, maxsplit=1)[0]).strip()


@dataclass
class Summary:
    """What a replay saw: counts, skips by kind (with a few examples), rejection reasons."""

    frames: int = 0                    # decoded pairs judged by the collector
    boards: int = 0                    # of them with a board found
    skipped: Counter = field(default_factory=Counter)
    examples: dict[str, list[Skip]] = field(default_factory=dict)
    rejections: Counter = field(default_factory=Counter)
    view_stamps: list[float] = field(default_factory=list)
    image_size: tuple[int, int] | None = None

    def skip(self, item: Skip) -> None:
        self.skipped[item.kind] += 1
        examples = self.examples.setdefault(item.kind, [])
        if len(examples) < EXAMPLES_PER_KIND:
            examples.append(item)


def decode_sized(frame: Frame, size: tuple[int, int] | None) -> tuple[np.ndarray, np.ndarray]:
    """The frame's images; FrameError ("size") when they are not ``size`` (width, height)."""
    amplitude, depth = frame.decode()
    h, w = depth.shape
    if size is not None and (w, h) != tuple(size):
        raise FrameError("size", f"image is {w}x{h}, the recording's is {size[0]}x{size[1]}")
    return amplitude, depth


class Replay:
    """Feeds frames to a ``ViewCollector`` with the node's rules; ``run`` returns the summary.

    ``image_size`` (width, height), when known (from camera_info), is what every frame must
    have; otherwise the first decoded frame sets it. ``progress`` is called after every frame
    with the summary and the collector. The node replays a recording through this too: into its
    own ``collector``, under the ``lock`` its services read the views with, hearing of each
    frame's ``on_outcome`` and each ``on_skip``. With more than one worker, the workers are started as
    fresh processes (``worker_context``), which import the calling script's main module: a script that
    runs a replay must do so under ``if __name__ == "__main__":``, as multiprocessing requires.
    """

    def __init__(self, board: Board, config: CollectorConfig, *, workers: int = 1,
                 image_size: tuple[int, int] | None = None,
                 progress: Callable[[Summary, ViewCollector], None] | None = None,
                 collector: ViewCollector | None = None, lock: AbstractContextManager | None = None,
                 on_outcome: Callable[[Frame, np.ndarray, Outcome], None] | None = None,
                 on_skip: Callable[[Skip], None] | None = None) -> None:
        if workers < 1:
            raise CalibrationError(f"workers must be at least 1, got {workers}")
        self.board = board
        # the node replays into its own collector, under the lock its services read it with
        self.collector = ViewCollector(board, config) if collector is None else collector
        self._lock = lock or nullcontext()
        self.workers = workers
        self.summary = Summary(image_size=image_size)
        self._progress = progress or (lambda _s, _c: None)
        self._on_outcome = on_outcome or (lambda _f, _a, _o: None)
        self._on_skip = on_skip or (lambda _s: None)

    def run(self, frames: Iterable[Frame | Skip]) -> Summary:
        with self._pool() as pool:
            for frame, result in self._located(frames, pool):
                if isinstance(result, Skip):
                    self._skip(replace(result, where=frame.where))
                else:
                    self._judge(frame, result)
                self._progress(self.summary, self.collector)
            self._sharpen(pool)
        return self.summary

    def _sharpen(self, pool: Pool | None) -> None:
        """The kept views' accurate corners, in the workers, only now that the views are known: a
        view swapped out on the way never costs them (about half of those a 1,000-frame
        recording at 200x200 would have cost), and whichever worker finds them, the views are the same."""
        with self._lock:
            todo = self.collector.unsharpened()
        work = [(amplitude, self.board, quick) for _, amplitude, quick in todo]
        if pool is None:
            with single_threaded():   # as in a worker
                found = list(itertools.starmap(accurate_detect, work))
        else:
            found = pool.starmap(accurate_detect, work)
        with self._lock:
            dropped = self.collector.sharpen({key: f for (key, *_), f in zip(todo, found)})
            self.summary.view_stamps = self.collector.stamps
        for reason in dropped:
            self.summary.rejections[reason_key(reason.split(": ", 1)[1])] += 1

    def _pool(self) -> AbstractContextManager:
        """The worker processes, or None (nullcontext) for one worker: this process does it all."""
        if self.workers == 1:
            return nullcontext()
        return worker_context().Pool(self.workers, initializer=init_worker)

    def _skip(self, skip: Skip) -> None:
        self.summary.skip(skip)
        self._on_skip(skip)

    def _judge(self, frame: Frame, located: Located) -> None:
        s = self.summary
        try:
            amplitude, depth = decode_sized(frame, s.image_size)
        except FrameError as exc:
            self._skip(Skip(exc.kind, frame.where, str(exc)))
            return
        if s.image_size is None:
            s.image_size = (depth.shape[1], depth.shape[0])
        s.frames += 1
        s.boards += located.found.corners is not None
        with self._lock:
            outcome: Outcome = self.collector.add(amplitude, depth, frame.stamp, located=located.found,
                                                  detected=located.accurate)
        self._on_outcome(frame, amplitude, outcome)
        if outcome.accepted:
            s.view_stamps = self.collector.stamps
        else:
            s.rejections[reason_key(outcome.reason)] += 1

    def _located(self, frames: Iterable[Frame | Skip], pool: Pool | None) -> Iterator[tuple[Frame, Located | Skip]]:
        """Each frame with what a worker (of ``pool``; this process without) found in its
        amplitude image, in order."""
        config = self.collector.config
        # a still depends on no other frame, and costs a whole detection: one per task balances best
        chunks = _chunks(frames, self._skip, 1 if config.stills else CHUNK_FRAMES)

        def work(chunk: list[Frame]) -> tuple:
            return [f.amplitude_source() for f in chunk], self.board, config

        if pool is None:   # here, as single-threaded as a worker: one worker means one core
            with single_threaded():
                for chunk in chunks:
                    yield from zip(chunk, _locate_chunk(*work(chunk)))
            return
        pending: deque = deque()
        for chunk in chunks:
            pending.append((chunk, pool.apply_async(_locate_chunk, work(chunk))))
            if len(pending) > self.workers:   # one running in each worker, one waiting
                chunk, result = pending.popleft()
                yield from zip(chunk, result.get())
        while pending:
            chunk, result = pending.popleft()
            yield from zip(chunk, result.get())
