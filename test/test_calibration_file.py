"""Calibration files: the ROS camera YAML, the JSON report, atomic writes, saved views."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import cv2
import numpy as np
import pytest

from tof_calib_ros import View
from tof_calib_ros.core.result import CalibrationResult, ViewReport
from tof_calib_ros.files import calibration_file as cf
from tof_calib_ros.files.calibration_file import (
    CalibrationFileError,
    camera_yaml,
    encode_views,
    read_camera_yaml,
    save_views,
    write_camera_yaml,
    write_json,
)
from tof_calib_ros.files.image_folder import load_views
from tof_calib_ros.files.output_folder import write_calibration

K = np.array([[500.0, 0.0, 320.25], [0.0, 501.5, 240.125], [0.0, 0.0, 1.0]])
D = np.array([0.1, -0.25, 0.001, -0.002, 0.0])

EXPECTED_TEXT = """\
image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [500.0, 0.0, 320.25, 0.0, 501.5, 240.125, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.1, -0.25, 0.001, -0.002, 0.0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
projection_matrix:
  rows: 3
  cols: 4
  data: [500.0, 0.0, 320.25, 0.0, 0.0, 501.5, 240.125, 0.0, 0.0, 0.0, 1.0, 0.0]
"""


def _result(K: np.ndarray = K, D: np.ndarray = D) -> CalibrationResult:
    view = ViewReport(index=0, rvec=np.zeros(3), tvec=np.array([0.0, 0.0, 1.0]), pixel_rms=0.2,
                      depth_rms=float("nan"), pixel_residuals=np.full((4, 2), 0.2),
                      depth_residuals=np.array([0.001, np.nan, -0.001, 0.0]))
    return CalibrationResult(method="depth", image_size=(640, 480), K=K, D=D,
                             depth_bias=np.array([0.02, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
                             std={"fx": 0.5, "fy": 0.5, "cx": 1.0, "cy": float("nan")}, views=[view])


# --- camera YAML ---------------------------------------------------------------------------

def test_yaml_text_matches_the_ros_schema_line_by_line(tmp_path: Path) -> None:
    path = write_camera_yaml(tmp_path / "cam.yaml", _result(), "narrow_stereo")
    assert path.read_text().splitlines() == EXPECTED_TEXT.splitlines()


def test_yaml_round_trip_is_exact(tmp_path: Path) -> None:
    awkward_K = np.array([[378.41655563165887, 0.0, 253.66891565288495],
                          [0.0, 383.19185607185238, 190.05466139352319], [0.0, 0.0, 1.0]])
    awkward_D = np.array([0.10208314569573707, -2.0310303005835004e-17, 1e-05, -3.637e-300, -0.0])
    fields = {"K": awkward_K, "D": awkward_D, "image_size": (512, 424)}
    cam = read_camera_yaml(write_camera_yaml(tmp_path / "sub" / "dir" / "ir.yaml", fields, "kinect2_ir"))
    assert (cam.camera_name, cam.width, cam.height, cam.distortion_model) == ("kinect2_ir", 512, 424, "plumb_bob")
    np.testing.assert_array_equal(cam.K, awkward_K)   # bit for bit, not rounded
    np.testing.assert_array_equal(cam.D, awkward_D)
    np.testing.assert_array_equal(cam.R, np.eye(3))
    np.testing.assert_array_equal(cam.P, np.hstack([awkward_K, np.zeros((3, 1))]))
    assert cam.K.shape == (3, 3) and cam.D.shape == (5,) and cam.P.shape == (3, 4)


def test_a_rational_lens_is_written_as_rational_polynomial_and_read_back(tmp_path: Path) -> None:
    wide = np.array([4.7247, 3.2092, 1.2e-4, 5.9e-6, 0.1706, 5.0559, 4.7758, 0.8865])
    text = camera_yaml({"K": K, "D": wide, "image_size": (512, 512)}, "azure_wfov").decode()
    assert "distortion_model: rational_polynomial\ndistortion_coefficients:\n  rows: 1\n  cols: 8\n" in text
    cam = read_camera_yaml(write_camera_yaml(tmp_path / "wide.yaml", {"K": K, "D": wide, "image_size": (512, 512)},
                                             "azure_wfov"))
    assert cam.distortion_model == "rational_polynomial"
    np.testing.assert_array_equal(cam.D, wide)


def test_reads_what_camera_calibration_parsers_writes(tmp_path: Path) -> None:
    # yaml-cpp style: integers for whole numbers, 1e-05 without a dot (text to PyYAML's YAML 1.1)
    path = tmp_path / "cam.yaml"
    path.write_text(EXPECTED_TEXT.replace("500.0", "500").replace("0.001", "1e-03")
                    .replace("camera_name: narrow_stereo\n", "").replace("distortion_model: plumb_bob\n", ""))
    cam = read_camera_yaml(path)
    assert cam.camera_name == "unknown" and cam.distortion_model == "plumb_bob"   # the parsers' defaults
    np.testing.assert_array_equal(cam.K, K)
    np.testing.assert_array_equal(cam.D, D)


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("image_width: 640\n", ""), "image_width must be a positive integer, got None"),
    (lambda t: t.replace("image_height: 480", "image_height: 480.5"), "image_height must be a positive integer"),
    (lambda t: t.replace("image_height: 480", "image_height: 0"), "image_height must be a positive integer, got 0"),
    (lambda t: t.replace("camera_name: narrow_stereo", "camera_name: [a]"), "camera_name must be text"),
    (lambda t: t.replace("camera_matrix:", "camera_matrixx:"), "missing camera_matrix (a map with rows, cols"),
    (lambda t: t.replace("  data: [500.0, 0.0, 320.25, 0.0, 501.5, 240.125, 0.0, 0.0, 1.0]\n", ""),
     "camera_matrix has no data"),
    (lambda t: t.replace("data: [500.0, 0.0, 320.25, 0.0, 501.5, 240.125, 0.0, 0.0, 1.0]",
                         "data: [500.0, 0.0, 320.25, 0.0, 501.5, 240.125, 0.0, 0.0]"),
     "camera_matrix is 3x3 but its data has 8 values, not 9"),
    (lambda t: t.replace("data: [0.1, -0.25, 0.001, -0.002, 0.0]", "data: [0.1, -0.25, 0.001, -0.002]"),
     "distortion_coefficients is 1x5 but its data has 4 values, not 5"),
    (lambda t: t.replace("data: [0.1, -0.25, 0.001, -0.002, 0.0]", "data: 0.1"),
     "distortion_coefficients is 1x5 but its data has no list of values, not 5"),
    (lambda t: t.replace("rows: 3\n  cols: 4", "rows: 4\n  cols: 3"), "projection_matrix must be 3x4, got 4x3"),
    (lambda t: t.replace("rows: 3\n  cols: 4", "rows: three\n  cols: 4"),
     "projection_matrix rows and cols must be non-negative integers, got 'three' and 4"),
    (lambda t: t.replace("501.5", "fx"), "camera_matrix: expected a number, got 'fx'"),
    (lambda t: t.replace("501.5", ".nan"), "camera_matrix: nan is not a finite number"),
    (lambda t: t.replace("data: [0.1, -0.25, 0.001, -0.002, 0.0]", "data: [0.1, true, 0.001, -0.002, 0.0]"),
     "distortion_coefficients: expected a number, got True"),
    (lambda t: t.replace("rows: 1\n  cols: 5", "rows: 5\n  cols: 1"), "distortion_coefficients must be one row"),
    (lambda t: t.replace("camera_matrix:\n", "camera_matrix: [\n"), "not valid YAML"),
    (lambda t: "- just\n- a list\n", "expected a map of calibration keys, got list"),
    (lambda t: "", "expected a map of calibration keys, got NoneType"),
])
def test_malformed_yaml_is_refused_clearly(tmp_path: Path, edit, message: str) -> None:
    path = tmp_path / "cam.yaml"
    path.write_text(edit(EXPECTED_TEXT))
    with pytest.raises(CalibrationFileError) as info:
        read_camera_yaml(path)
    assert str(info.value).startswith(f"{path}: {message}")
    assert "\n" not in str(info.value)


def test_unreadable_yaml_file(tmp_path: Path) -> None:
    with pytest.raises(CalibrationFileError, match="cannot read"):
        read_camera_yaml(tmp_path / "missing.yaml")
    (tmp_path / "binary.yaml").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(CalibrationFileError, match="not a text file"):
        read_camera_yaml(tmp_path / "binary.yaml")


@pytest.mark.parametrize("fields, name, message", [
    ({"K": K, "D": D, "image_size": (640, 480)}, "narrow stereo", "camera name 'narrow stereo' must be letters"),
    ({"K": K, "D": D, "image_size": (640, 480)}, "", "camera name '' must be letters"),
    ({"K": K, "D": D}, "cam", "need K, D and image_size to write a camera file; missing: image_size"),
    (object(), "cam", "need K, D and image_size to write a camera file; missing: K, D, image_size"),
    ({"K": K[:2], "D": D, "image_size": (640, 480)}, "cam", "K must be 3x3, got shape (2, 3)"),
    ({"K": K, "D": D[:4], "image_size": (640, 480)}, "cam", "D must hold the 5 plumb_bob terms"),
    ({"K": K, "D": np.r_[D, 0.1], "image_size": (640, 480)}, "cam", "D must hold the 5 plumb_bob terms"),
    ({"K": K * np.nan, "D": D, "image_size": (640, 480)}, "cam", "K or D has NaN or inf values"),
    ({"K": K, "D": D, "image_size": (0, 480)}, "cam", "image size must be positive, got 0x480"),
    ({"K": K, "D": D, "image_size": 640}, "cam", "K, D must be numbers and image_size (width, height)"),
    ({"K": "K", "D": D, "image_size": (640, 480)}, "cam", "K, D must be numbers and image_size (width, height)"),
])
def test_bad_yaml_input_is_refused_before_writing(tmp_path: Path, fields: dict, name: str, message: str) -> None:
    with pytest.raises(CalibrationFileError) as info:
        write_camera_yaml(tmp_path / "cam.yaml", fields, name)
    assert str(info.value).startswith(message)
    assert list(tmp_path.iterdir()) == []


# --- atomic writes ---------------------------------------------------------------------------

def _old_file(tmp_path: Path) -> tuple[Path, str]:
    path = write_camera_yaml(tmp_path / "cam.yaml", _result(), "narrow_stereo")
    return path, path.read_text()


def test_failed_replace_keeps_the_old_file_and_no_temp(tmp_path: Path, monkeypatch) -> None:
    path, old = _old_file(tmp_path)

    def crash(src, dst):
        raise OSError(5, "Input/output error")
    monkeypatch.setattr(cf.os, "replace", crash)
    with pytest.raises(CalibrationFileError, match=r"cannot write .*cam.yaml: Input/output error"):
        write_camera_yaml(path, _result(K=K * 2), "narrow_stereo")
    assert path.read_text() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cam.yaml"]


def test_disk_full_midway_keeps_the_old_file_and_no_temp(tmp_path: Path, monkeypatch) -> None:
    path, old = _old_file(tmp_path)
    real_fdopen = os.fdopen

    class HalfWriter:
        """Writes half the data, then fails as a full disk does."""

        def __init__(self, f):
            self.f = f

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

        def write(self, data):
            self.f.write(data[:len(data) // 2])
            self.f.flush()
            raise OSError(28, "No space left on device")
    monkeypatch.setattr(cf.os, "fdopen", lambda fd, mode: HalfWriter(real_fdopen(fd, mode)))
    with pytest.raises(CalibrationFileError, match="No space left on device"):
        write_json(path, _result())
    assert path.read_text() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cam.yaml"]


def test_interrupt_is_not_wrapped_and_leaves_no_temp(tmp_path: Path, monkeypatch) -> None:
    path, old = _old_file(tmp_path)

    def interrupt(fd):
        raise KeyboardInterrupt
    monkeypatch.setattr(cf.os, "fsync", interrupt)
    with pytest.raises(KeyboardInterrupt):
        write_camera_yaml(path, _result(K=K * 2), "narrow_stereo")
    assert path.read_text() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cam.yaml"]


def test_sigkill_before_the_rename_keeps_the_old_file(tmp_path: Path) -> None:
    path, old = _old_file(tmp_path)
    child = textwrap.dedent(f"""
        import os, signal
        import numpy as np
        from tof_calib_ros.files import calibration_file as cf
        os.replace = lambda src, dst: os.kill(os.getpid(), signal.SIGKILL)   # die with the new data on disk
        cf.write_camera_yaml({str(path)!r}, {{"K": np.eye(3), "D": np.zeros(5), "image_size": (1, 1)}}, "x")
    """)
    proc = subprocess.run([sys.executable, "-c", child], check=False, cwd=Path(__file__).parents[1], timeout=60)
    assert proc.returncode == -9
    assert path.read_text() == old
    # the complete temporary file is what a SIGKILL leaves; the target never is partial
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_writes_go_through_atomic_write(tmp_path: Path, monkeypatch) -> None:
    written = []
    real = cf.atomic_write
    monkeypatch.setattr(cf, "atomic_write", lambda path, data: written.append(Path(path).name) or real(path, data))
    write_camera_yaml(tmp_path / "cam.yaml", _result(), "cam")
    write_json(tmp_path / "cal.json", _result())
    save_views(tmp_path / "views", [View(depth=np.ones((4, 5)), amplitude=np.ones((4, 5), np.uint8))])
    assert written == ["cam.yaml", "cal.json", "0000_ir.png", "0000_depth.png"]


# --- JSON -------------------------------------------------------------------------------------

def test_json_holds_the_result_and_extras_as_strict_json(tmp_path: Path) -> None:
    result = _result()
    path = write_json(tmp_path / "cal.json", result, {"board": {"cols": 5, "rows": 7, "square": np.float64(0.03)},
                                                      "topics": ("/ir", "/depth"), "count": np.int64(3)})

    def refuse(constant):
        raise AssertionError(f"non-standard JSON constant {constant}")
    doc = json.loads(path.read_text(), parse_constant=refuse)
    assert doc["camera_matrix"] == K.tolist() and doc["distortion_coefficients"] == D.tolist()
    assert doc["board"] == {"cols": 5, "rows": 7, "square": 0.03} and doc["topics"] == ["/ir", "/depth"]
    assert doc["count"] == 3
    assert doc["std"]["cy"] is None and doc["views"][0]["depth_rms_m"] is None    # NaN
    assert doc["verdict"] == {"ok": result.ok, "reasons": result.verdict}


def test_json_extra_may_not_overwrite_the_result(tmp_path: Path) -> None:
    with pytest.raises(CalibrationFileError, match=r"extra keys \['camera_matrix'\] would overwrite"):
        write_json(tmp_path / "cal.json", _result(), {"camera_matrix": []})
    with pytest.raises(CalibrationFileError, match="cannot write .* as JSON"):
        write_json(tmp_path / "cal.json", _result(), {"thing": object()})
    assert list(tmp_path.iterdir()) == []


# --- saved views ------------------------------------------------------------------------------

def test_save_views_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    metres = rng.uniform(0.4, 4.5, (6, 8))
    metres[0, :4] = [np.nan, 0.0, -1.0, 70.0]   # invalid, or beyond MAX_DEPTH_M (and uint16 mm)
    ir16 = rng.integers(0, 65535, (6, 8), endpoint=True).astype(np.uint16)
    ir8 = rng.integers(0, 255, (6, 8), endpoint=True).astype(np.uint8)
    mm = rng.integers(0, 50000, (6, 8), endpoint=True).astype(np.uint16)   # up to MAX_DEPTH_M
    views = [View(depth=metres, amplitude=ir16), View(depth=mm, amplitude=ir8)]
    paths = save_views(tmp_path, views)
    assert [p.name for p in paths] == ["0000_ir.png", "0000_depth.png", "0001_ir.png", "0001_depth.png"]
    loaded = load_views(tmp_path)
    assert len(loaded) == 2
    assert loaded[0].amplitude.dtype == np.uint16 and loaded[1].amplitude.dtype == np.uint8
    np.testing.assert_array_equal(loaded[0].amplitude, ir16)
    np.testing.assert_array_equal(loaded[1].amplitude, ir8)
    depth0 = loaded[0].depth
    assert depth0.dtype == np.uint16
    np.testing.assert_array_equal(depth0[0, :4], 0)
    valid = np.isfinite(metres) & (metres > 0) & (metres < 65)
    assert np.max(np.abs(depth0[valid] / 1000.0 - metres[valid])) <= 0.0005   # to the millimetre
    np.testing.assert_array_equal(loaded[1].depth, mm)                        # integer mm: exact


def test_save_views_float_amplitude_and_depth_units(tmp_path: Path) -> None:
    amplitude = np.array([[0.0, 0.25, 1.0, 2.0], [np.nan, -1.0, np.inf, 0.5]], dtype=np.float32)
    depth = np.array([[10000, 7500, 0, 1], [2, 3, 4, 5]], dtype=np.int32)   # in 0.1 mm
    save_views(tmp_path, [View(depth=depth, amplitude=amplitude)], depth_units=1e-4)
    ir = cv2.imread(str(tmp_path / "0000_ir.png"), cv2.IMREAD_UNCHANGED)
    assert ir.dtype == np.uint16
    # scaled by 65535 / max: ratios kept, non-finite and negative to 0
    np.testing.assert_array_equal(ir, [[0, 8192, 32768, 65535], [0, 0, 0, 16384]])
    np.testing.assert_array_equal(cv2.imread(str(tmp_path / "0000_depth.png"), cv2.IMREAD_UNCHANGED),
                                  [[1000, 750, 0, 0], [0, 0, 0, 0]])


@pytest.mark.parametrize("view, message", [
    (View(depth=np.ones((4, 5))), "view 1 has no amplitude image"),
    (View(depth=np.ones((4, 5)), amplitude=np.ones((4, 5, 3), np.uint8)), "view 1: amplitude must be a non-empty 2-D"),
    (View(depth=np.ones(5), amplitude=np.ones((4, 5), np.uint8)), "view 1: depth must be a non-empty 2-D"),
    (View(depth=np.ones((4, 5), bool), amplitude=np.ones((4, 5), np.uint8)), "view 1: depth must be integer or float"),
])
def test_save_views_refuses_bad_views_before_writing(tmp_path: Path, view: View, message: str) -> None:
    good = View(depth=np.ones((4, 5)), amplitude=np.ones((4, 5), np.uint16))
    with pytest.raises(CalibrationFileError) as info:
        save_views(tmp_path / "views", [good, view])
    assert str(info.value).startswith(message)
    assert not (tmp_path / "views").exists()


def test_load_views_errors(tmp_path: Path) -> None:
    with pytest.raises(CalibrationFileError, match=r"no amplitude/depth pairs \(NNNN_ir.png with NNNN_depth.png\)"):
        load_views(tmp_path)
    cv2.imwrite(str(tmp_path / "0000_ir.png"), np.ones((4, 5), np.uint8))
    with pytest.raises(CalibrationFileError, match="no depth image beside 0000_ir.png"):
        load_views(tmp_path)
    (tmp_path / "0000_depth.png").write_bytes(b"not a png")
    with pytest.raises(CalibrationFileError, match="0000_depth.png: missing or not a readable image"):
        load_views(tmp_path)
    (tmp_path / "0000_depth.png").write_bytes((tmp_path / "0000_ir.png").read_bytes())
    (tmp_path / "0000_corners.csv").write_text("x,y\n")
    with pytest.raises(CalibrationFileError, match="0000_corners.csv: not a corners file"):
        load_views(tmp_path)


def test_load_views_reads_the_kinect_set(kinect_dir: Path) -> None:
    views = load_views(kinect_dir)
    assert len(views) == 51
    assert views[0].depth.dtype == np.uint16 and views[0].amplitude.shape == (424, 512)


# --- the whole output ----------------------------------------------------------------------

def _views(n: int, value: int) -> list[View]:
    return [View(depth=np.full((6, 8), 1000 + i, np.uint16), amplitude=np.full((6, 8), value, np.uint16))
            for i in range(n)]


def test_views_encoded_ahead_are_written_as_the_views_themselves(tmp_path: Path) -> None:
    views = _views(3, 9)
    write_calibration(tmp_path / "direct", _result(), views, "tof")
    encoded = encode_views(views)
    views[0].amplitude[:] = 1   # encoded already: a later change is not written
    write_calibration(tmp_path / "ahead", _result(), encoded, "tof")
    direct, ahead = sorted((tmp_path / "direct" / "views").iterdir()), sorted((tmp_path / "ahead" / "views").iterdir())
    assert [p.name for p in direct] == [p.name for p in ahead] and len(direct) == 6
    assert all(a.read_bytes() == b.read_bytes() for a, b in zip(direct, ahead))


def test_saved_corners_round_trip_exactly_and_a_bad_file_is_named(tmp_path):
    from tof_calib_ros.files.calibration_file import read_corners, save_views

    rng = np.random.default_rng(3)
    corners = rng.uniform(0, 200, (35, 2))
    view = View(depth=np.full((200, 200), 800, np.uint16), corners=corners, amplitude=np.ones((200, 200), np.uint16))
    save_views(tmp_path, [view])
    ids, back = read_corners(tmp_path / "0000_corners.csv")
    np.testing.assert_array_equal(ids, np.arange(35))
    np.testing.assert_array_equal(back, corners)   # bit for bit: a recalibration sees the same numbers
    (tmp_path / "0000_corners.csv").write_text("id,x,y\n0,1.5,nan\n")
    with pytest.raises(CalibrationFileError, match=r"0000_corners.csv: corner ids must be whole numbers"):
        read_corners(tmp_path / "0000_corners.csv")
    (tmp_path / "0000_corners.csv").write_text("x,y\n1,2\n")
    with pytest.raises(CalibrationFileError, match=r"0000_corners.csv: not a corners file"):
        read_corners(tmp_path / "0000_corners.csv")
