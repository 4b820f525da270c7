"""A camera's frames as ROS 2 messages: ``sensor_msgs/Image`` and ``CameraInfo``.

For the twin's ROS node and its recording (real rclpy message types, imported when called, so
the rest of the camera package needs no ROS):

- :func:`colour_message`: ``rgb8``, ``step = 3 W``; :func:`depth_message`: ``32FC1``, metres
  along the optical axis, NaN where the sensor returned nothing (REP 118), ``step = 4 W``;
  both little-endian (``is_bigendian = 0``), stamped with the frame's exposure (sim clock) in the
  camera's optical frame;
- :func:`info_message`: the camera's ``CameraInfo`` (:func:`interfaces.camera.camera_info`:
  ``plumb_bob``, zero distortion, ``R = I``, ``P = [K | 0]``).

The topics are :mod:`interfaces.camera_topics`'s; the camera's frames go on ``/tf_static`` with
the scene's (:func:`twin.scene.camera_frames`).
"""

from __future__ import annotations

import array
import math
from typing import Any

import numpy as np

from interfaces.camera import RgbdCameraSpec, RgbdFrame, camera_info
from twin.camera.errors import RenderError

__all__ = [
    "colour_message",
    "depth_message",
    "info_message",
]


def _stamp(stamp_s: float) -> Any:
    from builtin_interfaces.msg import Time

    if not (math.isfinite(stamp_s) and stamp_s >= 0.0):
        msg = f"stamp_s = {stamp_s!r}: a frame's time must be finite and >= 0"
        raise RenderError(msg)
    nanoseconds = round(stamp_s * 1e9)
    return Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


def _image(frame: RgbdFrame, frame_id: str, data: np.ndarray, encoding: str) -> Any:
    from sensor_msgs.msg import Image

    msg = Image()
    msg.header.stamp = _stamp(frame.stamp_s)
    msg.header.frame_id = frame_id
    msg.height, msg.width = int(data.shape[0]), int(data.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = int(data.strides[0])
    msg.data = array.array("B", data.tobytes())  # bytes through the setter: 40x slower
    return msg


def colour_message(frame: RgbdFrame, spec: RgbdCameraSpec) -> Any:
    """``sensor_msgs/Image`` ``rgb8`` of ``frame``'s colour ``(H, W, 3) uint8``."""
    rgb = np.ascontiguousarray(frame.rgb, dtype=np.uint8)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        msg = f"frame {frame.camera}: rgb of shape {rgb.shape}, expected (H, W, 3)"
        raise RenderError(msg)
    return _image(frame, spec.optical_frame, rgb, "rgb8")


def depth_message(frame: RgbdFrame, spec: RgbdCameraSpec) -> Any:
    """``sensor_msgs/Image`` ``32FC1`` of ``frame``'s depth ``(H, W) float32`` (m, NaN: none)."""
    depth = np.ascontiguousarray(frame.depth_m, dtype="<f4")
    if depth.ndim != 2:
        msg = f"frame {frame.camera}: depth of shape {depth.shape}, expected (H, W)"
        raise RenderError(msg)
    return _image(frame, spec.optical_frame, depth, "32FC1")


def info_message(spec: RgbdCameraSpec, stamp_s: float) -> Any:
    """``sensor_msgs/CameraInfo`` of camera ``spec`` stamped ``stamp_s``."""
    from sensor_msgs.msg import CameraInfo

    fields = camera_info(spec)
    msg = CameraInfo()
    msg.header.stamp = _stamp(stamp_s)
    msg.header.frame_id = fields.frame_id
    msg.width, msg.height = fields.width, fields.height
    msg.distortion_model = fields.distortion_model
    msg.d = list(fields.d)
    msg.k = list(fields.k)
    msg.r = list(fields.r)
    msg.p = list(fields.p)
    return msg
