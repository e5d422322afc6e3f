"""Calibration files: the ROS camera YAML, the full JSON report, and the views behind them.

The YAML is the schema camera_calibration_parsers writes and camera_info_manager loads, so a
camera driver picks the result up unchanged. Every file is written atomically (see
``atomic_write``): a crash while saving never costs the previous calibration.
"""
from __future__ import annotations

import json
import math
import os
import re
import secrets
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from ..core.camera import MODEL_TERMS, distortion_model
from ..core.errors import CalibrationError
from ..core.inputs import View, depth_in_metres

DISTORTION_MODEL = "plumb_bob"   # what a file without the key means
# camera_info_manager refuses any other camera name (CameraInfoManager::validateName)
CAMERA_NAME = re.compile(r"[A-Za-z0-9_]+")
_MAX_MM = np.iinfo(np.uint16).max
_MAX_SIZE = np.iinfo(np.uint32).max


class CalibrationFileError(CalibrationError):
    """A calibration file that cannot be written or read as asked; the message names the file."""


@dataclass
class CameraYaml:
    """The contents of a camera calibration YAML file."""

    camera_name: str
    width: int
    height: int
    distortion_model: str
    K: np.ndarray   # (3, 3)
    D: np.ndarray   # (n,)
    R: np.ndarray   # (3, 3)
    P: np.ndarray   # (3, 4)


def atomic_write(path: str | os.PathLike, data: bytes) -> Path:
    """Replace ``path`` with ``data`` so that readers see the old file or the new, never a part.

    The data goes to a hidden temporary file in the same directory (a rename is atomic only
    within one file system), is flushed to disk, then renamed over the target; the directory
    is synced so the rename itself survives a power cut. On an error the temporary file is
    removed (OSError becomes CalibrationFileError); after SIGKILL one may remain, named
    ``.<name>.<pid>.<random>.tmp``.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    created = False
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        # O_EXCL: never follow or clobber anything already there; 0o666 lets the umask decide
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        created = True
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
        created = False
        sync_dir(path.parent)
    except BaseException as exc:
        if created:
            tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise CalibrationFileError(f"cannot write {path}: {exc.strerror or exc}") from exc
        raise
    return path


def sync_dir(path: Path) -> None:
    """Flush a directory's entries, so that a rename in it survives a power cut."""
    if not hasattr(os, "O_DIRECTORY"):   # POSIX; Windows cannot open a directory
        return
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _matrix(rows: int, cols: int, values) -> dict:
    return {"rows": rows, "cols": cols, "data": [float(v) for v in np.ravel(values)]}


def monocular_fields(K: np.ndarray, D: np.ndarray, size: tuple[int, int]) -> dict:
    """The sensor_msgs/CameraInfo fields of a monocular camera, as camera_calibration fills them:
    plumb_bob (rational_polynomial for 8 terms), R the identity, P = [K | 0]. The node's message,
    the simulated driver's, a bag's and the YAML file are all made from these."""
    K = np.asarray(K, dtype=float).reshape(3, 3)
    return {"width": int(size[0]), "height": int(size[1]), "distortion_model": distortion_model(D),
            "d": [float(x) for x in np.ravel(D)], "k": [float(x) for x in K.ravel()],
            "r": [float(x) for x in np.eye(3).ravel()],
            "p": [float(x) for x in np.hstack([K, np.zeros((3, 1))]).ravel()]}


def _intrinsics(source: Any) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """K, D and (width, height) from a CalibrationResult or a mapping with the same names."""
    names = ("K", "D", "image_size")
    K, D, size = (source.get(n) if isinstance(source, Mapping) else getattr(source, n, None) for n in names)
    missing = [n for n, v in zip(names, (K, D, size)) if v is None]
    if missing:
        raise CalibrationFileError(f"need K, D and image_size to write a camera file; missing: {', '.join(missing)}")
    try:
        K, D = np.asarray(K, dtype=float), np.asarray(D, dtype=float).ravel()
        w, h = (int(v) for v in size)
    except (TypeError, ValueError) as exc:
        raise CalibrationFileError(f"K, D must be numbers and image_size (width, height): {exc}") from None
    if K.shape != (3, 3):
        raise CalibrationFileError(f"K must be 3x3, got shape {K.shape}")
    if D.size not in MODEL_TERMS.values():
        raise CalibrationFileError("D must hold the 5 plumb_bob terms (k1, k2, p1, p2, k3) or the 8 of "
                                   f"rational_polynomial (k4, k5, k6 after them), got {D.size}")
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(D))):
        raise CalibrationFileError("K or D has NaN or inf values; refusing to write them as a calibration")
    if w <= 0 or h <= 0:
        raise CalibrationFileError(f"image size must be positive, got {w}x{h}")
    return K, D, (w, h)


