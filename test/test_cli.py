"""tof_calib end to end: simulated recordings in both rosbag2 storages against their ground truth,
the Kinect v2 folder, broken messages, every exit code, the check of a calibration."""
from __future__ import annotations

import contextlib
import io
import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from tof_calib_ros import Board, View, sim
from tof_calib_ros.core.depth_bias import TERMS_ADDED_LATER
from tof_calib_ros.files.bag_io import IMAGE, BagWriter
from tof_calib_ros.files.calibration_file import read_camera_yaml, save_views, write_camera_yaml
from tof_calib_ros.offline.cli import (
    EXIT_CODES,
    EXIT_ERROR,
    EXIT_MISSING_TOPIC,
    EXIT_NO_BOARD,
    EXIT_OK,
    EXIT_QUALITY,
    EXIT_TOO_FEW_VIEWS,
    EXIT_UNREADABLE,
    EXIT_USAGE,
    Progress,
    main,
)
from tof_calib_ros.settings import SETTINGS
from tof_calib_ros.sim.recording import FRAME_ID, TOPICS, Scene, render_frames, truth_path

VIEWS_MAX, MAX_BLUR_PX = SETTINGS["views.max"].default, SETTINGS["motion.max_blur_px"].default

BOARD = ["--size", "5x7", "--square", "0.03"]
SIM = ["--frames", "240", "--hold", "5", "--transit", "5", "--seed", "1"]


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def last_line(err: str) -> str:
    return err.strip().splitlines()[-1]


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, Path]:
    """A simulated recording (240 frames of 200x200, 24 poses) in each rosbag2 storage."""
    out = {}
    for storage in ("sqlite3", "mcap"):
        path = tmp_path_factory.mktemp(storage) / "recording"
        assert main(["simulate", "--output", str(path), "--storage", storage, *SIM]) == EXIT_OK
        out[storage] = path
    return out


@pytest.fixture(scope="module")
def calibrated(bags, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("calibrated")
    assert main(["bag", str(bags["sqlite3"]), *BOARD, "--output", str(out)]) == EXIT_OK
    return out


def _truth(bag: Path) -> dict:
    return json.loads(truth_path(bag).read_text())


# -- the round trip -----------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_a_simulated_recording_calibrates_to_its_ground_truth(bags, tmp_path, capsys, storage):
    code, out, err = run(capsys, "bag", bags[storage], *BOARD, "--output", tmp_path)
    assert code == EXIT_OK, err
    truth = _truth(bags[storage])
    K_true = np.array(truth["camera_matrix"])
    doc = json.loads((tmp_path / "calibration.json").read_text())
    K = np.array(doc["camera_matrix"])
    assert K[0, 0] == pytest.approx(K_true[0, 0], rel=0.005) and K[1, 1] == pytest.approx(K_true[1, 1], rel=0.005)
    assert K[0, 2] == pytest.approx(K_true[0, 2], abs=1.0) and K[1, 2] == pytest.approx(K_true[1, 2], abs=1.0)
    assert doc["distortion_coefficients"][0] == pytest.approx(truth["distortion_coefficients"][0], abs=0.01)
    assert doc["depth_bias"]["depth_offset"] == pytest.approx(truth["depth_offset_m"], abs=0.003)
    # the YAML a driver loads holds the same numbers; the JSON says where they came from
    yaml = read_camera_yaml(tmp_path / "calibration.yaml")
    np.testing.assert_array_equal(yaml.K, K)
    assert (yaml.width, yaml.height, yaml.camera_name) == (200, 200, "tof_camera")
    assert doc["source"]["topics"] == {"amplitude": TOPICS["amplitude"], "depth": TOPICS["depth"],
                                       "camera_info": TOPICS["camera_info"]}
    assert doc["source"]["camera_info"]["camera_matrix"] == truth["camera_info"]["camera_matrix"]
    assert doc["board"] == {"cols": 5, "rows": 7, "square_m": 0.03}
    assert doc["collection"]["frames"] == 240 and doc["collection"]["skipped"] == {}
    assert len(doc["collection"]["view_stamps"]) == len(doc["views"]) >= 15
    # what was chosen and why, and the factory camera_info's 4 % error, are reported
    assert f"amplitude {TOPICS['amplitude']} (by name)" in out and f"({storage}" in out.replace("rosbag2 ", "(")
    factory = truth["camera_info"]["camera_matrix"][0][0] / K[0, 0] - 1
    assert f"fx differs from ours by {100 * factory:+.2f} %" in out and abs(factory - 0.04) < 0.002, out
    # the report holds its plots
    report = (tmp_path / "report.html").read_text()
    assert len(re.findall(r"<svg|<img", report)) >= 1


@pytest.mark.slow
def test_one_worker_and_two_keep_the_same_views(bags, calibrated, tmp_path, capsys):
    code, _, err = run(capsys, "bag", bags["sqlite3"], *BOARD, "--output", tmp_path, "--workers", "1")
    assert code == EXIT_OK, err
    one = json.loads((tmp_path / "calibration.json").read_text())
    two = json.loads((calibrated / "calibration.json").read_text())
    assert one["collection"] == two["collection"]   # the same frames kept
    # the same calibration, to the last digits the threaded sums of the solver leave alone
    np.testing.assert_allclose(one["camera_matrix"], two["camera_matrix"], rtol=1e-7)


@pytest.fixture(scope="module")
def kinect_folder(kinect_dir, tmp_path_factory) -> tuple[int, str, str, Path]:
    """`tof_calib images` on the Kinect folder, run once for the three tests that read it (exit
    code, stdout, stderr, output folder)."""
    folder, out, err = tmp_path_factory.mktemp("kinect_folder"), io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["images", str(kinect_dir), *BOARD, "--output", str(folder)])
    return code, out.getvalue(), err.getvalue(), folder


