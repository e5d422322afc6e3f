"""Amplitude and depth image pairs in a folder: the Kinect v2 data set's layout, which is also
what ``calibration_file.save_views`` writes (with each view's corners in ``<name>_corners.csv``,
which are then used as they are instead of being detected again).

A pair is ``<name>_ir.<ext>`` (or ``_amplitude``) with ``<name>_depth.<ext>``, in 16- or 8-bit
PNG, TIFF or NPY (extensions may differ within a pair). Integer depth counts ``depth_scale``
metres (millimetres by default), float depth is metres; 0 and NaN are invalid. Pairs are taken
in name order; each is a still, so the collector's motion check does not apply to them.
"""
from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..collect.replay import FrameError, Skip
from ..core.detection import IMAGE_DTYPES
from ..core.inputs import View, depth_in_metres
from .calibration_file import CORNERS_SUFFIX, CalibrationFileError, read_corners
from .image_decode import ImageTooLarge, check_pixels

EXTENSIONS = (".png", ".tif", ".tiff", ".npy")
AMPLITUDE_SUFFIXES = ("ir", "amplitude")
DEPTH_SUFFIX = "depth"
_NAME = re.compile(r"(?P<stem>.+)_(?P<kind>[A-Za-z]+)$")


def _read(path: Path) -> np.ndarray:
    try:
        size = _header_size(path)
        if size is not None:
            check_pixels(*size, where=path.name)
        image = (np.load(path, allow_pickle=False) if path.suffix.lower() == ".npy"
                 else cv2.imread(str(path), cv2.IMREAD_UNCHANGED))
    except ImageTooLarge as exc:
        raise FrameError("too_large", str(exc)) from None
    except (OSError, ValueError, MemoryError, struct.error) as exc:
        raise FrameError("unreadable", f"{path.name}: {type(exc).__name__}: {exc}") from None
    if image is None:
        raise FrameError("unreadable", f"{path.name}: missing or not a readable image")
    if image.ndim != 2 or image.dtype.type not in IMAGE_DTYPES:
        raise FrameError("encoding", f"{path.name}: {image.dtype} image of shape {image.shape}; need one "
                                     "channel of uint8, uint16, int16 or float")
    return image


def _header_size(path: Path) -> tuple[int, int] | None:
    """(width, height) from the file's header, read before the image is: a small file may hold a
    huge image (a 20000x20000 PNG of 836 kB). None where the header does not say (the decoder
    then finds out what it is)."""
    with open(path, "rb") as f:
        head = f.read(32)
        if head.startswith(b"\x89PNG\r\n\x1a\n") and head[12:16] == b"IHDR":
            return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
        if head[:4] in (b"II*\x00", b"MM\x00*"):
            return _tiff_size(f, "<" if head[:2] == b"II" else ">", int.from_bytes(head[4:8], _ORDER[head[:2]]))
        if head.startswith(b"\x93NUMPY"):
            f.seek(0)
            version = np.lib.format.read_magic(f)
            shape = (np.lib.format.read_array_header_1_0(f) if version == (1, 0)
                     else np.lib.format.read_array_header_2_0(f))[0]
            return (int(shape[1]), int(shape[0])) if len(shape) == 2 else (int(np.prod(shape)), 1)
    return None


_ORDER = {b"II": "little", b"MM": "big"}


def _tiff_size(f, endian: str, offset: int) -> tuple[int, int] | None:
    """ImageWidth (256) and ImageLength (257) from a TIFF's first directory."""
    f.seek(offset)
    (count,) = struct.unpack(endian + "H", f.read(2))
    found = {}
    for _ in range(min(count, 512)):
        tag, kind, _n, value = struct.unpack(endian + "HHI4s", f.read(12))
        if tag in (256, 257):
            found[tag] = struct.unpack(endian + ("H" if kind == 3 else "I"), value[:2 if kind == 3 else 4])[0]
    return (found[256], found[257]) if len(found) == 2 else None