def write_camera_yaml(path: str | os.PathLike, source: Any, camera_name: str) -> Path:
    """Write K and D (from a CalibrationResult, or a mapping with K, D, image_size) for ROS."""
    return atomic_write(path, camera_yaml(source, camera_name))


def camera_yaml(source: Any, camera_name: str) -> bytes:
    """A monocular camera has R = identity and P = [K | 0]. Floats are written in full (repr),
    so reading the file back gives the same numbers bit for bit."""
    if not isinstance(camera_name, str) or not CAMERA_NAME.fullmatch(camera_name):
        raise CalibrationFileError(f"camera name {camera_name!r} must be letters, digits and '_' only "
                                   "(camera_info_manager rejects anything else)")
    f = monocular_fields(*_intrinsics(source))
    doc = {
        "image_width": f["width"],
        "image_height": f["height"],
        "camera_name": camera_name,
        "camera_matrix": _matrix(3, 3, f["k"]),
        "distortion_model": f["distortion_model"],
        "distortion_coefficients": _matrix(1, len(f["d"]), f["d"]),
        "rectification_matrix": _matrix(3, 3, f["r"]),
        "projection_matrix": _matrix(3, 4, f["p"]),
    }
    # default_flow_style=None: lists (the data) in flow style, maps in block style, as
    # camera_calibration_parsers writes; an unlimited width keeps each list on one line
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=math.inf).encode()


def _number(value: Any, where: str) -> float:
    # yaml-cpp writes 1e-05 where YAML 1.1 (PyYAML) wants 1.0e-05, so numbers may come as text
    if isinstance(value, bool):
        raise CalibrationFileError(f"{where}: expected a number, got {_short(value)}")
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise CalibrationFileError(f"{where}: expected a number, got {_short(value)}") from None
    if not math.isfinite(number):
        raise CalibrationFileError(f"{where}: {value!r} is not a finite number")
    return number


def _read_matrix(doc: dict, key: str, shape: tuple[int, int] | None, where: str) -> np.ndarray:
    node = doc.get(key)
    if not isinstance(node, dict):
        raise CalibrationFileError(f"{where}: missing {key} (a map with rows, cols and data)")
    for field in ("rows", "cols", "data"):
        if field not in node:
            raise CalibrationFileError(f"{where}: {key} has no {field}")
    rows, cols, data = node["rows"], node["cols"], node["data"]
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in (rows, cols)):
        raise CalibrationFileError(f"{where}: {key} rows and cols must be non-negative integers, "
                                   f"got {_short(rows)} and {_short(cols)}")
    if shape is not None and (rows, cols) != shape:
        raise CalibrationFileError(f"{where}: {key} must be {shape[0]}x{shape[1]}, got {rows}x{cols}")
    if not isinstance(data, list) or len(data) != rows * cols:
        n = len(data) if isinstance(data, list) else "no list of"
        raise CalibrationFileError(f"{where}: {key} is {rows}x{cols} but its data has {n} values, "
                                   f"not {rows * cols}")
    values = np.array([_number(v, f"{where}: {key}") for v in data], dtype=float)
    # an empty matrix may claim any size, even one beyond numpy's (0 x 10**30)
    return values.reshape(rows, cols) if values.size else values.reshape(0, 0)


# A camera calibration file is about 1 kB: a thousand times that is not one.
MAX_YAML_BYTES = 1 << 20


