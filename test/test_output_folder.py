"""The output folder changes as one set: killed at any rename, out of disk quota, two writers."""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import pytest

from tof_calib_ros.files.calibration_file import (
    CalibrationFileError,
    read_camera_yaml,
    save_views,
    write_camera_yaml,
    write_json,
)
from tof_calib_ros.files.output_folder import GENERATIONS, write_calibration

sys.path.insert(0, str(Path(__file__).parent))
from test_calibration_file import K, _result, _views  # noqa: E402

OLD = (K[0, 0], 5)       # fx and views of the set written first
NEW = (2 * K[0, 0], 3)   # and of the one that replaces it


def _write(out: Path, scale: float, n: int, **kwargs) -> Path:
    return write_calibration(out, _result(K * [[scale], [scale], [1]]), _views(n, 9), "tof",
                             {"n_views": n, **kwargs.pop("extra", {})}, **kwargs)


def read_set(out: Path, through_links: bool = True) -> tuple[float, int]:
    """fx and the number of views of the set a reader sees, after checking that its files belong
    together: one generation, resolved once, as the module's docstring tells readers to."""
    gen = Path(os.path.realpath(out / "current"))
    try:
        fx = read_camera_yaml(gen / "calibration.yaml").K[0, 0]
        doc = json.loads((gen / "calibration.json").read_text())
        n = len(list((gen / "views").glob("*_ir.png")))
    except (OSError, ValueError):   # CalibrationFileError is a ValueError
        if not gen.is_dir():   # dropped while read (a reader two switches behind): no set to judge
            raise FileNotFoundError(gen) from None
        raise
    if not gen.is_dir():
        raise FileNotFoundError(gen)
    assert doc["camera_matrix"][0][0] == fx and doc["n_views"] == n, f"a mixed set in {gen}"
    if through_links:   # the fixed names a driver opens lead to the same set (no writer running)
        assert read_camera_yaml(out / "calibration.yaml").K[0, 0] == fx
    return fx, n


def test_a_new_set_replaces_the_old_whole(tmp_path: Path) -> None:
    _write(tmp_path, 1, 5)
    assert read_set(tmp_path) == OLD
    path = _write(tmp_path, 2, 3)
    assert path == tmp_path / "calibration.yaml" and read_set(tmp_path) == NEW
    assert len(list((tmp_path / "views").glob("*_ir.png"))) == 3   # none of the 5 left behind
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == [".generations", ".lock", "calibration.json", "calibration.yaml", "current", "views"]
    assert len(list((tmp_path / GENERATIONS).iterdir())) == 2   # the new one and the one before it
    _write(tmp_path, 3, 4)
    assert len(list((tmp_path / GENERATIONS).iterdir())) == 2


def test_the_report_belongs_to_its_set_and_its_failure_changes_nothing(tmp_path: Path) -> None:
    _write(tmp_path, 1, 5, report=lambda p: p.write_text("old report"))
    assert (tmp_path / "report.html").read_text() == "old report"

    def failing(path: Path) -> None:
        raise CalibrationFileError(f"cannot write {path}: disk full")

    with pytest.raises(CalibrationFileError, match="disk full"):
        _write(tmp_path, 2, 3, report=failing)
    assert read_set(tmp_path) == OLD and (tmp_path / "report.html").read_text() == "old report"
    assert [p.name for p in (tmp_path / GENERATIONS).iterdir()] == [Path(os.readlink(tmp_path / "current")).name]
    _write(tmp_path, 3, 4)   # a set without a report (the node's): no report.html, not a stale one
    assert not (tmp_path / "report.html").exists() and not (tmp_path / "report.html").is_symlink()


_KILLER = textwrap.dedent("""
    import os, signal, sys
    sys.path.insert(0, sys.argv[3])
    from test_output_folder import _write
    n, calls = int(sys.argv[2]), [0]
    def killing(real):
        def call(*args, **kwargs):
            calls[0] += 1
            if calls[0] == n:
                os.kill(os.getpid(), signal.SIGKILL)
            return real(*args, **kwargs)
        return call
    os.rename, os.replace = killing(os.rename), killing(os.replace)
    from pathlib import Path
    _write(Path(sys.argv[1]), 2, 3)
""")


