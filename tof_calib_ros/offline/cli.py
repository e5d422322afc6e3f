"""tof_calib: calibrate a ToF camera offline, from a bag or a folder of images, with no ROS install.

    tof_calib bag BAG --size 5x7 --square 0.03 --output DIR
    tof_calib images DIR --size 5x7 --square 0.03 --output DIR
    tof_calib simulate --output BAG
    tof_calib check CALIBRATION.yaml BAG|DIR --size 5x7 --square 0.03

Frames go through the calibration node's view collector (same rules, same defaults) and the
same calibration; the board is looked for in two worker processes. Reasons and figures go to
stdout, progress to stderr (a bar on a terminal, plain lines otherwise), and a failure ends
with one line on stderr and an exit code (see ``tof_calib --help``).
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from .. import Board, CalibrationError, calibrate
from ..collect.collector import AXES, LABELS, ViewCollector, still_short
from ..collect.replay import SKIP_KINDS, Frame, Replay, Skip, Summary, default_workers
from ..files.bag_io import STORAGES, BagError, BagSource, TopicError
from ..files.calibration_file import CalibrationFileError, write_json
from ..files.image_decode import DEPTH_ENCODINGS
from ..files.image_folder import is_image_folder, scan
from ..files.output_folder import write_calibration
from ..settings import LINKED, SETTINGS, calibration_options, collector_config, defaults, refusal
from ..sim.recording import CAMERA_INFO_MODES, MOTIONS, Scene, write_recording
from ..sim.stream import CAMERAS
from .check import check_views, load_calibration

REJECTED_DIR = "rejected"  # a refused calibration's report and figures, inside --output
EXIT_OK = 0
EXIT_ERROR = 1            # any other failure with a reason: bad value, unwritable output, calibration refused
EXIT_USAGE = 2            # argparse's: unknown option, missing argument
EXIT_UNREADABLE = 3       # the bag or folder cannot be opened or read, or holds no usable frame
EXIT_MISSING_TOPIC = 4    # the bag lacks a topic (or several could be it)
EXIT_NO_BOARD = 5         # no frame shows the board
EXIT_TOO_FEW_VIEWS = 6    # fewer views collected than --views-min
EXIT_QUALITY = 7          # the calibration (or the checked one) fails the quality check
EXIT_CODES = {EXIT_OK: "success", EXIT_ERROR: "other error (the message says which)",
              EXIT_USAGE: "bad command line", EXIT_UNREADABLE: "bag or folder unreadable, or no usable frame in it",
              EXIT_MISSING_TOPIC: "topic missing from the bag (or ambiguous)",
              EXIT_NO_BOARD: "no board found in any frame", EXIT_TOO_FEW_VIEWS: "too few views collected",
              EXIT_QUALITY: "calibration fails the quality check (check: the calibration does not fit the data)"}
PLAIN_PERIOD_S = 2.0


class Failure(Exception):
    """Ends the command with ``code`` and a one-line reason."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


# -- argument types ---------------------------------------------------------------------------
def _board_size(text: str) -> tuple[int, int]:
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not match:
        raise argparse.ArgumentTypeError(f"{text!r} is not COLSxROWS (interior corners, e.g. 5x7)")
    size = int(match[1]), int(match[2])
    try:
        Board(*size, 0.03)
    except CalibrationError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return size


def _positive(kind: type) -> Callable[[str], float]:
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not value > 0:
            raise argparse.ArgumentTypeError(f"must be positive, got {text}")
        return value
    return parse


# -- progress ---------------------------------------------------------------------------------
def _coverage(collector: ViewCollector) -> str:
    axes = collector.progress()["axes"]
    return " ".join(f"{LABELS[a]} {axes[a]['progress']:.0%}" for a in AXES)


def _views_and_coverage(collector: ViewCollector) -> str:
    return f"views {len(collector)} | coverage {_coverage(collector)}"