@pytest.mark.slow
def test_the_kinect_folder_calibrates(kinect_folder):
    code, out, err, folder = kinect_folder
    assert code == EXIT_OK, err
    doc = json.loads((folder / "calibration.json").read_text())
    K = np.array(doc["camera_matrix"])
    # OpenCV over all 49 views with a board gives fx 370.45, fy 371.89 (README); the driver's own file 378
    assert K[0, 0] == pytest.approx(370.45, rel=0.005) and K[1, 1] == pytest.approx(371.89, rel=0.005)
    # the offset on the optical axis, where the z and the radial offsets are one (the data set's
    # calibration: 25.5 mm; measured 22.6, of which the radial offset -46.5 mm)
    axis = doc["depth_bias"]["depth_offset"] + doc["depth_bias"]["depth_radial"]
    assert 0.015 < axis < 0.035, doc["depth_bias"]
    assert "51 amplitude/depth pairs" in out and doc["collection"]["frames_with_board"] >= 45
    assert (folder / "calibration.yaml").is_file() and (folder / "report.html").is_file()


# -- recordings unlike the held-still ones: a board that never stops, sparse frames, low resolution --
def _sharp_frames(bag: Path) -> int:
    """Frames whose whole board moved at most the default blur limit while exposed (the truth)."""
    return sum(f["board"] == "whole" and f["blur_px"] <= MAX_BLUR_PX for f in _truth(bag)["per_frame"])


@pytest.mark.slow
@pytest.mark.parametrize("rate, frames, seed", [(10, 200, 3), (5, 100, 4), (1, 30, 5)])
def test_a_board_that_never_stops_calibrates_at_any_frame_rate(tmp_path, capsys, rate, frames, seed):
    """A board waved without a pause, entering from the side after a second of empty frames,
    blurred where it moves fast: at 10 and 5 frames/s, and sparse (1 frame/s, where no speed can
    be measured between frames and each frame's own edges judge it)."""
    bag = tmp_path / "moving"
    assert main(["simulate", "--output", str(bag), "--motion", "continuous", "--rate", str(rate), "--frames",
                 str(frames), "--lead-in", str(rate), "--segment", "1.5", "--seed", str(seed)]) == EXIT_OK
    capsys.readouterr()
    code, out, err = run(capsys, "bag", bag, *BOARD, "--output", tmp_path / "out")
    assert code == EXIT_OK, err + out
    doc = json.loads((tmp_path / "out" / "calibration.json").read_text())
    K, K_true = np.array(doc["camera_matrix"]), np.array(_truth(bag)["camera_matrix"])
    # 1 % and 1 px: a fourth of the factory camera_info's error (the 0.5 % target is the
    # benchmark's, collection.py, a median over recordings)
    assert K[0, 0] == pytest.approx(K_true[0, 0], rel=0.01) and K[1, 1] == pytest.approx(K_true[1, 1], rel=0.01), K
    assert abs(K[0, 2] - K_true[0, 2]) < 1.0 and abs(K[1, 2] - K_true[1, 2]) < 1.0, K
    assert len(doc["views"]) >= 0.8 * min(_sharp_frames(bag), VIEWS_MAX), out


