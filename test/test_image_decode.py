"""Decoding sensor_msgs/Image without cv_bridge, from rclpy messages and plain field holders."""
from __future__ import annotations

import array
from types import SimpleNamespace

import numpy as np
import pytest

from tof_calib_ros.core.errors import CalibrationError
from tof_calib_ros.files.image_decode import ENCODINGS, ImageError, decode_image, depth_to_metres

try:
    from sensor_msgs.msg import Image
except ImportError:   # the ROS-free install; only the rclpy cases need it
    Image = None


def _pixels(encoding: str, h: int = 3, w: int = 4) -> np.ndarray:
    rng = np.random.default_rng(0)
    dtype = ENCODINGS[encoding]
    if dtype.kind == "f":
        return rng.normal(1.0, 0.5, (h, w)).astype(dtype)
    return rng.integers(0, np.iinfo(dtype).max, (h, w), endpoint=True).astype(dtype)


def _fields(image: np.ndarray, encoding: str, padding: int, bigendian: bool) -> dict:
    h, w = image.shape
    order = ">" if bigendian else "<"
    rows = image.astype(image.dtype.newbyteorder(order)).view(np.uint8).reshape(h, -1)
    padded = np.full((h, rows.shape[1] + padding), 0xAB, dtype=np.uint8)   # junk in the padding
    padded[:, :rows.shape[1]] = rows
    return {"encoding": encoding, "height": h, "width": w, "step": padded.shape[1],
            "is_bigendian": int(bigendian), "data": padded.tobytes()}


def _rclpy(fields: dict):
    if Image is None:
        pytest.skip("sensor_msgs (ROS 2) is not installed")
    msg = Image()
    for name, value in fields.items():
        setattr(msg, name, value)
    return msg


@pytest.mark.parametrize("encoding", list(ENCODINGS))
@pytest.mark.parametrize("padding", [0, 3])
@pytest.mark.parametrize("bigendian", [False, True])
@pytest.mark.parametrize("make", ["rclpy", "namespace_bytes", "namespace_numpy", "namespace_list"])
def test_round_trip(encoding: str, padding: int, bigendian: bool, make: str) -> None:
    image = _pixels(encoding)
    fields = _fields(image, encoding, padding, bigendian)
    if make == "rclpy":
        msg = _rclpy(fields)
        assert isinstance(msg.data, array.array)   # what rclpy hands a subscriber
    else:
        data = fields["data"]
        fields["data"] = {"namespace_bytes": data, "namespace_numpy": np.frombuffer(data, np.uint8),
                          "namespace_list": list(data)}[make]
        msg = SimpleNamespace(**fields)
    out = decode_image(msg)
    assert out.shape == image.shape and out.dtype == ENCODINGS[encoding] and out.dtype.isnative
    np.testing.assert_array_equal(out, image)


@pytest.mark.parametrize("data", [bytearray(24), array.array("B", bytes(24)), memoryview(bytes(24)),
                                  np.zeros(24, np.uint8)[::-1], np.zeros((2, 12), np.int8)])
def test_bytes_like_data(data) -> None:
    msg = SimpleNamespace(encoding="16UC1", height=2, width=6, step=12, is_bigendian=False, data=data)
    np.testing.assert_array_equal(decode_image(msg), np.zeros((2, 6), np.uint16))


def test_returns_a_copy_not_a_view() -> None:
    buffer = np.arange(12, dtype=np.uint8)   # rosbags hands out numpy arrays like this
    msg = SimpleNamespace(encoding="mono8", height=3, width=4, step=4, is_bigendian=0, data=buffer)
    out = decode_image(msg)
    assert not np.shares_memory(out, buffer)
    buffer[:] = 0
    np.testing.assert_array_equal(out.ravel(), np.arange(12))


def _msg(**overrides) -> SimpleNamespace:
    fields = {"encoding": "16UC1", "height": 2, "width": 3, "step": 6, "is_bigendian": 0, "data": bytes(12)}
    fields.update(overrides)
    return SimpleNamespace(**fields)