class Progress:
    """A bar over the frames, with a detail such as the views and coverage, on a terminal; a
    plain line every few seconds otherwise (a log file should not fill with bar redraws)."""

    def __init__(self, total: int | None, stream=None) -> None:
        self.total, self.stream = total, stream or sys.stderr
        self.tty = self.stream.isatty()
        self._bar = None
        self._last = 0.0
        self._done = 0

    def update(self, done: int, detail: Callable[[], str] = str) -> None:
        """``done`` frames so far; ``detail`` is called only when it is shown."""
        self._done = min(done, self.total) if self.total else done
        now = time.monotonic()
        if self.tty:
            if self._bar is None:   # made on first use: after any worker processes have started
                from tqdm import tqdm
                self._bar = tqdm(total=self.total, unit="frame", file=self.stream, dynamic_ncols=True)
            self._bar.update(self._done - self._bar.n)
        if now - self._last >= (0.5 if self.tty else PLAIN_PERIOD_S):
            self._last = now
            self._show(detail())

    def _show(self, detail: str) -> None:
        if self._bar is not None:
            self._bar.set_postfix_str(detail)
        elif not self.tty:
            of = f"/{self.total}" if self.total else ""
            print(f"frames {self._done}{of}" + (f", {detail}" if detail else ""), file=self.stream, flush=True)

    def close(self, detail: str = "") -> None:
        self._show(detail)
        if self._bar is not None:
            self._bar.close()


def stages(what: str) -> Callable[[str], None]:
    """A line on stderr for each stage a long step reaches, with the seconds since it began: a
    calibration takes seconds to minutes (17 s for 48 views at 512x424) and its report as
    long again."""
    start = time.monotonic()
    return lambda stage: print(f"{what} ({time.monotonic() - start:.0f} s): {stage}", file=sys.stderr, flush=True)


# -- the shared steps -------------------------------------------------------------------------
def _board(args: argparse.Namespace) -> Board:
    return Board(args.size[0], args.size[1], args.square)


def _values(args: argparse.Namespace) -> dict:
    """The settings (settings.py) as this command line gives them; the rest at their defaults."""
    values = defaults()
    for name, setting in SETTINGS.items():
        given = None if setting.flag is None else getattr(args, setting.flag[2:].replace("-", "_"), None)
        if given is not None:
            values[name] = given
    return values


def _collect(args: argparse.Namespace, board: Board, frames: Iterable[Frame | Skip], total: int | None,
             stills: bool, image_size: tuple[int, int] | None = None) -> tuple[Summary, ViewCollector]:
    config = collector_config(_values(args), stills)
    progress = Progress(total)

    def show(summary: Summary, collector: ViewCollector) -> None:
        progress.update(summary.frames + sum(summary.skipped.values()), lambda: _views_and_coverage(collector))

    replay = Replay(board, config, workers=args.workers, image_size=image_size, progress=show)
    try:
        summary = replay.run(frames)
    finally:
        progress.close(_views_and_coverage(replay.collector))
    return summary, replay.collector


def _print_summary(summary: Summary, collector: ViewCollector, unpaired: dict[str, int] | None = None,
                   unstamped: int = 0) -> None:
    print(f"frames: {summary.frames} judged, {summary.boards} with a board, {len(collector)} views kept")
    print(f"coverage: {_coverage(collector)}")
    if summary.rejections:
        print("not kept: " + ", ".join(f"{n} {reason}" for reason, n in summary.rejections.most_common()))
    if unstamped:
        print(f"unstamped: {unstamped} messages had a header stamp of 0 (the driver does not stamp its images): "
              "paired and ordered by the time the recorder received them")
    if unpaired and any(unpaired.values()):
        print("unpaired: " + ", ".join(f"{n} {role}" for role, n in unpaired.items() if n)
              + " frames had no partner within the pairing slop (--slop)")
    if summary.skipped:
        print("skipped: " + "; ".join(f"{n} {kind} ({SKIP_KINDS[kind]})" for kind, n in summary.skipped.most_common()))
        for kind, examples in summary.examples.items():
            for e in examples:
                print(f"  {kind}: {e.where}: {e.reason}")