@pytest.fixture(scope="module")
def kinect_low_res(kinect_dir, tmp_path_factory) -> Path:
    """The Kinect v2 folder at 0.4 scale (205x170): what a PMD or pico flexx class sensor gives
    (the depth's nearest pixel to each pixel's centre, where the IR's average is)."""
    folder = tmp_path_factory.mktemp("kinect_205x170")
    for ir_path in sorted(kinect_dir.glob("*_ir.png")):
        ir = cv2.imread(str(ir_path), cv2.IMREAD_UNCHANGED)
        depth = cv2.imread(str(ir_path.with_name(ir_path.name.replace("_ir", "_depth"))), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(folder / ir_path.name), cv2.resize(ir, (205, 170), interpolation=cv2.INTER_AREA))
        cv2.imwrite(str(folder / ir_path.name.replace("_ir", "_depth")),
                    cv2.resize(depth, (205, 170), interpolation=cv2.INTER_NEAREST_EXACT))
    return folder


@pytest.mark.slow
def test_the_kinect_folder_at_low_resolution_calibrates(kinect_folder, kinect_low_res, tmp_path, capsys):
    from tof_calib_ros.core.detection import detect

    found = sum(detect(cv2.imread(str(p), cv2.IMREAD_UNCHANGED), Board(5, 7, 0.03)).corners is not None
                for p in sorted(kinect_low_res.glob("*_ir.png")))
    code, out, err = run(capsys, "images", kinect_low_res, *BOARD, "--output", tmp_path)
    # trusted, or refused as poorly constrained only: the folder's 48 views (a partial board left
    # out) gave fx 150.22 +- 0.72, trusted, 1.5 % and 2.4 of those sigmas above the same views at
    # full resolution, scaled; their pixels weighted alike move fx 1.55 px, which their noise
    # does not explain, and the uncertainty now says so (+- 1.69: refused, 2026-11-28; +- 2.27 with the
    # jackknife over runs of views, 2026-11-29)
    assert code in (EXIT_OK, EXIT_QUALITY), err + out
    doc = json.loads((tmp_path / ("calibration.json" if code == EXIT_OK else "rejected/calibration.json")).read_text())
    assert code == EXIT_OK or all("poorly constrained" in r for r in doc["verdict"]["reasons"]), doc["verdict"]
    # the CLI finds what the calibration's detector finds (47 of 51), and uses nearly all of it
    assert doc["collection"]["frames_with_board"] >= max(found, 45), out
    assert len(doc["views"]) >= 0.9 * doc["collection"]["frames_with_board"], out
    # one worker finds the same corners as several: a worker's detections do not depend on those it
    # made before (the SB detector's random generator is seeded for each)
    one_code, _, err = run(capsys, "images", kinect_low_res, *BOARD, "--output", tmp_path / "one", "--workers", "1")
    assert one_code == code, err
    one = json.loads((tmp_path / "one" / ("calibration.json" if code == EXIT_OK else "rejected/calibration.json")
                      ).read_text())
    assert one["views"] == doc["views"] and one["camera_matrix"] == doc["camera_matrix"]
    # against the full-resolution calibration of the same views, scaled (pixel centres stay at integers)
    full_code, _, full_err, full_folder = kinect_folder
    assert full_code == EXIT_OK, full_err
    full_doc = json.loads((full_folder / "calibration.json").read_text())
    full, full_std = np.array(full_doc["camera_matrix"]), full_doc["std"]
    K, s = np.array(doc["camera_matrix"]), 205 / 512
    assert K[0, 0] == pytest.approx(full[0, 0] * s, rel=0.02) and K[1, 1] == pytest.approx(full[1, 1] * s, rel=0.02)
    if doc["verdict"]["ok"]:   # trusted: within 2 sigmas (both calibrations') of the full-resolution fx, scaled
        assert abs(K[0, 0] - full[0, 0] * s) < 2 * np.hypot(doc["std"]["fx"], full_std["fx"] * s), (K, doc["std"])
    # the principal point within 3 px (1.5 % of the width), or 3 of the two calibrations' combined
    # stated sigmas (known: the data-chosen model, full distortion and a depth tilt that trades
    # with the principal point, puts cx 2.8 px, about 6 stated sigmas, from the full-resolution one)
    # Since the first look tries SB's exhaustive search before its accuracy mode, the folder finds
    # 49 boards, not 48, and cy lands 3 to 4 px off (here 2.4 and 3.07 px, 2026-11-27; 2.3 and 2.5
    # with the depth half a pixel off the IR). kinect_real's 49 views at 0.4 put cy at 80.06 against
    # the full-resolution 199.11 scaled, 79.34, since the depth yields to what its model leaves
    # open (83.30 before); the folder's 48 views (a partial board left out) take a depth scale and
    # the yield does not move them. Since the stated uncertainty is jackknifed over runs of
    # consecutive views (2026-11-29), the tolerance of 3 combined sigmas holds it (it was reported
    # as an expected failure before; a plain check now, so that a regression fails)
    std = doc["std"]
    for k, name in enumerate(("cx", "cy")):
        tol = max(3.0, 3 * np.hypot(std[name], full_std[name] * s))
        off = abs(K[k, 2] - ((full[k, 2] + 0.5) * s - 0.5))
        assert off < tol, f"{name} {off:.2f} px from the full-resolution calibration's, scaled (tolerance {tol:.2f})"


