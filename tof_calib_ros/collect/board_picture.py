"""The picture of what the collector sees, as ROS camera_calibration's window shows it.

The amplitude image tone-mapped and enlarged to a readable size, the board's corners drawn on it
(green: the frame became a view; orange: a board, but no view, and why), the reason in words,
and beside it a bar per coverage axis (as ``ViewCollector.progress`` measures them) and the view
count. Drawn with OpenCV only, so the node publishes it as ``~/board_image`` and a script can
write it as a PNG alike.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from ..core.detection import tone_map
from ..core.errors import CalibrationError
from .collector import AXES, LABELS, WHAT_TO_DO, Outcome, short_axes

MIN_HEIGHT = 400        # px: a 200x200 sensor's frame is enlarged twice
PANEL_WIDTH = 220       # px of bars beside the image
KEPT, REFUSED, TEXT, BAR, BAR_FULL = (60, 200, 60), (0, 150, 255), (255, 255, 255), (90, 90, 90), (60, 200, 60)
TEXT_LINES, LINE_PX = 3, 18   # the reason, wrapped, over the top of the frame
TEXT_BAND_PX = 8 + LINE_PX * TEXT_LINES
# The panel: the view count, a label and a bar per axis BAR_STEP px apart, then what to do next,
# all within MIN_HEIGHT: the longest advice takes three lines, whose third fell below a 200x200
# sensor's picture with the bars 50 px apart.
COUNT_PX, BAR_STEP, NEXT_PX = 30, 46, 36


def scale_for(height: int) -> int:
    """The whole-number enlargement of a frame ``height`` px tall (nearest neighbour, so a pixel
    stays a square)."""
    return max(1, math.ceil(MIN_HEIGHT / height))


def enlarged(points: np.ndarray, k: int) -> np.ndarray:
    """Where points of the frame are in the picture: pixel i covers k i .. k i + k - 1, whose
    centre (OpenCV's convention: a pixel's centre is its integer coordinate) is k i + (k - 1) / 2."""
    return k * np.asarray(points, dtype=float) + (k - 1) / 2


def draw(amplitude: np.ndarray, outcome: Outcome, progress: dict) -> np.ndarray:
    """A BGR uint8 picture: the frame with its corners and reason, and the coverage panel."""
    k = scale_for(amplitude.shape[0])
    try:
        mapped = tone_map(amplitude)
    except CalibrationError:   # a blank frame (a covered lens): shown black under its reason, not skipped
        mapped = np.zeros(amplitude.shape[:2], np.uint8)
    gray = cv2.resize(mapped, None, fx=k, fy=k, interpolation=cv2.INTER_NEAREST)
    frame = cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
    colour = KEPT if outcome.accepted else REFUSED
    _text_lines(frame, outcome.reason, (255, 255, 255) if outcome.accepted or outcome.corners is None else colour)
    if outcome.corners is not None:   # over the text's band: a board at the top of the frame keeps its rings
        for x, y in enlarged(outcome.corners, k):
            cv2.circle(frame, (int(round(x)), int(round(y))), max(3, k + 1), colour, 2, cv2.LINE_AA)
    panel = np.zeros((frame.shape[0], PANEL_WIDTH, 3), np.uint8)
    y = COUNT_PX
    cv2.putText(panel, f"views {progress['views']}", (10, y), cv2.FONT_HERSHEY_SIMPLEX, 0.7, TEXT, 2, cv2.LINE_AA)
    for name in AXES:
        y += BAR_STEP
        share = float(progress["axes"][name]["progress"])
        cv2.putText(panel, LABELS[name], (10, y - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.55, TEXT, 1, cv2.LINE_AA)
        cv2.rectangle(panel, (10, y), (PANEL_WIDTH - 10, y + 14), BAR, -1)
        cv2.rectangle(panel, (10, y), (10 + int(share * (PANEL_WIDTH - 20)), y + 14),
                      BAR_FULL if share >= 1.0 else REFUSED, -1)
    if progress.get("good_enough"):
        cv2.putText(panel, "enough to calibrate", (10, y + NEXT_PX), cv2.FONT_HERSHEY_SIMPLEX, 0.55, KEPT, 1,
                    cv2.LINE_AA)
    elif short := short_axes(progress):   # what to do next, for the least covered axis
        for i, line in enumerate(_wrapped("next: " + WHAT_TO_DO[short[0][0]], PANEL_WIDTH // 8)):
            cv2.putText(panel, line, (10, y + NEXT_PX + LINE_PX * i), cv2.FONT_HERSHEY_SIMPLEX, 0.45, REFUSED, 1,
                        cv2.LINE_AA)
    return np.hstack([frame, panel])


def _wrapped(text: str, width: int) -> list[str]:
    """``text`` in lines of at most ``width`` characters, broken between words."""
    lines = [""]
    for word in text.split():
        if lines[-1] and len(lines[-1]) + len(word) + 1 > width:
            lines.append("")
        lines[-1] = (lines[-1] + " " + word).strip()
    return lines


def _text_lines(image: np.ndarray, text: str, colour: tuple[int, int, int]) -> None:
    """``text`` wrapped over the top of the image on a dark band, so it reads on any frame."""
    lines = _wrapped(text, max(20, image.shape[1] // 9))[:TEXT_LINES]
    cv2.rectangle(image, (0, 0), (image.shape[1], 8 + LINE_PX * len(lines)), (0, 0, 0), -1)
    for i, line in enumerate(lines):
        cv2.putText(image, line, (5, 20 + LINE_PX * i), cv2.FONT_HERSHEY_SIMPLEX, 0.45, colour, 1, cv2.LINE_AA)
