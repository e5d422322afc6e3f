"""Traditional (Zhang) calibration with OpenCV: the baseline and the first initial guess."""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .camera import pack_intrinsics, project, transform
from .errors import CalibrationError

# The distortion presets (options.DISTORTION_TERMS) as OpenCV's flags. The baseline's is
# plumb_bob, ROS camera_calibration's default: k1, k2, p1, p2 free, k3 fixed.
_NO_TANGENTIAL = cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3
OPENCV_FLAGS = {"none": _NO_TANGENTIAL | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2,
                "k1": _NO_TANGENTIAL | cv2.CALIB_FIX_K2, "k1k2": _NO_TANGENTIAL,
                "plumb_bob": cv2.CALIB_FIX_K3, "full": 0, "rational": cv2.CALIB_RATIONAL_MODEL}


@dataclass
class Traditional:
    intrinsics: np.ndarray
    poses: np.ndarray  # (V, 6) rvec, tvec
    rms: float


def calibrate_opencv(object_points: list[np.ndarray], pixels: list[np.ndarray],
                     image_size: tuple[int, int], distortion: str = "plumb_bob") -> Traditional:
    """cv2.calibrateCamera, with its refusals and divergences turned into CalibrationError."""
    w, h = image_size
    obj = [np.asarray(o, dtype=np.float32).reshape(-1, 1, 3) for o in object_points]
    img = [np.asarray(p, dtype=np.float32).reshape(-1, 1, 2) for p in pixels]
    try:
        rms, K, D, rvecs, tvecs = cv2.calibrateCamera(obj, img, (int(w), int(h)), None, None,
                                                     flags=OPENCV_FLAGS[distortion])
    except cv2.error as exc:
        reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else "unknown error"
        raise CalibrationError(f"OpenCV calibration refused the views: {reason}") from exc
    intr = pack_intrinsics(K, D)
    poses = np.array([np.r_[r.ravel(), t.ravel()] for r, t in zip(rvecs, tvecs)])
    if not (np.all(np.isfinite(intr)) and np.all(np.isfinite(poses))):
        raise CalibrationError("OpenCV calibration diverged (non-finite parameters)")
    if intr[0] <= 0 or intr[1] <= 0 or not (0 <= intr[2] <= w and 0 <= intr[3] <= h):
        raise CalibrationError(
            f"OpenCV calibration diverged (fx={intr[0]:.1f}, fy={intr[1]:.1f}, cx={intr[2]:.1f}, cy={intr[3]:.1f})")
    if np.any(poses[:, 5] <= 0):
        raise CalibrationError("OpenCV calibration diverged (board behind the camera)")
    # OpenCV's own RMS is not checked against a re-projection: recompute it from our model.
    err = [project(transform(p[:3], p[3:], o)[0], intr).pixels - x
           for p, o, x in zip(poses, object_points, pixels)]
    rms_ours = float(np.sqrt(np.mean(np.concatenate(err) ** 2) * 2))
    if not np.isfinite(rms_ours) or rms_ours > 10.0:
        raise CalibrationError(f"OpenCV calibration diverged (re-projection RMS {rms_ours:.1f} px)")
    return Traditional(intr, poses, rms_ours)