@pytest.mark.slow
def test_killed_at_every_rename_a_reader_sees_the_old_set_or_the_new(tmp_path: Path) -> None:
    seen = []
    for n in range(1, 60):
        out = tmp_path / f"kill{n}"
        _write(out, 1, 5)
        proc = subprocess.run([sys.executable, "-c", _KILLER, str(out), str(n), str(Path(__file__).parent)],
                              capture_output=True, text=True, timeout=60)
        seen.append(read_set(out))
        assert seen[-1] in (OLD, NEW)
        _write(out, 3, 4)   # the next writer cleans up what the killed one left
        assert read_set(out) == (3 * K[0, 0], 4)
        left = sorted(p.name for p in out.iterdir() if p.name.startswith(".") and p.name not in (GENERATIONS, ".lock"))
        assert left == [] and len(list((out / GENERATIONS).iterdir())) == 2
        if proc.returncode == 0:
            break
        assert proc.returncode == -9, proc.stderr
    else:
        pytest.fail("the writer was still renaming after 59 renames")
    assert seen[0] == OLD and seen[-1] == NEW and n > 10   # every file's rename, then the switch


def test_out_of_file_size_quota_leaves_the_old_set(tmp_path: Path) -> None:
    _write(tmp_path, 1, 5)
    script = ("import sys; sys.path.insert(0, sys.argv[2]); from pathlib import Path; "
              "from test_output_folder import _write; _write(Path(sys.argv[1]), 2, 3, extra={'pad': 'x' * 200000})")

    def quota() -> None:   # ulimit -f: no file may grow past 100 kB
        resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, 100_000))

    proc = subprocess.run([sys.executable, "-c", script, str(tmp_path), str(Path(__file__).parent)],
                          capture_output=True, text=True, timeout=60, preexec_fn=quota)
    assert proc.returncode != 0 and "File too large" in proc.stderr
    assert read_set(tmp_path) == OLD
    assert [p.name for p in (tmp_path / GENERATIONS).iterdir()] == [Path(os.readlink(tmp_path / "current")).name]


_WRITER = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[4])
    from pathlib import Path
    from test_output_folder import _write
    for _ in range(int(sys.argv[3])):
        _write(Path(sys.argv[1]), float(sys.argv[2]), int(float(sys.argv[2])) + 1)
""")


def test_two_writers_and_a_reader(tmp_path: Path) -> None:
    _write(tmp_path, 1, 5)
    writers = [subprocess.Popen([sys.executable, "-c", _WRITER, str(tmp_path), str(scale), "12",
                                 str(Path(__file__).parent)], stderr=subprocess.PIPE, text=True) for scale in (2, 3)]
    seen, problems, reads = set(), [], [0]

    def read() -> None:
        while any(w.poll() is None for w in writers):
            try:
                seen.add(read_set(tmp_path, through_links=False))
                reads[0] += 1
            except FileNotFoundError:
                pass   # the generation it was reading went two switches ago: read again
            except Exception as exc:  # noqa: BLE001 - anything else a reader meets is a fault
                problems.append(repr(exc))

    reader = threading.Thread(target=read)
    reader.start()
    errors = [w.communicate(timeout=300)[1] for w in writers]
    reader.join()
    assert [w.returncode for w in writers] == [0, 0], errors
    assert problems == [] and seen <= {OLD, (2 * K[0, 0], 3), (3 * K[0, 0], 4)}
    assert reads[0] >= 10 and seen - {OLD}, (reads, seen)   # it read, and saw the writers' sets
    assert read_set(tmp_path) in {(2 * K[0, 0], 3), (3 * K[0, 0], 4)}
    assert len(list((tmp_path / GENERATIONS).iterdir())) == 2


def test_a_folder_written_by_an_earlier_version_is_adopted(tmp_path: Path) -> None:
    write_json(tmp_path / "calibration.json", _result(), {"n_views": 5})
    write_camera_yaml(tmp_path / "calibration.yaml", _result(), "tof")
    save_views(tmp_path / "views", _views(5, 7))
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    (tmp_path / f".views.old.{dead}.ab").mkdir()   # what an earlier version's killed swap left
    _write(tmp_path, 2, 3)
    assert read_set(tmp_path) == NEW and not (tmp_path / f".views.old.{dead}.ab").exists()
    previous = [p for p in (tmp_path / GENERATIONS).iterdir() if "legacy" in p.name]
    assert len(previous) == 1 and read_camera_yaml(previous[0] / "calibration.yaml").K[0, 0] == K[0, 0]
    assert all((tmp_path / m).is_symlink() for m in ("calibration.yaml", "calibration.json", "views"))


def test_a_copy_that_followed_the_links_is_adopted(tmp_path: Path) -> None:
    import shutil

    _write(tmp_path / "a", 1, 5)
    shutil.copytree(tmp_path / "a", tmp_path / "b")   # links followed: every name a plain file or folder
    assert read_set(tmp_path / "b", through_links=False) == OLD
    _write(tmp_path / "b", 2, 3)
    assert read_set(tmp_path / "b") == NEW and (tmp_path / "b" / "current").is_symlink()