def _require_views(summary: Summary, collector: ViewCollector, board: Board, views_min: int) -> None:
    """Fail with the reason when the frames gave too little to calibrate."""
    if summary.frames == 0:
        raise Failure(EXIT_UNREADABLE, "no usable frame pair" + (
            f": every one was skipped ({', '.join(f'{n} {k}' for k, n in summary.skipped.most_common())})"
            if summary.skipped else " in the input"))
    if summary.boards == 0:
        raise Failure(EXIT_NO_BOARD, f"no {board.cols}x{board.rows} board found in any of {summary.frames} frames "
                                     "(--size counts interior corners, as camera_calibration does)")
    n = len(collector)
    if n < views_min:
        why = []
        for what, counts in (("frames were rejected as", summary.rejections), ("messages were skipped as",
                                                                                summary.skipped)):
            if counts:
                why.append(f"{what}: " + ", ".join(f"{reason} ({c})" for reason, c in counts.most_common(3)))
        short = still_short(collector.progress())
        if short:   # what a new recording should do
            why.append(f"the views kept are short of {short}")
        raise Failure(EXIT_TOO_FEW_VIEWS, f"only {n} views collected, need {views_min} "
                                          "(--views-min); " + "; ".join(why))


def _output_dir(path: Path) -> Path:
    """The output folder, made now, so an unwritable one fails before the long work."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise Failure(EXIT_ERROR, f"cannot create the output folder {path}: {exc.strerror or exc}") from None
    if not os.access(path, os.W_OK):
        raise Failure(EXIT_ERROR, f"cannot write to the output folder {path}")
    return path


def _calibrate_and_write(args: argparse.Namespace, board: Board, summary: Summary, collector: ViewCollector,
                         source: dict) -> int:
    views = collector.views
    t0 = time.monotonic()
    options = calibration_options(_values(args))
    try:
        result = calibrate(views, board, summary.image_size, **options,
                           progress=stages(f"calibrating {len(views)} views"))
    except CalibrationError as exc:
        raise Failure(EXIT_ERROR, f"calibration failed: {exc}") from None
    print("calibration: " + result.summary(len(views), time.monotonic() - t0))
    driver = source.get("camera_info")
    if driver is not None:
        K = np.asarray(driver["camera_matrix"])
        print(f"the recording's camera_info: fx={K[0, 0]:.2f} fy={K[1, 1]:.2f} cx={K[0, 2]:.2f} cy={K[1, 2]:.2f} "
              f"(fx differs from ours by {(K[0, 0] / result.K[0, 0] - 1) * 100:+.2f} %)")
    out = Path(args.output)
    extra = {"board": {"cols": board.cols, "rows": board.rows, "square_m": board.square},
             "camera_name": args.camera_name, "source": source,
             "collection": {"frames": summary.frames, "frames_with_board": summary.boards,
                            "skipped": dict(summary.skipped), "view_stamps": summary.view_stamps}}
    rejected = out / REJECTED_DIR
    if not result.ok:
        # what went wrong, beside (never over) an earlier good calibration
        rejected.mkdir(exist_ok=True)
        written = [write_json(rejected / "calibration.json", result, extra),
                   _write_report(rejected / "report.html", views, board, result, source["path"])]
        print("wrote " + ", ".join(str(p) for p in written))
        raise Failure(EXIT_QUALITY, f"calibration not trusted, nothing in {out} changed: " + "; ".join(result.verdict))
    try:
        yaml_path = write_calibration(out, result, views, args.camera_name, extra, report=lambda path: _write_report(
            path, views, board, result, source["path"]))
    except CalibrationFileError as exc:
        raise Failure(EXIT_ERROR, str(exc)) from None
    shutil.rmtree(rejected, ignore_errors=True)   # an earlier refusal's: this result replaces it
    print(f"wrote {yaml_path}, {out / 'calibration.json'}, {out / 'views'}/, {out / 'report.html'} "
          f"(as one set: {out / 'current'})")
    return EXIT_OK


def _write_report(path: Path, views, board: Board, result, title: str) -> Path:
    """The report of ``result`` (which calibrates again with the options ``result`` records)."""
    from .report import write_report  # matplotlib is imported only when a report is written
    return write_report(path, views, board, result, title=f"tof_calib: {title}",
                        progress=stages("writing the report"))


# -- commands ---------------------------------------------------------------------------------
def _bag_frames(args: argparse.Namespace, board: Board, path: Path):
    """Collect views from a bag; returns the summary, the collector and what to record of the source."""
    with BagSource(path, amplitude=args.amplitude_topic or None, depth=args.depth_topic or None,
                   camera_info=args.camera_info_topic, slop=args.slop, depth_scale=args.depth_scale) as bag:
        t = bag.topics
        print(f"bag: {bag.path} ({bag.storage}, {bag.frame_count} amplitude messages)")
        print("topics: " + ", ".join(f"{role} {name} ({t.how[role]})" for role, name in
                                     (("amplitude", t.amplitude), ("depth", t.depth), ("camera_info", t.camera_info))
                                     if name is not None)
              + ("" if t.camera_info else "; no camera_info topic: the first frame sets the image size"))
        info = bag.camera_info
        size = None if info is None else (info.width, info.height)
        summary, collector = _collect(args, board, bag.frames(), bag.frame_count, False, size)
        source = {"kind": "bag", "path": str(bag.path), "storage": bag.storage,
                  "topics": {"amplitude": t.amplitude, "depth": t.depth, "camera_info": t.camera_info},
                  "camera_info": None if info is None else {"width": info.width, "height": info.height,
                                                            "camera_matrix": info.K.tolist(),
                                                            "distortion_coefficients": info.D.tolist()}}
        _print_summary(summary, collector, bag.unpaired, bag.unstamped)
    return summary, collector, source


def _folder_frames(args: argparse.Namespace, board: Board, folder: Path):
    if not folder.is_dir():
        raise Failure(EXIT_UNREADABLE, f"{folder}: not a folder")
    try:
        frames, skips = scan(folder, args.depth_scale, board.n_corners)
    except OSError as exc:
        raise Failure(EXIT_UNREADABLE, f"{folder}: cannot list it ({exc.strerror or exc})") from None
    if not frames:
        raise Failure(EXIT_UNREADABLE, f"{folder}: no amplitude/depth pairs (NNNN_ir.png with NNNN_depth.png; "
                                       "PNG, TIFF or NPY)")
    saved = sum(f.corners_path is not None for f in frames)
    print(f"folder: {folder} ({len(frames)} amplitude/depth pairs, each a still: every one with a board is used, "
          "near-duplicates aside" + (f"; {saved} with the corners saved beside them" if saved else "") + ")")
    summary, collector = _collect(args, board, [*skips, *frames], len(frames) + len(skips), stills=True)
    _print_summary(summary, collector)
    return summary, collector, {"kind": "folder", "path": str(folder)}


def _calibrate_from(args: argparse.Namespace, collect: Callable[[argparse.Namespace, Board, Path], tuple],
                    source: Path) -> int:
    board = _board(args)
    _output_dir(Path(args.output))
    summary, collector, described = collect(args, board, source)
    _require_views(summary, collector, board, args.views_min)
    return _calibrate_and_write(args, board, summary, collector, described)


def cmd_bag(args: argparse.Namespace) -> int:
    return _calibrate_from(args, _bag_frames, args.bag)


def cmd_images(args: argparse.Namespace) -> int:
    return _calibrate_from(args, _folder_frames, args.folder)


def cmd_simulate(args: argparse.Namespace) -> int:
    scene = Scene(camera=args.camera, board=_board(args), frames=args.frames, rate=args.rate, hold=args.hold,
                  transit=args.transit, motion=args.motion, segment=args.segment, exposure=args.exposure,
                  lead_in=args.lead_in, depth_convention=args.depth_convention,
                  depth_encoding=args.depth_encoding, depth_offset=args.depth_offset,
                  camera_info=args.camera_info, seed=args.seed)
    out = Path(args.output)
    if out.exists():
        raise Failure(EXIT_ERROR, f"{out} exists already; a bag is never overwritten")
    progress = Progress(args.frames)
    try:
        truth = write_recording(out, scene, args.storage, progress=progress.update)
    finally:
        progress.close()
    print(f"wrote {out} ({args.storage}, {args.frames} frames of {scene.sim_camera.width}x"
          f"{scene.sim_camera.height}) and its ground truth {truth}")
    return EXIT_OK


def cmd_check(args: argparse.Namespace) -> int:
    board = _board(args)
    calibration = load_calibration(args.calibration)
    # the convention given, else the one the calibration was made in ('auto' chose it then)
    given = None if args.depth_convention == "auto" else args.depth_convention
    convention = given or calibration.depth_convention or "z"
    print(f"checking {calibration.source} (depth convention {convention})")
    source = Path(args.data)
    if is_image_folder(source):
        summary, collector, _ = _folder_frames(args, board, source)
    else:
        summary, collector, _ = _bag_frames(args, board, source)
    _require_views(summary, collector, board, args.views_min)
    result = check_views(collector.views, board, calibration, convention)
    print(f"{'view':>4} {'reproj px':>9} {'depth mean mm':>13} {'depth RMS mm':>12} {'plane sigma mm':>14}")
    for v in result.views:
        print(f"{v.index:4d} {v.pixel_rms:9.3f} {v.depth_mean * 1e3:13.2f} {v.depth_rms * 1e3:12.2f} "
              f"{v.plane_sigma * 1e3:14.2f}" + (f"  {v.note}" if v.note else ""))
    print(f"all views: re-projection RMS {result.pixel_rms:.3f} px; depth residuals mean "
          f"{result.depth_mean * 1e3:+.2f} mm, RMS {result.depth_rms * 1e3:.2f} mm"
          + ("" if result.has_depth_model else " about the mean (no calibration.json: the depth offset is unknown)")
          + (f", growing by {result.depth_scale:+.2%} of the distance" if np.isfinite(result.depth_scale)
             else ", all at about one distance (the focal length cannot be judged from the depth)"))
    if args.output:
        out = _output_dir(Path(args.output))
        path = write_json(out / "check.json", result, {"calibration": calibration.source, "data": str(source)})
        print(f"wrote {path}")
    if not result.ok:
        raise Failure(EXIT_QUALITY, "the calibration does not fit these views: " + "; ".join(result.verdict))
    print("the calibration fits these views")
    return EXIT_OK


# -- the command line -------------------------------------------------------------------------
def _option(p: argparse.ArgumentParser, name: str, metavar: str | None = None, **overrides) -> None:
    """tof_calib's option for the setting ``name`` (settings.py): the node's flag, default, check and words."""
    setting = SETTINGS[name]
    kind = type(setting.default)

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'a number' if kind is not str else 'text'}") from None
        reason = setting.refusal(value)
        if reason:
            raise argparse.ArgumentTypeError(reason)
        return value

    default = overrides.pop("default", setting.default)
    shown = "" if default in (None, "") else f" (default {default})"
    p.add_argument(setting.flag, type=parse, default=default, metavar=metavar or (
        "|".join(setting.choices) if setting.choices else "X"), help=setting.text + shown, **overrides)


def _add_board(p: argparse.ArgumentParser, required: bool = True) -> None:
    kw = {"required": True} if required else {"default": None}
    p.add_argument("--size", type=_board_size, metavar="COLSxROWS",
                   help="interior corners, as ROS camera_calibration counts them (e.g. 5x7)",
                   **(kw if required else {"default": (5, 7)}))
    _option(p, "board.square", "M", **({"required": True, "default": None} if required else {}))


def _add_collection(p: argparse.ArgumentParser, convention_default: str | None = "auto") -> None:
    _option(p, "depth.convention", default=convention_default)
    _option(p, "depth.scale", "M")
    _option(p, "views.min", "N")
    _option(p, "views.max", "N")
    _option(p, "motion.exposure", "S")
    _option(p, "motion.max_blur_px", "PX")
    p.add_argument("--workers", type=int, default=default_workers(), metavar="N",
                   help=f"processes looking for the board (default {default_workers()})")


def _add_topics(p: argparse.ArgumentParser) -> None:
    _option(p, "bag.amplitude_topic", "T")
    _option(p, "bag.depth_topic", "T")
    p.add_argument("--camera-info-topic", metavar="T", help="default: the CameraInfo topic (used for the image "
                                                            "size and compared with the result)")
    _option(p, "sync.slop", "S")


def _add_calibration(p: argparse.ArgumentParser) -> None:
    p.add_argument("--output", required=True, type=Path, metavar="DIR",
                   help="where calibration.yaml, calibration.json, views/ and report.html go (for a refused "
                        "calibration: its report and figures in DIR/rejected/, nothing else changed)")
    for name in ("depth.bias", "calibration.distortion", "calibration.loss", "calibration.plane_squares"):
        _option(p, name, "TERMS" if name == "depth.bias" else None)
    _option(p, "depth.modulation_mhz", "MHZ")
    _option(p, "camera_name", "NAME")


def build_parser() -> argparse.ArgumentParser:
    epilog = "exit codes:\n" + "\n".join(f"  {code}  {text}" for code, text in EXIT_CODES.items())
    parser = argparse.ArgumentParser(prog="tof_calib", description=__doc__.splitlines()[0],
                                     epilog=epilog, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, text: str, run: Callable[[argparse.Namespace], int]) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=text, description=text, epilog=epilog,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        p.set_defaults(run=run)
        return p

    p = command("bag", "calibrate from a recording: rosbag2 (sqlite3, mcap) or ROS 1 .bag", cmd_bag)
    p.add_argument("bag", type=Path, metavar="BAG")
    _add_board(p)
    _add_calibration(p)
    _add_topics(p)
    _add_collection(p)

    p = command("images", "calibrate from a folder of amplitude/depth pairs (NNNN_ir.png + NNNN_depth.png; "
                          "PNG, TIFF or NPY), each a still", cmd_images)
    p.add_argument("folder", type=Path, metavar="DIR")
    _add_board(p)
    _add_calibration(p)
    _add_collection(p)

    p = command("simulate", "write a recording of the simulated ToF camera (amplitude, depth, camera_info) "
                            "and its ground truth (BAG.truth.json)", cmd_simulate)
    p.add_argument("--output", required=True, type=Path, metavar="BAG", help="the bag to create")
    _add_board(p, required=False)
    p.add_argument("--camera", choices=tuple(CAMERAS), default="pmd", help="pmd: 200x200; azure: 640x576")
    p.add_argument("--frames", type=int, default=Scene.frames)
    p.add_argument("--rate", type=_positive(float), default=Scene.rate, help="frames per second")
    p.add_argument("--motion", choices=MOTIONS, default=Scene.motion,
                   help="hold: held still at each pose, then carried to the next (default); continuous: never "
                        "still, entering from the side, blurred where it moves fast")
    p.add_argument("--hold", type=int, default=Scene.hold, help="hold: frames the board is held still at each pose")
    p.add_argument("--transit", type=int, default=Scene.transit, help="hold: frames it moves between poses")
    p.add_argument("--segment", type=_positive(float), default=Scene.segment, metavar="S",
                   help=f"continuous: seconds from one pose to the next (default {Scene.segment})")
    p.add_argument("--exposure", type=float, default=Scene.exposure, metavar="S",
                   help=f"continuous: how long each frame is exposed while the board moves (default {Scene.exposure})")
    p.add_argument("--lead-in", type=int, default=Scene.lead_in, metavar="N",
                   help="frames without a board before it appears (default 0)")
    p.add_argument("--depth-convention", choices=("z", "radial"), default="z")
    p.add_argument("--depth-encoding", choices=DEPTH_ENCODINGS, default="16UC1")
    p.add_argument("--depth-offset", type=float, default=0.02, metavar="M", help="systematic depth offset")
    p.add_argument("--camera-info", choices=CAMERA_INFO_MODES, default="factory",
                   help="the camera_info published: a factory calibration 4%% off (default), the truth, or none")
    p.add_argument("--storage", choices=STORAGES, default="sqlite3")
    p.add_argument("--seed", type=int, default=0)

    p = command("check", "judge an existing calibration on a recording or folder: re-projection RMS, depth "
                         "residuals, board planarity per view", cmd_check)
    p.add_argument("calibration", type=Path, metavar="CALIBRATION.yaml",
                   help="a camera_calibration_parsers YAML; a calibration.json beside it adds the depth model")
    p.add_argument("data", type=Path, metavar="BAG|DIR")
    _add_board(p)
    p.add_argument("--output", type=Path, metavar="DIR", help="also write check.json there")
    _add_topics(p)
    _add_collection(p, convention_default=None)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "workers", 1) < 1:
        parser.error("--workers must be at least 1")
    reason = refusal({name: v for name, v in _values(args).items() if any(name in pair for pair in LINKED)})
    if reason:
        parser.error(reason)
    try:
        return args.run(args)
    except Failure as exc:
        code, message = exc.code, str(exc)
    except TopicError as exc:
        code, message = EXIT_MISSING_TOPIC, str(exc)
    except BagError as exc:
        code, message = EXIT_UNREADABLE, str(exc)
    except CalibrationError as exc:
        code, message = EXIT_ERROR, str(exc)
    except KeyboardInterrupt:
        code, message = 130, "interrupted"
    sys.stdout.flush()
    print(f"tof_calib: {message}", file=sys.stderr)
    return code


if __name__ == "__main__":
    raise SystemExit(main())