@pytest.mark.slow
def test_every_still_is_used_and_the_saved_corners_are_kept(kinect_folder, tmp_path, capsys):
    """A folder of stills is not thinned as a stream is: every view with a whole board is used;
    the views/ written beside the calibration hold their corners, and calibrate again to the same K."""
    from tof_calib_ros import calibrate
    from tof_calib_ros.files.image_folder import load_views

    code, out, err, folder = kinect_folder
    assert code == EXIT_OK, err
    doc = json.loads((folder / "calibration.json").read_text())
    rejected = doc["collection"]["frames_with_board"] - len(doc["views"])
    assert rejected <= 1 and "too similar" not in out, out   # 0002's outer squares touch the border
    views = load_views(folder / "views")
    assert len(views) == len(doc["views"]) and all(v.corners is not None for v in views)
    api = calibrate(views, Board(5, 7, 0.03), (512, 424))
    # the same numbers, to 1e-5 (the fit stops within a hundredth of a sigma; rounding in
    # the saved corners and the threaded sums move the last digits), far below any stated sigma
    np.testing.assert_allclose(api.K, doc["camera_matrix"], rtol=1e-5)
    code, out, err = run(capsys, "images", folder / "views", *BOARD, "--output", tmp_path / "b")
    assert code == EXIT_OK, err
    assert f"{len(views)} with the corners saved beside them" in out
    np.testing.assert_allclose(json.loads((tmp_path / "b" / "calibration.json").read_text())["camera_matrix"],
                               doc["camera_matrix"], rtol=1e-5)


@pytest.mark.slow
def test_saved_views_in_png_tiff_and_npy_calibrate(tmp_path, capsys):
    """Our own save_views layout, and the other formats a folder may hold, to the ground truth."""
    camera, board = sim.pmd_camera(), Board(5, 7, 0.03)
    rng = np.random.default_rng(4)
    poses = sim.random_poses(camera, board, 14, rng, distance=(0.4, 0.9), max_tilt_deg=40)
    noise = sim.Noise(depth=0.003, offset=0.02, amplitude=0.002)
    frames = [sim.render(camera, board, r, t, noise=noise, rng=rng, gain=0.3) for r, t in poses]
    folder = tmp_path / "views"
    save_views(folder, [View(f.depth, amplitude=f.amplitude) for f in frames[:8]])
    for i, f in enumerate(frames[8:11], start=8):     # TIFF, uint16 mm
        cv2.imwrite(str(folder / f"{i:04d}_amplitude.tiff"), f.amplitude)
        cv2.imwrite(str(folder / f"{i:04d}_depth.tiff"), np.nan_to_num(np.rint(f.depth * 1000)).astype(np.uint16))
    for i, f in enumerate(frames[11:], start=11):     # NPY, float metres with NaN
        np.save(folder / f"{i:04d}_ir.npy", f.amplitude)
        np.save(folder / f"{i:04d}_depth.npy", f.depth)
    (folder / "0099_ir.png").write_bytes((folder / "0000_ir.png").read_bytes())   # no depth beside it
    code, out, err = run(capsys, "images", folder, *BOARD, "--output", tmp_path / "out")
    assert code == EXIT_OK, err
    doc = json.loads((tmp_path / "out" / "calibration.json").read_text())
    assert doc["camera_matrix"][0][0] == pytest.approx(camera.K[0, 0], rel=0.01)
    assert doc["collection"]["frames"] == 14 and doc["collection"]["skipped"] == {"unreadable": 1}
    assert "no depth image beside 0099_ir.png" in out
    # the long steps show the stages they reach on stderr, in order, as they reach them
    stages = [line for line in err.splitlines() if line.startswith(("calibrating 14 views (", "writing the report ("))]
    assert stages[0].endswith("): 14 of 14 views have a board") and "): traditional calibration: fx=" in stages[1], err
    assert any("): chosen by the data: distortion" in line for line in stages), err
    assert [line.split("): ", 1)[1] for line in stages if line.startswith("writing")] == [
        "the traditional calibration of the same 14 views", "the first half of the views alone (7)",
        "the second half of the views alone (7)", "drawing the figures"], err
    writing = [line.startswith("writing") for line in stages]
    assert writing == sorted(writing) and "calibrating" not in out   # the report after the calibration


