"""The HTML report: self-contained, every section there, and its numbers those of the calibrations
it claims to show (checked against calibrations done here independently)."""
from __future__ import annotations

import base64
import re
import struct
from dataclasses import replace
from html.parser import HTMLParser

import cv2
import numpy as np
import pytest

from tof_calib_ros import Board, View, calibrate, sim
from tof_calib_ros.core.camera import N_INTRINSICS
from tof_calib_ros.core.projection_diff import projection_difference, projection_spread
from tof_calib_ros.files.image_folder import load_views
from tof_calib_ros.offline.report import ReportError, _section_parameters, write_report

BOARD = Board(8, 6, 0.04)
CAM = sim.pmd_camera()
SECTIONS = ("summary", "parameters", "residuals", "per-view", "coverage", "poses", "planarization", "comparison",
            "cross-validation")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SHORT = 5   # the view given with too few corners: calibrate leaves it out


class _Page(HTMLParser):
    """The page's tables (by id, rows of cell texts), section texts (by id) and image sources."""

    def __init__(self, text: str):
        super().__init__()
        self.tables: dict[str, list[list[str]]] = {}
        self.sections: dict[str, str] = {}
        self.images: list[str] = []
        self.links: list[str] = []
        self._table = self._section = None
        self._cell: list[str] | None = None
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "section":
            self._section = a["id"]
            self.sections[self._section] = ""
        elif tag == "table":
            self._table = a.get("id")
            self.tables[self._table] = []
        elif tag == "tr" and self._table is not None:
            self.tables[self._table].append([])
        elif tag in ("td", "th"):
            self._cell = []
        elif tag == "img":
            self.images.append(a["src"])
        for key in ("src", "href"):
            if key in a:
                self.links.append(a[key])

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.tables[self._table][-1].append("".join(self._cell).strip())
            self._cell = None
        elif tag == "table":
            self._table = None
        elif tag == "section":
            self._section = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)
        if self._section is not None:
            self.sections[self._section] += data

    def rows(self, table: str) -> dict[str, list[str]]:
        """A table's body rows by their first cell."""
        return {r[0]: r[1:] for r in self.tables[table][1:]}


def _shows(cell: str, value: float) -> bool:
    """Whether the printed number is the value to its printed digits."""
    decimals = len(cell.split(".")[1]) if "." in cell else 0
    return abs(float(cell) - value) <= 0.5 * 10.0 ** -decimals + 1e-9 * abs(value)