@pytest.mark.parametrize("overrides, message", [
    ({"encoding": "bgr8"}, "unsupported image encoding 'bgr8'; supported: mono8, 8UC1, mono16, 16UC1, 32FC1"),
    ({"encoding": None}, "unsupported image encoding None"),
    ({"height": 0, "data": b""}, "image is empty (3x0)"),
    ({"width": 0, "step": 0, "data": b""}, "image is empty (0x2)"),
    ({"step": 5, "data": bytes(10)}, "image step 5 is less than width x bytes per pixel = 6 (16UC1)"),
    ({"data": bytes(11)}, "image data has 11 bytes but step x height = 6 x 2 = 12"),
    ({"data": bytes(13)}, "image data has 13 bytes but step x height = 6 x 2 = 12"),
    ({"height": 2.0}, "image height must be an integer, got 2.0"),
    ({"width": "3"}, "image width must be an integer, got '3'"),
    ({"step": None}, "image step must be an integer, got None"),
    ({"height": True}, "image height must be an integer, got True"),
    ({"width": -3}, "image width must not be negative, got -3"),
    ({"is_bigendian": 2}, "image is_bigendian must be 0 or 1, got 2"),
    ({"is_bigendian": "1"}, "image is_bigendian must be 0 or 1, got '1'"),
    ({"data": None}, "image data must be bytes-like, got NoneType"),
    ({"data": "abcdefghijkl"}, "image data must be bytes-like, got str"),
    ({"data": np.zeros(6, np.uint16)}, "image data must be bytes, got a numpy array of uint16"),
    ({"data": array.array("H", [0] * 6)}, "image data must be bytes, got items of 2 bytes"),
    ({"data": [0] * 11 + [256]}, "image data given as a list must hold integers 0..255"),
    ({"data": [0.0] * 12}, "image data given as a list must hold integers 0..255"),
])
def test_errors(overrides: dict, message: str) -> None:
    with pytest.raises(ImageError) as info:
        decode_image(_msg(**overrides))
    assert str(info.value).startswith(message)
    assert "\n" not in str(info.value)


def test_missing_field_and_error_type() -> None:
    with pytest.raises(ImageError, match="not an image message: it has no 'data' field"):
        decode_image(SimpleNamespace(encoding="mono8", height=1, width=1, step=1, is_bigendian=0))
    assert issubclass(ImageError, CalibrationError) and issubclass(ImageError, ValueError)


def test_depth_16uc1_millimetres_and_scale() -> None:
    image = np.array([[0, 1, 1500, 65535]], dtype=np.uint16)
    metres = depth_to_metres(image, "16UC1")
    assert metres.dtype == np.float64
    # 0 is invalid, and so is 65535 mm: beyond any ToF camera's range (MAX_DEPTH_M), a driver's sentinel
    np.testing.assert_array_equal(np.isnan(metres), [[True, False, False, True]])
    np.testing.assert_allclose(metres[0, 1:3], [0.001, 1.5])
    np.testing.assert_allclose(depth_to_metres(image, "16UC1", scale_16u=0.0001)[0, 1:], [0.0001, 0.15, 6.5535])


def test_depth_32fc1_invalid_values_become_nan() -> None:
    image = np.array([[0.0, np.nan, -0.5, np.inf, -np.inf, 0.75]], dtype=np.float32)
    metres = depth_to_metres(image, "32FC1")
    assert metres.dtype == np.float64
    np.testing.assert_array_equal(np.isnan(metres), [[True] * 5 + [False]])
    assert metres[0, 5] == 0.75


def test_depth_from_a_message() -> None:
    mm = np.array([[0, 800], [1200, 4000]], dtype=np.uint16)
    msg = _rclpy(_fields(mm, "16UC1", padding=2, bigendian=True))
    np.testing.assert_allclose(depth_to_metres(decode_image(msg), msg.encoding), [[np.nan, 0.8], [1.2, 4.0]])


@pytest.mark.parametrize("image, encoding, kwargs, message", [
    (np.zeros((2, 2), np.uint8), "mono8", {}, "'mono8' is not a depth encoding; depth must be one of 16UC1, 32FC1"),
    (np.zeros((2, 2), np.uint16), "mono16", {}, "'mono16' is not a depth encoding"),
    (np.zeros((2, 2), np.float32), "16UC1", {}, "16UC1 depth must be a uint16 array, got float32"),
    (np.zeros((2, 2), np.float64), "32FC1", {}, "32FC1 depth must be a float32 array, got float64"),
    (np.zeros((2, 2), np.uint16), "16UC1", {"scale_16u": 0.0}, "scale_16u must be a positive number"),
    (np.zeros((2, 2), np.uint16), "16UC1", {"scale_16u": float("nan")}, "scale_16u must be a positive number"),
    (np.zeros((2, 2), np.uint16), "16UC1", {"scale_16u": "0.001"}, "scale_16u must be a positive number"),
])
def test_depth_errors(image, encoding, kwargs, message) -> None:
    with pytest.raises(ImageError) as info:
        depth_to_metres(image, encoding, **kwargs)
    assert str(info.value).startswith(message)
