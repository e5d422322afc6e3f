"""A simulated ToF camera driver: the demo and the tests with no hardware.

Publishes ``amplitude`` (mono16), ``depth`` (16UC1 millimetres, or 32FC1 metres) and
``camera_info`` (a deliberately wrong factory calibration) from the renderer, moving the board
through varied poses and holding each for a moment as a person would; serves
``set_camera_info`` as a driver with camera_info_manager does (stores the calibration to a
file and answers with success and a status message).
"""
from __future__ import annotations

import numpy as np
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image
from sensor_msgs.srv import SetCameraInfo

from .. import Board, CalibrationError
from ..files.calibration_file import CalibrationFileError, monocular_fields, write_camera_yaml
from ..files.image_decode import DEPTH_ENCODINGS
from ..sim import stream
from .run import run

# name: (default, description); all read-only
PARAMETERS = {
    "camera": ("pmd", "'pmd' (200x200) or 'azure' (640x576)"),
    "rate": (15.0, "frames per second"),
    "hold": (4, "frames each board pose is held still"),
    "board.cols": (5, "interior corners per row"),
    "board.rows": (7, "interior corners per column"),
    "board.square": (0.03, "square size, metres"),
    "depth.convention": ("z", "'z' or 'radial'"),
    "depth.encoding": ("16UC1", "'16UC1' (millimetres) or '32FC1' (metres)"),
    "depth.offset": (0.02, "systematic depth offset, metres"),
    "frame_id": ("tof_optical_frame", "frame_id of the images"),
    "calibration_file": ("", "where set_camera_info stores the calibration (empty: memory only)"),
    "seed": (0, "random seed of the poses and the noise"),
}


class SimCameraNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("tof_sim_node", **kwargs)
        for name, (default, text) in PARAMETERS.items():
            self.declare_parameter(name, default, ParameterDescriptor(description=text, read_only=True))
        p = lambda name: self.get_parameter(name).value  # noqa: E731
        self._check(p)
        self.camera = stream.CAMERAS[p("camera")]()
        self.board = Board(p("board.cols"), p("board.rows"), p("board.square"))
        self.convention, self.encoding, self.frame_id = p("depth.convention"), p("depth.encoding"), p("frame_id")
        self.hold, self.calibration_file = int(p("hold")), p("calibration_file")
        self.rng = np.random.default_rng(p("seed"))
        self.noise = stream.noise(p("depth.offset"))
        self.poses = stream.poses(self.camera, self.board, 200, self.rng)
        self.frame = 0
        self.info = self._factory_info()
        self.amplitude_pub = self.create_publisher(Image, "amplitude", qos_profile_sensor_data)
        self.depth_pub = self.create_publisher(Image, "depth", qos_profile_sensor_data)
        self.info_pub = self.create_publisher(CameraInfo, "camera_info", qos_profile_sensor_data)
        self.create_service(SetCameraInfo, "set_camera_info", self._on_set_camera_info)
        self.create_timer(1.0 / float(p("rate")), self._tick)

    @staticmethod
    def _check(p) -> None:
        """Refuse bad parameters with a reason up front, not as a KeyError, a division by zero
        or (an unknown encoding) silently publishing 32FC1."""
        checks = [
            (p("camera") in stream.CAMERAS, f"camera must be one of {', '.join(stream.CAMERAS)}, "
                                            f"not {p('camera')!r}"),
            (p("rate") > 0, f"rate must be positive, not {p('rate')}"),
            (p("hold") >= 1, f"hold must be at least 1 frame, not {p('hold')}"),
            (p("depth.convention") in ("z", "radial"),
             f"depth.convention must be 'z' or 'radial', not {p('depth.convention')!r}"),
            (p("depth.encoding") in DEPTH_ENCODINGS,
             f"depth.encoding must be one of {', '.join(DEPTH_ENCODINGS)}, not {p('depth.encoding')!r}"),
        ]
        for ok, reason in checks:
            if not ok:
                raise CalibrationError(reason)

    def _factory_info(self) -> CameraInfo:
        return CameraInfo(**monocular_fields(stream.factory_K(self.camera), np.zeros(5), self.camera.size))

    def _tick(self) -> None:
        pose = self.poses[(self.frame // self.hold) % len(self.poses)]
        self.frame += 1
        frame = stream.frame(self.camera, self.board, pose, self.noise, self.rng, self.convention)
        stamp = self.get_clock().now().to_msg()
        self.amplitude_pub.publish(self._image(frame.amplitude.astype(np.uint16), "mono16", stamp))
        self.depth_pub.publish(self._image(stream.encoded_depth(frame.depth, self.encoding), self.encoding, stamp))
        self.info.header.stamp, self.info.header.frame_id = stamp, self.frame_id
        self.info_pub.publish(self.info)

    def _image(self, array: np.ndarray, encoding: str, stamp) -> Image:
        msg = Image(height=array.shape[0], width=array.shape[1], encoding=encoding, is_bigendian=0,
                    step=array.shape[1] * array.itemsize)
        msg.header.stamp, msg.header.frame_id = stamp, self.frame_id
        msg.data = array.tobytes()
        return msg

    def _on_set_camera_info(self, req: SetCameraInfo.Request,
                            resp: SetCameraInfo.Response) -> SetCameraInfo.Response:
        info = req.camera_info
        if (info.width, info.height) != (self.camera.width, self.camera.height) or len(info.k) != 9:
            resp.success = False
            resp.status_message = (f"refused: calibration is for {info.width}x{info.height}, the camera is "
                                   f"{self.camera.width}x{self.camera.height}")
            return resp
        self.info = info
        where = "kept in memory"
        if self.calibration_file:
            try:
                write_camera_yaml(self.calibration_file, {"K": np.reshape(info.k, (3, 3)), "D": np.asarray(info.d),
                                                          "image_size": (info.width, info.height)}, "tof_sim")
                where = f"stored to {self.calibration_file}"
            except CalibrationFileError as exc:
                resp.success, resp.status_message = False, f"could not store the calibration: {exc}"
                return resp
        resp.success = True
        resp.status_message = f"calibration {where}"
        self.get_logger().info(f"new camera_info: fx={info.k[0]:.2f} fy={info.k[4]:.2f}, {where}")
        return resp


def main(args: list[str] | None = None) -> int:
    return run("tof_sim_node", SimCameraNode, __doc__, PARAMETERS, args)


if __name__ == "__main__":
    raise SystemExit(main())