# -- broken messages ----------------------------------------------------------------------------
@pytest.mark.slow
def test_broken_messages_are_skipped_counted_and_named(tmp_path, capsys):
    scene = Scene(frames=200, hold=5, transit=5, seed=2)
    camera = scene.sim_camera
    path = tmp_path / "broken"
    with BagWriter(path) as bag:
        for i, (frame, _truth) in enumerate(render_frames(scene)):
            t = 1000.0 + i / scene.rate
            amplitude = bag.image_message(frame.amplitude, "mono16", t, FRAME_ID)
            depth = bag.image_message(np.nan_to_num(np.rint(frame.depth * 1000)).astype(np.uint16), "16UC1", t,
                                      FRAME_ID)
            bag.write(TOPICS["amplitude"], amplitude, t)
            bag.write(TOPICS["depth"], depth, t)
            bag.write(TOPICS["camera_info"], bag.camera_info_message(camera.K, camera.D, camera.size, t, FRAME_ID), t)
            u = t + 0.033   # between frames, farther from them than the pairing slop
            header = bag.header(u, FRAME_ID)
            if i == 20:     # wrong encodings
                bag.write(TOPICS["amplitude"], bag.image_message(np.zeros((200, 200, 3), np.uint8), "rgb8", u,
                                                                 FRAME_ID), u)
                bag.write(TOPICS["depth"], replace(depth, header=header, encoding="bgr8"), u)
            if i == 40:     # data length not matching step x height
                bag.write(TOPICS["amplitude"], replace(amplitude, header=header, data=amplitude.data[:-400]), u)
                bag.write(TOPICS["depth"], replace(depth, header=header), u)
            if i == 60:     # an image of another size
                bag.write(TOPICS["amplitude"], bag.image_message(np.ones((120, 160), np.uint16), "mono16", u,
                                                                 FRAME_ID), u)
                bag.write(TOPICS["depth"], bag.image_message(np.ones((120, 160), np.uint16), "16UC1", u,
                                                             FRAME_ID), u)
            if i == 80:     # truncated and garbage serialized data
                raw = bytes(bag.typestore.serialize_cdr(replace(amplitude, header=header), IMAGE))
                bag.write_raw(TOPICS["amplitude"], IMAGE, u, raw[:1000])
                bag.write_raw(TOPICS["depth"], IMAGE, u, np.random.default_rng(0).bytes(len(raw)))
            if i == 100:    # a stamp out of order
                bag.write(TOPICS["depth"], replace(depth, header=bag.header(t - 1.0, FRAME_ID)), u)
    code, out, err = run(capsys, "bag", path, *BOARD, "--output", tmp_path / "out")
    assert code == EXIT_OK, err
    doc = json.loads((tmp_path / "out" / "calibration.json").read_text())
    assert doc["collection"]["skipped"] == {"encoding": 2, "layout": 1, "size": 1, "undecodable": 2,
                                            "stamp_order": 1}
    assert doc["collection"]["frames"] == 200
    skipped = next(line for line in out.splitlines() if line.startswith("skipped:"))
    for text in ("2 encoding", "2 undecodable", "1 layout", "1 size", "1 stamp_order"):
        assert text in skipped
    assert "'rgb8'" in out and "'bgr8'" in out and "160x120" in out and "step x height" in out
    assert doc["camera_matrix"][0][0] == pytest.approx(camera.K[0, 0], rel=0.01)