class _NoAliasLoader(yaml.SafeLoader):
    """SafeLoader refusing aliases: a calibration file has none, and a few nested ones (a
    "billion laughs" of 1 kB) expand to gigabytes before any check could see them."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.composer.ComposerError(None, None, "aliases (*name) are not accepted in a calibration file",
                                              event.start_mark)
        return super().compose_node(parent, index)


def _short(value: Any) -> str:
    """A value for an error message, cut short: it may be a huge structure."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def read_camera_yaml(path: str | os.PathLike) -> CameraYaml:
    """Read a camera_calibration_parsers YAML file, refusing anything it would misread.

    As in camera_calibration_parsers, camera_name defaults to "unknown" and distortion_model
    to plumb_bob (older files have neither); everything else must be there and consistent.
    """
    where = str(path)
    try:
        with open(path, "rb") as f:
            raw = f.read(MAX_YAML_BYTES + 1)
        if len(raw) > MAX_YAML_BYTES:
            raise CalibrationFileError(f"{where}: larger than {MAX_YAML_BYTES // 1024} kB; a camera calibration "
                                       "file is about 1 kB")
        doc = yaml.load(raw.decode(), Loader=_NoAliasLoader)   # noqa: S506 - a SafeLoader without aliases
    except OSError as exc:
        raise CalibrationFileError(f"{where}: cannot read ({exc.strerror or exc})") from exc
    except yaml.YAMLError as exc:
        raise CalibrationFileError(f"{where}: not valid YAML ({' '.join(str(exc).split())})") from None
    except RecursionError:   # the parser recurses once per level of nesting
        raise CalibrationFileError(f"{where}: not a calibration file (nested too deeply)") from None
    except UnicodeDecodeError:
        raise CalibrationFileError(f"{where}: not a text file") from None
    if not isinstance(doc, dict):
        raise CalibrationFileError(f"{where}: expected a map of calibration keys, got {type(doc).__name__}")
    size = []
    for key in ("image_width", "image_height"):
        value = doc.get(key)
        if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
            raise CalibrationFileError(f"{where}: {key} must be a positive integer, got {_short(value)}")
        if value > _MAX_SIZE:
            raise CalibrationFileError(f"{where}: {key} {value} is beyond what a CameraInfo holds (uint32)")
        size.append(value)
    name, model = doc.get("camera_name", "unknown"), doc.get("distortion_model", DISTORTION_MODEL)
    for key, value in (("camera_name", name), ("distortion_model", model)):
        if not isinstance(value, str):
            raise CalibrationFileError(f"{where}: {key} must be text, got {_short(value)}")
    D = _read_matrix(doc, "distortion_coefficients", None, where)
    if D.shape[0] != 1 and D.size:
        raise CalibrationFileError(f"{where}: distortion_coefficients must be one row, got {D.shape[0]}")
    return CameraYaml(
        camera_name=name, width=size[0], height=size[1], distortion_model=model,
        K=_read_matrix(doc, "camera_matrix", (3, 3), where), D=D.ravel(),
        R=_read_matrix(doc, "rectification_matrix", (3, 3), where),
        P=_read_matrix(doc, "projection_matrix", (3, 4), where))