def _param(result, name: str) -> float:
    values = np.r_[result.K[0, 0], result.K[1, 1], result.K[0, 2], result.K[1, 2], result.D, result.depth_bias]
    return float(values[["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "depth_offset"].index(name)])


def _scene(n: int, seed: int) -> list[View]:
    rng = np.random.default_rng(seed)
    poses = sim.random_poses(CAM, BOARD, n, rng, distance=(0.55, 0.9), max_tilt_deg=35)
    frames = [sim.render(CAM, BOARD, r, t, noise=sim.Noise(depth=0.003, offset=0.02), rng=rng) for r, t in poses]
    return [View(f.depth, f.corners + rng.normal(0, 0.05, f.corners.shape)) for f in frames]


def _check_images(page: _Page, at_least: int) -> None:
    assert len(page.images) >= at_least
    for src in page.images:
        assert src.startswith("data:image/png;base64,")
        png = base64.b64decode(src.split(",", 1)[1], validate=True)
        assert png[:8] == PNG_SIGNATURE
        width, height = struct.unpack(">II", png[16:24])
        assert width > 100 and height > 100
        image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
        assert image is not None and image.shape[:2] == (height, width)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    views = _scene(13, 1)
    views[SHORT] = View(views[SHORT].depth, views[SHORT].corners[:3], np.arange(3))
    result = calibrate(views, BOARD, distortion="plumb_bob")
    lines: list[str] = []
    path = write_report(tmp_path_factory.mktemp("report") / "report.html", views, BOARD, result, progress=lines.append)
    return views, result, path, lines


def test_the_report_is_self_contained_with_every_section(report):
    views, result, path, lines = report
    assert path.name == "report.html" and path.is_file()
    assert not list(path.parent.glob(".*.tmp"))   # written atomically, nothing left behind
    text = path.read_text("utf-8")
    page = _Page(text)
    assert set(SECTIONS) <= set(page.sections)
    assert all(link.startswith(("data:", "#")) for link in page.links), page.links
    assert not re.search(r"<script|<link|@import|url\(", text)
    _check_images(page, at_least=8)
    # each calibration it runs, then the drawing, said before it starts (13 views, one too short: 12 used)
    assert lines == ["the traditional calibration of the same 12 views", "the first half of the views alone (6)",
                     "the second half of the views alone (6)", "drawing the figures"], lines
    summary = page.sections["summary"]
    assert "Trusted" in summary and f"12 of {len(views)}" in summary
    assert f"view {SHORT}: only 3 corners" in summary
    assert "distortion plumb_bob, depth bias offset" in summary


def test_the_parameters_are_those_of_the_result(report):
    _, result, path, _ = report
    page = _Page(path.read_text("utf-8"))
    rows = page.rows("parameters")
    for name, value in (("fx", result.K[0, 0]), ("fy", result.K[1, 1]), ("cx", result.K[0, 2]), ("k1", result.D[0])):
        assert _shows(rows[name][0], value), (name, rows[name], value)
        assert float(rows[name][1]) == pytest.approx(result.std[name], rel=0.06)
    assert rows["k3"][1] == "fixed"
    assert _shows(rows["depth_offset"][0], result.depth_offset * 1e3) and rows["depth_offset"][2] == "mm"
    assert abs(float(rows["fx"][0]) - CAM.params[0]) < 0.005 * CAM.params[0]   # and the calibration is sound
    per_view = page.rows("views")
    assert sorted(map(int, per_view)) == [v.index for v in result.views]
    for v in result.views:
        assert _shows(per_view[str(v.index)][3], v.pixel_rms)


def test_a_term_the_views_leave_free_is_shown_unconstrained_not_fixed(report):
    """A rational lens's numerator and denominator terms can trade: their variance is infinite
    (a NaN before 2026-11-30), which the table showed as "fixed"."""
    _, result, _, _ = report
    free = replace(result, std={**result.std, "k1": np.inf, "k2": np.inf})
    page = _Page(_section_parameters(free))
    rows = page.rows("parameters")
    assert rows["k1"][1] == rows["k2"][1] == "unconstrained" and rows["k3"][1] == "fixed", rows
    assert float(rows["fx"][1]) == pytest.approx(result.std["fx"], rel=0.06)


def test_traditional_and_cross_validation_match_independent_calibrations(report):
    views, result, path, _ = report
    page = _Page(path.read_text("utf-8"))
    trad = calibrate(views, BOARD, method="traditional")
    rows = page.rows("comparison")
    for name, ours, theirs in (("fx", result.K[0, 0], trad.K[0, 0]), ("cy", result.K[1, 2], trad.K[1, 2]),
                               ("k2", result.D[1], trad.D[1])):
        assert _shows(rows[name][0], ours) and _shows(rows[name][2], theirs)
        assert float(rows[name][3]) == pytest.approx(trad.std[name], rel=0.06)
    assert rows["depth_offset"][2] == "—"
    assert _shows(rows["pixel RMS"][2], trad.pixel_rms)
    # what the depth added: fx's uncertainty against OpenCV's on the same corners, each on its noise
    assert result.depth_gain["fx"] == pytest.approx(trad.std["fx"] / result.noise_std["fx"], rel=0.06)
    assert f"the depth made fx {result.depth_gain['fx']:.3g} and fy" in page.sections["summary"]

    used = [i for i in range(len(views)) if i != SHORT]
    # the halves in the views' order (a recording's), not alternate views
    first = calibrate([views[i] for i in used[:len(used) // 2]], BOARD, distortion="plumb_bob")
    second = calibrate([views[i] for i in used[len(used) // 2:]], BOARD, distortion="plumb_bob")
    cv = page.rows("cross-validation")
    assert list(cv) == ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "depth_offset"]
    for name in cv:
        k = 1e3 if name == "depth_offset" else 1.0   # shown in mm
        e, o = _param(first, name) * k, _param(second, name) * k
        sigma = np.hypot(first.std[name], second.std[name]) * k
        got = cv[name]
        assert _shows(got[0], e) and _shows(got[2], o) and _shows(got[4], e - o), (name, got, e, o)
        assert float(got[5]) == pytest.approx(sigma, rel=0.06)
        assert _shows(got[6], abs(e - o) / sigma)
        assert got[7] == ("consistent" if abs(e - o) <= 3 * sigma else "inconsistent")
    assert "parameters agree within 3 predicted standard deviations" in page.sections["cross-validation"]

    # where over the image the halves project apart, where both saw the board and elsewhere
    text = page.sections["cross-validation"]
    angle, median, most = map(float, re.search(r"frame of ([\d.]+)°.*a median of ([\d.]+) px, ([\d.]+) px at most",
                                               text).groups())
    elsewhere = float(re.search(r"at most one of them looked, by up to ([\d.]+) px", text).group(1))
    cells = np.linspace(-0.5, CAM.width - 0.5, 9), np.linspace(-0.5, CAM.height - 0.5, 9)
    halves = used[:len(used) // 2], used[len(used) // 2:]
    corners = [np.concatenate([views[i].corners for i in half]) for half in halves]
    both = np.logical_and(*[np.histogram2d(*c.T, bins=cells)[0] > 0 for c in corners])

    def in_both(px):
        i, j = (np.clip(np.digitize(px[:, k], cells[k]) - 1, 0, 7) for k in (0, 1))
        return both[i, j]

    seen = np.concatenate(corners)
    pd = projection_difference(np.r_[first.K[[0, 1, 0, 1], [0, 1, 2, 2]], first.D.ravel()],
                               np.r_[second.K[[0, 1, 0, 1], [0, 1, 2, 2]], second.D.ravel()], CAM.size,
                               seen[in_both(seen)])
    shared = in_both(np.stack(np.meshgrid(pd.xs, pd.ys), -1).reshape(-1, 2)).reshape(pd.diff.shape)
    assert 0 < shared.sum() < shared.size
    assert _shows(f"{angle:.2f}", pd.angle_deg)
    assert _shows(f"{median:.2f}", np.median(pd.diff[shared])) and _shows(f"{most:.2f}", pd.diff[shared].max())
    assert _shows(f"{elsewhere:.2f}", np.nanmax(pd.diff[~shared]))


def test_the_coverage_maps_how_well_each_pixel_s_projection_is_known(report):
    views, result, path, _ = report
    text = _Page(path.read_text("utf-8")).sections["coverage"]
    median, most = map(float, re.search(r"known to a median of ([\d.]+) px \(([\d.]+) at most\)", text).groups())
    corners = np.concatenate([views[v.index].corners for v in result.views])
    xs, ys, spread = projection_spread(np.r_[result.K[[0, 1, 0, 1], [0, 1, 2, 2]], result.D.ravel()],
                                       result.run_intrinsics, CAM.size, corners)
    assert result.run_intrinsics.shape == (10, N_INTRINSICS)
    cells = np.zeros((8, 8), bool)
    cells[((corners[:, 0] + 0.5) // 25).astype(int), ((corners[:, 1] + 0.5) // 25).astype(int)] = True
    gx, gy = np.meshgrid(xs, ys)
    reached = spread[cells[((gx + 0.5) // 25).astype(int), ((gy + 0.5) // 25).astype(int)]]
    assert _shows(f"{median:.2f}", np.median(reached)) and _shows(f"{most:.2f}", reached.max())
    assert 0 < median < 0.5   # 12 views of a mild lens over most of the image
    assert result.extrapolated is None   # nothing there worth a note


def test_the_banner_agrees_with_the_cross_validation(report):
    views, result, path, _ = report
    page = _Page(path.read_text("utf-8"))
    apart = [name for name, row in page.rows("cross-validation").items() if row[7] == "inconsistent"]
    summary = page.sections["summary"]
    assert result.ok
    assert ("Trusted" in summary) == (not apart) and ("cross-validation disagrees" in summary) == bool(apart)
    assert all(name in summary for name in apart)


def test_halves_further_apart_than_their_sigmas_take_the_trust_out_of_the_banner(report):
    from dataclasses import replace

    from tof_calib_ros.offline.report import _Comparison, _section_summary

    views, result, _, _ = report
    options = {"distortion": "plumb_bob", "depth_bias": "offset", "plane_squares": "all"}
    K = result.K.copy()
    K[0, 0] += 10 * result.std["fx"]   # 10 / sqrt(2) of the difference's predicted sigmas
    apart = _Comparison(result, (result, replace(result, K=K)), ([0], [1]))
    summary = _section_summary(result, views, options, apart)
    assert "Trusted" not in summary and "cross-validation disagrees" in summary and "fx 7.1" in summary
    agree = _Comparison(result, (result, result), ([0], [1]))
    assert "Trusted:" in _section_summary(result, views, options, agree)


def test_where_opencv_refuses_the_report_says_so(four_corner_views, tmp_path):
    views = four_corner_views
    result = calibrate(views, BOARD, depth_bias="none")
    page = _Page(write_report(tmp_path / "r.html", views, BOARD, result).read_text("utf-8"))
    comparison = page.sections["comparison"]
    assert "traditional calibration of the same views failed" in comparison and "OpenCV" in comparison
    assert "comparison" not in page.tables
    assert "skipped: the calibration used 3 views" in page.sections["cross-validation"]
    assert "cross-validation" not in page.tables
    assert "depth bias none" in page.sections["summary"]
    _check_images(page, at_least=6)


def test_a_lens_other_than_the_baseline_s_is_compared_with_opencv_fitting_it_too(tmp_path):
    """Ours fitted k3; the baseline fixes it as ROS does. The report also shows OpenCV with k3 and
    how far the principal point is from it, the numbers those of an independent calibration."""
    views = _scene(8, 3)
    result = calibrate(views, BOARD, distortion="full")
    page = _Page(write_report(tmp_path / "r.html", views, BOARD, result).read_text("utf-8"))
    same = calibrate(views, BOARD, method="traditional", distortion="full")
    text = page.sections["comparison"]
    assert "chose the full lens terms" in text, text
    shown = re.search(r"cx (\S+) ± \S+, cy (\S+) ± \S+ px: the depth-aided principal point is (\S+), (\S+) px",
                      text)
    assert shown, text
    cx, cy, dx, dy = (float(g) for g in shown.groups())
    assert _shows(f"{cx:.2f}", same.K[0, 2]) and _shows(f"{cy:.2f}", same.K[1, 2])
    assert _shows(f"{dx:.2f}", result.K[0, 2] - same.K[0, 2]) and _shows(f"{dy:.2f}", result.K[1, 2] - same.K[1, 2])
    plumb = calibrate(views, BOARD, distortion="plumb_bob")
    other = _Page(write_report(tmp_path / "p.html", views, BOARD, plumb).read_text("utf-8"))
    assert "lens terms" not in other.sections["comparison"]   # the baseline's own lens: nothing to add


def test_a_whole_board_calibration_is_recalibrated_on_the_whole_board(tmp_path):
    views = _scene(6, 4)
    result = calibrate(views, BOARD, distortion="plumb_bob", plane_squares="all")
    page = _Page(write_report(tmp_path / "r.html", views, BOARD, result).read_text("utf-8"))
    assert "planes on the all squares" in page.sections["summary"]
    assert "pixels of both colours" in page.sections["planarization"]
    first = calibrate(views[:3], BOARD, distortion="plumb_bob", plane_squares="all")
    white = calibrate(views[:3], BOARD, distortion="plumb_bob", plane_squares="white")
    shown = page.rows("cross-validation")["fx"][0]
    assert _shows(shown, first.K[0, 0]) and not _shows(shown, white.K[0, 0])


def test_a_robust_fit_that_dropped_a_corner(tmp_path):
    views = _scene(5, 8)
    views[2].corners[10] += (12.0, -9.0)   # misdetected
    result = calibrate(views, BOARD, distortion="plumb_bob", loss="cauchy")
    assert any("2: [10]" in n for n in result.notes)
    page = _Page(write_report(tmp_path / "r.html", views, BOARD, result).read_text("utf-8"))
    per_view = page.rows("views")
    assert per_view["2"][2] == str(BOARD.n_corners - 1) and per_view["0"][2] == str(BOARD.n_corners)
    assert "dropped outlier corners" in page.sections["summary"]
    assert result.model.dropped_corners == {2: [10]}   # as data, for the report and the JSON


def test_views_that_are_not_the_result_s_are_refused(report, tmp_path):
    views, result, _, _ = report
    with pytest.raises(ReportError, match="only 4 views were given"):
        write_report(tmp_path / "r.html", views[:4], BOARD, result)
    with pytest.raises(ReportError, match="does not match"):
        write_report(tmp_path / "r.html", [View(v.depth, None, None, None) for v in views[::-1]], Board(4, 3, 0.04),
                     result)
    assert not (tmp_path / "r.html").exists()


@pytest.mark.slow
def test_a_report_on_real_kinect_views(kinect_dir, tmp_path):
    board = Board(5, 7, 0.03)
    views = load_views(kinect_dir)[::6][:8]
    result = calibrate(views, board, depth_bias="offset+tilt")
    assert len(result.views) >= 6
    page = _Page(write_report(tmp_path / "report.html", views, board, result, title="Kinect v2").read_text("utf-8"))
    assert set(SECTIONS) <= set(page.sections)
    _check_images(page, at_least=8)
    rows = page.rows("parameters")
    assert _shows(rows["fx"][0], result.K[0, 0]) and _shows(rows["depth_tilt_y"][0], result.depth_bias[3])
    assert 15 < float(rows["depth_offset"][0]) < 35   # mm: the data set's own calibration found 25.5
    assert "depth bias offset+tilt" in page.sections["summary"]
    assert {"fx", "depth_tilt_x", "depth_tilt_y"} <= set(page.rows("cross-validation"))
    trad = page.rows("comparison")
    assert 340 < float(trad["fx"][2]) < 390   # OpenCV calibrates real Kinect views
    assert "the one with the most plane pixels" in page.sections["planarization"]