# -- exit codes -----------------------------------------------------------------------------------
def test_every_exit_code_is_documented_in_the_help(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for code, text in EXIT_CODES.items():
        assert f"  {code}  {text}" in out


def test_bad_command_lines_exit_2(capsys, tmp_path):
    for argv in (["bag", "x", "--size", "5by7", "--square", "0.03", "--output", "o"],
                 ["bag", "x", "--size", "5x7", "--square", "-1", "--output", "o"],
                 ["images", "x", "--size", "5x7", "--square", "0.03"],
                 ["bag", "x", *BOARD, "--output", "o", "--views-min", "9", "--views-max", "8"]):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == EXIT_USAGE
        capsys.readouterr()
    # refused on the command line, before any frame is read, with the reason
    for option, value, reason in (("--size", "2x5", "at least 3x3 interior corners"),
                                  ("--size", "0x0", "at least 3x3 interior corners"),
                                  ("--size", "1x1", "at least 3x3 interior corners"),
                                  ("--slop", "-1", "sync.slop must be at least 0, got -1.0"),
                                  ("--depth-scale", "1e300", "depth.scale must be at most 10, got 1e+300"),
                                  ("--square", "30", "board.square must be at most 10, got 30.0"),
                                  ("--depth-bias", "offset+wobble", "depth_bias must be 'none' or terms")):
        argv = ["bag", str(tmp_path / "never_read"), *BOARD, "--output", str(tmp_path / "o"), option, value]
        with pytest.raises(SystemExit) as exc:
            main(argv)
        err = capsys.readouterr().err
        assert exc.value.code == EXIT_USAGE and reason in err and "Traceback" not in err, (option, value, err)


def test_unreadable_input_exits_3(capsys, tmp_path):
    code, _, err = run(capsys, "bag", tmp_path / "nothing", *BOARD, "--output", tmp_path / "o")
    assert code == EXIT_UNREADABLE and last_line(err) == f"tof_calib: {tmp_path / 'nothing'}: no such bag"
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "metadata.yaml").write_text("not: [a bag\n")
    code, _, err = run(capsys, "bag", tmp_path / "junk", *BOARD, "--output", tmp_path / "o")
    assert code == EXIT_UNREADABLE and "cannot open the bag" in last_line(err)
    code, _, err = run(capsys, "images", tmp_path / "junk", *BOARD, "--output", tmp_path / "o")
    assert code == EXIT_UNREADABLE and "no amplitude/depth pairs" in last_line(err)
    # a bag whose every frame is unusable
    path = tmp_path / "rgb"
    with BagWriter(path) as bag:
        for i in range(3):
            bag.write("/cam/ir", bag.image_message(np.zeros((4, 4, 3), np.uint8), "rgb8", i, "f"), i)
            bag.write("/cam/depth", bag.image_message(np.zeros((4, 4), np.uint16), "16UC1", i, "f"), i)
    code, _, err = run(capsys, "bag", path, *BOARD, "--output", tmp_path / "o")
    assert code == EXIT_UNREADABLE and last_line(err) == "tof_calib: no usable frame pair: every one was skipped " \
                                                         "(3 encoding)"


def test_missing_topics_exit_4(bags, capsys, tmp_path):
    code, _, err = run(capsys, "bag", bags["mcap"], *BOARD, "--output", tmp_path, "--depth-topic", "/nope")
    assert code == EXIT_MISSING_TOPIC
    assert last_line(err).startswith("tof_calib: --depth-topic /nope: no such topic in the bag (image topics")
    path = tmp_path / "amplitude_only"
    with BagWriter(path) as bag:
        bag.write("/tof/amplitude", bag.image_message(np.ones((4, 4), np.uint16), "mono16", 1.0, "f"), 1.0)
    code, _, err = run(capsys, "bag", path, *BOARD, "--output", tmp_path)
    assert code == EXIT_MISSING_TOPIC and "no depth image topic found" in last_line(err)


@pytest.mark.slow
def test_no_board_exits_5(bags, capsys, tmp_path):
    code, _, err = run(capsys, "bag", bags["sqlite3"], "--size", "9x6", "--square", "0.03", "--output", tmp_path)
    assert code == EXIT_NO_BOARD
    assert last_line(err) == "tof_calib: no 9x6 board found in any of 240 frames (--size counts interior " \
                             "corners, as camera_calibration does)"


def test_too_few_views_exit_6(capsys, tmp_path):
    # a board held at three poses for 8 frames each: three views and their near-duplicates
    bag = tmp_path / "three_poses"
    assert main(["simulate", "--output", str(bag), "--frames", "24", "--hold", "8", "--transit", "0"]) == EXIT_OK
    code, out, err = run(capsys, "bag", bag, *BOARD, "--output", tmp_path / "out", "--views-min", "20")
    assert code == EXIT_TOO_FEW_VIEWS
    assert re.fullmatch(r"tof_calib: only [3-6] views collected, need 20 \(--views-min\); frames were rejected as: "
                        r"too similar to a kept view \(1\d\).*; the views kept are short of [A-Z]\w+ \d+%: [a-z].*",
                        last_line(err)), last_line(err)
    assert not (tmp_path / "out" / "calibration.yaml").exists()


