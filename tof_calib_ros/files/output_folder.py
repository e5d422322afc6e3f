"""The output folder, whose calibration.yaml, calibration.json, views/ and report.html change as one.

A calibration is written whole into a generation folder of its own, then made current by a
single atomic step, the rename of the ``current`` symbolic link; the names a reader opens are
fixed links through it::

    out/.generations/<time>-<pid>.<random>/   calibration.yaml  calibration.json  views/  report.html
    out/current -> .generations/<the newest>
    out/calibration.yaml -> current/calibration.yaml      (and calibration.json, views, report.html)

So at any instant, killed or failed at any step, a reader sees one complete set: the old one,
or the new one. A reader that opens several files and must not straddle a switch resolves
``current`` once (``os.path.realpath``) and reads from there. A set without a report (the node
writes none) has no ``report.html``.

Writers stage without a lock; the switch and the clean-up take an exclusive ``flock`` on
``out/.lock``, so two writers never delete each other's work: the later switch wins, and a
writer that cannot get the lock in ``LOCK_TIMEOUT_S`` refuses with a message. The previous
generation is kept (a reader may still be in it); older ones, and the staging folders of dead
writers, go at the next write.
"""
from __future__ import annotations

import fcntl
import os
import re
import secrets
import shutil
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ..core.inputs import View
from .calibration_file import (
    CalibrationFileError,
    EncodedViews,
    atomic_write,
    camera_yaml,
    encode_views,
    save_views,
    sync_dir,
    write_json,
)

GENERATIONS = ".generations"
CURRENT = "current"
LOCK = ".lock"
# what a set holds, each reached through a fixed link of the same name in the output folder
MEMBERS = ("calibration.yaml", "calibration.json", "views", "report.html")
LOCK_TIMEOUT_S = 60.0
_STAGING = ".staging."
_LEFTOVER = re.compile(r"\.(?:current|current\.legacy|calibration\.yaml|calibration\.json|report\.html"
                       r"|views|views\.new|views\.old|views\.legacy)\.(\d+\.[0-9a-f]+)")


def write_calibration(directory: str | os.PathLike, result: Any, views: Sequence[View] | EncodedViews,
                      camera_name: str, extra: Mapping[str, Any] | None = None,
                      report: Callable[[Path], object] | None = None) -> Path:
    """Write a new calibration set into ``directory`` and make it current; returns the YAML's path.

    ``report``, when given, writes the set's report.html at the path it is passed. Everything
    that can be refused (a bad camera name, a view without amplitude) is refused, and every
    file is written, before the set becomes current; on any failure the current set is left as
    it was and the staged one removed. Raises CalibrationFileError (OSError included).
    """
    out = Path(directory).expanduser()
    text = camera_yaml(result, camera_name)
    encoded = views if isinstance(views, EncodedViews) else encode_views(views)
    token = f"{os.getpid()}.{secrets.token_hex(4)}"
    generations = out / GENERATIONS
    staging = generations / f"{_STAGING}{token}"
    try:
        try:
            staging.mkdir(parents=True)
            save_views(staging / "views", encoded)
            write_json(staging / "calibration.json", result, extra)
            atomic_write(staging / "calibration.yaml", text)
            if report is not None:
                report(staging / "report.html")
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
        with _locked(out):
            name = f"{time.strftime('%Y%m%dT%H%M%S')}-{token}"
            os.rename(staging, generations / name)
            _adopt_legacy(out, token)
            previous = _current(out)
            _point(out / CURRENT, f"{GENERATIONS}/{name}", token)
            _link_members(out, token)
            _collect(out, keep={name, previous}, token=token)
    except OSError as exc:
        raise CalibrationFileError(f"cannot write the calibration into {out}: {exc.strerror or exc}") from exc
    return out / "calibration.yaml"


@contextmanager
def _locked(out: Path) -> Iterator[None]:
    fd = os.open(out / LOCK, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        deadline = time.monotonic() + LOCK_TIMEOUT_S
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise CalibrationFileError(
                        f"{out} is being written by another process (it holds {out / LOCK} for over "
                        f"{LOCK_TIMEOUT_S:g} s); nothing changed, try again when it has finished") from None
                time.sleep(0.05)
        yield
    finally:
        os.close(fd)   # releases the lock


def _current(out: Path) -> str | None:
    """The current generation's folder name, or None."""
    try:
        return Path(os.readlink(out / CURRENT)).name
    except OSError:
        return None


def _point(link: Path, target: str, token: str) -> None:
    """Make ``link`` a symbolic link to ``target`` in one atomic step (a new link renamed over it)."""
    tmp = link.with_name(f".{link.name}.{token}")
    os.symlink(target, tmp)
    os.replace(tmp, link)
    sync_dir(link.parent)


def _link_members(out: Path, token: str) -> None:
    """A fixed link for each member the current set has; none for one it lacks (a dangling link
    would trip copies that follow links)."""
    for member in MEMBERS:
        path = out / member
        has = (out / CURRENT / member).exists()
        if has and not path.is_symlink():
            _point(path, f"{CURRENT}/{member}", token)
        elif not has and path.is_symlink():
            path.unlink()


def _adopt_legacy(out: Path, token: str) -> None:
    """A folder written before generations holds its set as plain files: copy it into a
    generation and make that current, then turn the plain names into links one by one. A file
    is replaced by its link atomically; a directory (views/) cannot be, so for that one rename
    a reader finds no views/ (once per folder, on its first write by this version)."""
    plain = [m for m in MEMBERS if (out / m).exists() and not (out / m).is_symlink()]
    if (out / CURRENT).exists() and not (out / CURRENT).is_symlink():
        # a copy that followed the links (shutil.copytree's default): the plain names hold the set
        _drop(out / CURRENT, token)
    if not plain:
        return
    name = f"00000000T000000-legacy.{token}"
    staging = out / GENERATIONS / f"{_STAGING}{token}.legacy"
    staging.mkdir()
    for member in plain:
        copy = shutil.copytree if (out / member).is_dir() else shutil.copy2
        copy(out / member, staging / member)
    os.rename(staging, out / GENERATIONS / name)
    _point(out / CURRENT, f"{GENERATIONS}/{name}", token)
    for member in plain:
        path = out / member
        if path.is_dir():
            _drop(path, token)
        _point(path, f"{CURRENT}/{member}", token)


def _collect(out: Path, keep: set[str | None], token: str) -> None:
    """Remove generations other than ``keep``, and what dead writers left: staging folders,
    half-made links, the views an earlier version was swapping (``.views.new.<pid>...``).
    A generation goes by ``_drop``: a reader still in it then finds it gone, never half deleted."""
    for path in (out / GENERATIONS).iterdir():
        if path.name.startswith(_STAGING):
            if _alive_writer(path.name[len(_STAGING):]):
                continue
        elif path.name in keep:
            continue
        if path.name.startswith("."):   # a staging folder, or one dropped before
            shutil.rmtree(path, ignore_errors=True)
        else:
            _drop(path, token)
    for path in out.iterdir():
        left = _LEFTOVER.fullmatch(path.name)
        if left and not _alive_writer(left.group(1)):
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)


def _alive_writer(token: str) -> bool:
    """Whether the process whose ``<pid>.<random>`` token this is still runs (this host)."""
    pid = token.split(".")[0]
    if not pid.isdigit():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:   # another user's: alive
        pass
    return True


def _drop(path: Path, token: str) -> None:
    """Remove a folder by first renaming it aside (one step for a reader), then deleting it."""
    aside = path.with_name(f".{path.name}.legacy.{token}")
    os.rename(path, aside)
    shutil.rmtree(aside, ignore_errors=True)