def _json_ready(value: Any) -> Any:
    """Plain types with NaN and inf as null, as to_dict already does for missing depth."""
    if isinstance(value, Mapping):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_json_ready(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json(path: str | os.PathLike, result: Any, extra: Mapping[str, Any] | None = None) -> Path:
    """Write ``result.to_dict()`` plus ``extra`` (e.g. the board, the topics) as strict JSON."""
    doc = result.to_dict()
    clash = sorted(set(doc) & set(extra or {}))
    if clash:
        raise CalibrationFileError(f"extra keys {clash} would overwrite the result's own")
    doc.update(extra or {})
    try:
        text = json.dumps(_json_ready(doc), indent=2, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise CalibrationFileError(f"cannot write {path} as JSON: {exc}") from None
    return atomic_write(path, (text + "\n").encode())


def _png(image: np.ndarray, where: str) -> bytes:
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise CalibrationFileError(f"{where}: PNG encoding failed")
    return buf.tobytes()


def _amplitude_png(amplitude: Any, where: str) -> np.ndarray:
    """uint8 and uint16 as they are; anything else scaled to 16 bits by 65535 / max.

    The scaling keeps ratios (0 stays 0) and costs at most 1/65535 of the range, while the
    corner detector's percentile stretch ignores any positive scale, so recalibrating from
    the saved views finds the same corners. Negative and non-finite values become 0.
    """
    a = np.asarray(amplitude)
    if a.ndim != 2 or a.size == 0:
        raise CalibrationFileError(f"{where}: amplitude must be a non-empty 2-D image, got shape {a.shape}")
    if a.dtype in (np.uint8, np.uint16):
        return a
    if not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
        raise CalibrationFileError(f"{where}: amplitude must be integer or float, got {a.dtype}")
    a = a.astype(np.float64)
    a[~np.isfinite(a) | (a < 0)] = 0.0
    peak = a.max()
    return np.round(a * (_MAX_MM / peak)).astype(np.uint16) if peak > 0 else a.astype(np.uint16)


def _depth_png(depth: Any, units: float | None, where: str) -> np.ndarray:
    """uint16 millimetres, 0 where invalid or beyond 65.535 m (unrepresentable, and no ToF range)."""
    d = np.asarray(depth)
    if d.ndim != 2 or d.size == 0:
        raise CalibrationFileError(f"{where}: depth must be a non-empty 2-D image, got shape {d.shape}")
    if not (np.issubdtype(d.dtype, np.integer) or np.issubdtype(d.dtype, np.floating)):
        raise CalibrationFileError(f"{where}: depth must be integer or float, got {d.dtype}")
    mm = np.round(depth_in_metres(d, units) * 1000.0)
    mm[~(mm <= _MAX_MM)] = 0   # also NaN
    return mm.astype(np.uint16)


@dataclass(frozen=True)
class EncodedViews:
    """Views as the files ``save_views`` writes, encoded ahead: the node encodes them while the
    calibration runs (0.5 s for 20 views at 640x576) instead of after it."""
    files: tuple[tuple[str, bytes], ...]


CORNERS_SUFFIX = "_corners.csv"
_CORNERS_HEADER = "id,x,y"


def _corners_csv(view: View) -> bytes:
    """The corners a view was calibrated with: board index and pixel (OpenCV's convention: pixel
    centres at integers), one corner a line, so a recalibration uses them instead of detecting."""
    corners = np.asarray(view.corners, dtype=float).reshape(-1, 2)
    ids = np.arange(len(corners)) if view.ids is None else np.asarray(view.ids, dtype=int).ravel()
    lines = [_CORNERS_HEADER] + [f"{i},{x!r},{y!r}" for i, (x, y) in zip(ids, corners.tolist())]
    return ("\n".join(lines) + "\n").encode()


def read_corners(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """(ids, corners) from a ``NNNN_corners.csv``; CalibrationError naming the file when it is not one."""
    path = Path(path)
    try:
        lines = path.read_text().split()
        if not lines or lines[0] != _CORNERS_HEADER:
            raise ValueError(f"the first line must be {_CORNERS_HEADER!r}")
        rows = np.array([[float(v) for v in line.split(",")] for line in lines[1:]], dtype=float).reshape(-1, 3)
    except (OSError, ValueError) as exc:
        raise CalibrationFileError(f"{path.name}: not a corners file ({exc})") from None
    if not np.all(np.isfinite(rows)) or np.any(rows[:, 0] != np.round(rows[:, 0])) or rows[:, 0].min(initial=0) < 0:
        raise CalibrationFileError(f"{path.name}: corner ids must be whole numbers >= 0 and pixels finite")
    return rows[:, 0].astype(int), rows[:, 1:]


def encode_views(views: Sequence[View], depth_units: float | None = None) -> EncodedViews:
    """NNNN_ir.png and NNNN_depth.png of each view, as in the Kinect v2 data set, and the
    NNNN_corners.csv it was calibrated with when it has corners.

    Depth follows ``calibrate``'s convention (float metres, integer millimetres unless
    ``depth_units`` says otherwise) and is stored as uint16 millimetres, 0 = invalid. Every
    view is converted before the first file is written, so a bad view leaves no partial set.
    """
    files = []
    for i, view in enumerate(views):
        where = f"view {i}"
        if view.amplitude is None:
            raise CalibrationFileError(f"{where} has no amplitude image; saved views are recalibrated from it")
        files.append((f"{i:04d}_ir.png", _png(_amplitude_png(view.amplitude, where), where)))
        files.append((f"{i:04d}_depth.png", _png(_depth_png(view.depth, depth_units, where), where)))
        if view.corners is not None:
            files.append((f"{i:04d}{CORNERS_SUFFIX}", _corners_csv(view)))
    return EncodedViews(tuple(files))


def save_views(directory: str | os.PathLike, views: Sequence[View] | EncodedViews,
               depth_units: float | None = None) -> list[Path]:
    """Write views (``encode_views``, unless encoded already) into ``directory``."""
    encoded = views if isinstance(views, EncodedViews) else encode_views(views, depth_units)
    return [atomic_write(Path(directory) / name, data) for name, data in encoded.files]