@pytest.mark.slow
def test_a_failed_quality_check_exits_7_and_leaves_the_earlier_calibration(bags, calibrated, capsys, tmp_path):
    shutil.copytree(calibrated, tmp_path, dirs_exist_ok=True, symlinks=True)
    before = {p.relative_to(tmp_path): p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    # depth read in the wrong units (3 mm a count): no focal length and offset reconcile it
    code, out, err = run(capsys, "bag", bags["sqlite3"], *BOARD, "--output", tmp_path, "--depth-scale", "0.003")
    assert code == EXIT_QUALITY
    assert re.fullmatch(rf"tof_calib: calibration not trusted, nothing in {re.escape(str(tmp_path))} changed: "
                        r"(the corners alone give|the depth reads)[^;]*"   # the cause first: 3x the squares
                        r"the depth says (8[5-9]|9[0-4])\.\d mm, not the 30\.0 mm given.*", last_line(err))
    after = {p.relative_to(tmp_path): p.read_bytes() for p in tmp_path.rglob("*")
             if p.is_file() and p.parts[len(tmp_path.parts)] != "rejected"}
    assert after == before   # every earlier file as it was, none added
    assert json.loads((tmp_path / "rejected" / "calibration.json").read_text())["verdict"]["ok"] is False
    assert (tmp_path / "rejected" / "report.html").is_file()
    # the next good run replaces the calibration (a new generation) and clears the refusal's report
    earlier = os.readlink(tmp_path / "current")
    code, _, err = run(capsys, "bag", bags["sqlite3"], *BOARD, "--output", tmp_path)
    assert code == EXIT_OK, err
    assert not (tmp_path / "rejected").exists() and os.readlink(tmp_path / "current") != earlier
    assert read_camera_yaml(tmp_path / "calibration.yaml").K[0, 0] == pytest.approx(284.4, rel=0.01)


def test_other_errors_exit_1(bags, capsys, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    code, _, err = run(capsys, "bag", bags["sqlite3"], *BOARD, "--output", blocker / "out")
    assert code == EXIT_ERROR and "cannot create the output folder" in last_line(err)
    code, _, err = run(capsys, "simulate", "--output", bags["sqlite3"])
    assert code == EXIT_ERROR and "exists already" in last_line(err)
    code, _, err = run(capsys, "check", blocker, bags["sqlite3"], *BOARD)
    assert code == EXIT_ERROR and "expected a map of calibration keys" in last_line(err)


# -- check ----------------------------------------------------------------------------------------
@pytest.mark.slow
def test_check_passes_the_calibration_and_fails_the_factory_one(bags, calibrated, capsys, tmp_path):
    code, out, err = run(capsys, "check", calibrated / "calibration.yaml", bags["mcap"], *BOARD,
                         "--output", tmp_path)
    assert code == EXIT_OK, err
    assert "with calibration.json" in out and "the calibration fits these views" in out
    doc = json.loads((tmp_path / "check.json").read_text())
    assert doc["pixel_rms"] < 0.2 and abs(doc["depth_mean_m"]) < 0.002 and len(doc["views"]) >= 15
    assert abs(doc["depth_scale"]) < 0.003 and all(v["plane_sigma"] < 0.005 for v in doc["views"])
    # a calibration.json from before the wiggle term (neither its terms nor a period) reads as one
    # whose wiggle is 0; the period the data chose is read back (without it the depth fits worse)
    sidecar = json.loads((calibrated / "calibration.json").read_text())
    depth_line = re.compile(r"depth residuals mean (\S+) mm, RMS (\S+) mm.*")
    lines = {}
    for name in ("zeroed", "older"):
        copy = tmp_path / name / "calibration.yaml"
        copy.parent.mkdir()
        copy.write_bytes((calibrated / "calibration.yaml").read_bytes())
        for term in TERMS_ADDED_LATER:
            sidecar["depth_bias"][term] = 0.0
            if name == "older":
                del sidecar["depth_bias"][term]
        if name == "older":
            del sidecar["options"]["modulation_hz"], sidecar["model"]["wiggle_period"]
        copy.with_suffix(".json").write_text(json.dumps(sidecar))
        code, out_copy, err = run(capsys, "check", copy, bags["mcap"], *BOARD)
        assert code == EXIT_OK, err
        lines[name] = depth_line.search(out_copy)
    assert lines["older"][0] == lines["zeroed"][0]
    assert float(depth_line.search(out)[2]) <= float(lines["zeroed"][2])
    # the YAML alone: the camera's 20 mm depth offset is then unknown, and not held against it
    alone = tmp_path / "alone" / "calibration.yaml"
    alone.parent.mkdir()
    alone.write_bytes((calibrated / "calibration.yaml").read_bytes())
    code, out, err = run(capsys, "check", alone, bags["mcap"], *BOARD)
    assert code == EXIT_OK, err
    truth = _truth(bags["mcap"])
    mean = re.search(r"depth residuals mean \+(\d+\.\d\d) mm, RMS 0\.\d\d mm about the mean", out)
    assert mean and float(mean[1]) == pytest.approx(1e3 * truth["depth_offset_m"], abs=1.0), out
    # the recording's factory camera_info: focal lengths 4 % long, which the pixels alone cannot tell
    factory = tmp_path / "factory.yaml"
    write_camera_yaml(factory, {"K": truth["camera_info"]["camera_matrix"], "D": np.zeros(5),
                                "image_size": (200, 200)}, "factory")
    code, out, err = run(capsys, "check", factory, bags["mcap"], *BOARD)
    assert code == EXIT_QUALITY
    assert re.search(r"re-projection RMS 0\.\d+ px", out)
    scale = float(re.search(r"the focal length is off by about \+(\d\.\d)%", last_line(err))[1])
    assert scale == pytest.approx(4.0, abs=0.5)


@pytest.mark.slow
def test_a_recording_of_radial_depth_calibrates_and_checks_in_it(tmp_path, capsys):
    """A raw PMD-class sensor whose depth is the light's path, calibrated on the defaults as a user
    would: the convention is read from the boards' flatness and kept for `tof_calib check`."""
    bag = tmp_path / "radial"
    assert main(["simulate", "--output", str(bag), "--depth-convention", "radial", *SIM]) == EXIT_OK
    code, out, err = run(capsys, "bag", bag, *BOARD, "--output", tmp_path / "cal")
    assert code == EXIT_OK, err
    assert "depth convention radial: the boards are flat read as the radial distance" in err
    doc = json.loads((tmp_path / "cal" / "calibration.json").read_text())
    K, K_true = np.array(doc["camera_matrix"]), np.array(_truth(bag)["camera_matrix"])
    assert doc["depth_convention"] == "radial" and doc["options"]["depth_convention"] == "auto"
    assert K[0, 0] == pytest.approx(K_true[0, 0], rel=0.005) and K[1, 1] == pytest.approx(K_true[1, 1], rel=0.005)
    assert doc["depth_bias"]["depth_offset"] == pytest.approx(_truth(bag)["depth_offset_m"], abs=0.003)
    code, out, err = run(capsys, "check", tmp_path / "cal" / "calibration.yaml", bag, *BOARD)
    assert code == EXIT_OK, err
    assert "(depth convention radial)" in out and "the calibration fits these views" in out


# -- progress and the console script --------------------------------------------------------------
class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_is_a_bar_on_a_terminal_and_plain_lines_otherwise():
    tty, plain = _Terminal(), io.StringIO()
    for stream in (tty, plain):
        p = Progress(10, stream)
        for i in range(1, 11):
            p.update(i, lambda: "views 3 | coverage x 50%")
        p.close("views 3 | coverage x 50%")
    assert "\r" in tty.getvalue() and "10/10" in tty.getvalue() and "views 3" in tty.getvalue()
    lines = plain.getvalue().splitlines()
    assert "\r" not in plain.getvalue() and lines[0].startswith("frames 1/10, views 3")
    assert lines[-1] == "frames 10/10, views 3 | coverage x 50%" and len(lines) <= 3


def test_the_module_runs_and_the_ros2_run_launcher_finds_the_console_script(tmp_path):
    done = subprocess.run([sys.executable, "-m", "tof_calib_ros.offline.cli", "--help"], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0 and "exit codes:" in done.stdout
    # a wheel's layout: <prefix>/lib/tof_calib_ros/tof_calib runs <prefix>/bin/tof_calib with the arguments
    launcher = Path(__file__).resolve().parents[1] / "launchers" / "tof_calib"
    (tmp_path / "lib" / "tof_calib_ros").mkdir(parents=True)
    (tmp_path / "bin").mkdir()
    installed = tmp_path / "lib" / "tof_calib_ros" / "tof_calib"
    installed.write_bytes(launcher.read_bytes())
    installed.chmod(0o755)
    missing = subprocess.run([str(installed)], capture_output=True, text=True, timeout=60)
    assert missing.returncode == 127 and "console script" in missing.stderr
    script = tmp_path / "bin" / "tof_calib"
    script.write_text('#!/bin/sh\necho "ran with $*"\n')
    script.chmod(0o755)
    done = subprocess.run([str(installed), "bag", "x y"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout == "ran with bag x y\n"