@dataclass(frozen=True)
class ImageFile:
    """An image file, read where it is needed (a worker reads the amplitude to find the board)."""

    path: Path
    corners_path: Path | None = None
    n_corners: int = 0
    nbytes: int = 0   # not read yet

    def load(self) -> np.ndarray:
        return _read(self.path)

    def saved_corners(self) -> np.ndarray | None:
        if self.corners_path is None:
            return None
        try:
            ids, corners = read_corners(self.corners_path)
        except CalibrationFileError as exc:
            raise FrameError("unreadable", str(exc)) from None
        if len(ids) != self.n_corners or np.any(ids != np.arange(self.n_corners)):
            raise FrameError("unreadable", f"{self.corners_path.name}: holds corners {ids.min(initial=0)} to "
                                           f"{ids.max(initial=-1)} of {len(ids)}, not the whole board's "
                                           f"{self.n_corners} in order")
        return corners


@dataclass(frozen=True)
class FileFrame:
    """One amplitude/depth pair of files."""

    stamp: float
    where: str
    amplitude_path: Path
    depth_path: Path
    depth_scale: float
    corners_path: Path | None = None
    n_corners: int = 0

    def amplitude_source(self) -> ImageFile:
        return ImageFile(self.amplitude_path, self.corners_path, self.n_corners)

    def decode(self) -> tuple[np.ndarray, np.ndarray]:
        amplitude, depth = _read(self.amplitude_path), _read(self.depth_path)
        if amplitude.shape != depth.shape:
            raise FrameError("size", f"{self.amplitude_path.name} is {amplitude.shape[1]}x{amplitude.shape[0]} "
                                     f"but {self.depth_path.name} is {depth.shape[1]}x{depth.shape[0]}")
        scale = self.depth_scale if np.issubdtype(depth.dtype, np.integer) else 1.0
        return amplitude, depth_in_metres(depth, scale)


def is_image_folder(path: Path) -> bool:
    """A folder of image pairs rather than a rosbag2 folder (which has metadata.yaml, or at least
    its storage files)."""
    return (path.is_dir() and not (path / "metadata.yaml").exists()
            and not any(path.glob("*.db3")) and not any(path.glob("*.mcap")))


def scan(directory: str | Path, depth_scale: float = 0.001,
         n_corners: int = 0) -> tuple[list[FileFrame], list[Skip]]:
    """The folder's pairs in name order, and a Skip for each image without its partner.

    Frames get stamps one second apart: they only order the stills. A pair's saved corners
    (``<name>_corners.csv``) are used when ``n_corners`` (the board's) is given.
    """
    directory = Path(directory)
    found: dict[str, dict[str, Path]] = {}
    for path in sorted(directory.iterdir()):
        match = _NAME.match(path.stem)
        if path.suffix.lower() not in EXTENSIONS or match is None:
            continue
        kind = match["kind"].lower()
        role = "amplitude" if kind in AMPLITUDE_SUFFIXES else "depth" if kind == DEPTH_SUFFIX else None
        if role is not None:
            found.setdefault(match["stem"], {})[role] = path
    frames, skips = [], []
    for stem in sorted(found):
        pair = found[stem]
        if len(pair) < 2:
            (role, path), = pair.items()
            skips.append(Skip("unreadable", path.name, f"no {'depth' if role == 'amplitude' else 'amplitude'} "
                                                       f"image beside {path.name}"))
            continue
        corners = directory / f"{stem}{CORNERS_SUFFIX}"
        frames.append(FileFrame(float(len(frames)), stem, pair["amplitude"], pair["depth"], depth_scale,
                                corners if n_corners and corners.exists() else None, n_corners))
    return frames, skips


def load_views(directory: str | Path) -> list[View]:
    """The views ``save_views`` wrote (or the Kinect v2 set), in name order, as they are stored
    (integer depth in its units, millimetres there), with the corners they were calibrated with
    where those were saved; CalibrationFileError names the first pair that cannot be read."""
    frames, skips = scan(directory)
    if skips:
        raise CalibrationFileError(f"{directory}: {skips[0].reason}")
    if not frames:
        raise CalibrationFileError(f"{directory}: no amplitude/depth pairs (NNNN_ir.png with NNNN_depth.png)")
    views = []
    for frame in frames:
        try:
            amplitude, depth = _read(frame.amplitude_path), _read(frame.depth_path)
        except FrameError as exc:
            raise CalibrationFileError(str(exc)) from None
        corners_path = frame.depth_path.with_name(f"{frame.where}{CORNERS_SUFFIX}")
        ids, corners = read_corners(corners_path) if corners_path.exists() else (None, None)
        views.append(View(depth=depth, corners=corners, ids=ids, amplitude=amplitude))
    return views
