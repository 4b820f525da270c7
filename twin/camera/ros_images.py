"""A camera's frames as ROS 2 messages: ``sensor_msgs/Image``, ``CameraInfo`` and ``/tf_static``.

For the twin's ROS node and its recording (real rclpy message types, imported when called, so
the rest of the camera package needs no ROS):

- :func:`colour_message`: ``rgb8``, ``step = 3 W``; :func:`depth_message`: ``32FC1``, metres
  along the optical axis, NaN where the sensor returned nothing (REP 118), ``step = 4 W``;
  both little-endian (``is_bigendian = 0``), stamped with the frame's exposure (sim clock) in the
  camera's optical frame;
- :func:`info_message`: the camera's ``CameraInfo`` (:func:`interfaces.camera.camera_info`:
  ``plumb_bob``, zero distortion, ``R = I``, ``P = [K | 0]``);
- :func:`static_transforms`: ``NAME_link`` in ``world`` and ``NAME_optical_frame`` in
  ``NAME_link`` (:func:`interfaces.camera.static_frames`), one ``TransformStamped`` each, for a
  ``tf2_msgs/TFMessage`` on ``/tf_static``;
- :func:`topics`: the topic names of camera ``NAME``: ``/camera/NAME/color/image_raw``,
  ``/camera/NAME/depth/image_raw``, ``/camera/NAME/color/camera_info`` (colour and depth share
  one pinhole model: the depth is registered to the colour image).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from interfaces.camera import RgbdCameraSpec, RgbdFrame, camera_info, static_frames
from twin.camera.errors import RenderError

__all__ = [
    "CameraTopics",
    "colour_message",
    "depth_message",
    "info_message",
    "static_transforms",
    "topics",
]


@dataclass(frozen=True, kw_only=True)
class CameraTopics:
    """The topics of one camera (see the module)."""

    colour: str
    depth: str
    info: str


def topics(name: str) -> CameraTopics:
    """The topic names of camera ``name``."""
    base = f"/camera/{name}"
    return CameraTopics(
        colour=f"{base}/color/image_raw",
        depth=f"{base}/depth/image_raw",
        info=f"{base}/color/camera_info",
    )


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
    msg.data = data.tobytes()
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


def static_transforms(spec: RgbdCameraSpec, stamp_s: float = 0.0) -> list[Any]:
    """``geometry_msgs/TransformStamped`` of the camera's two static frames."""
    from geometry_msgs.msg import TransformStamped

    out = []
    for frame in static_frames(spec):
        t = TransformStamped()
        t.header.stamp = _stamp(stamp_s)
        t.header.frame_id = frame.parent
        t.child_frame_id = frame.child
        tx, ty, tz = frame.translation_m
        t.transform.translation.x, t.transform.translation.y = tx, ty
        t.transform.translation.z = tz
        qx, qy, qz, qw = frame.rotation_xyzw
        t.transform.rotation.x, t.transform.rotation.y = qx, qy
        t.transform.rotation.z, t.transform.rotation.w = qz, qw
        out.append(t)
    return out
