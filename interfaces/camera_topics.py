"""The topics of a cell's RGB-D cameras: names, message types and QoS, defined once.

The twin publishes every camera ``NAME`` of the cell (:class:`interfaces.camera.RgbdCameraSpec`)
on three topics, and the detector node (``cdw-twin detector-node``) subscribes to them:

- ``/camera/NAME/color/image_raw``: ``sensor_msgs/Image``, ``rgb8``;
- ``/camera/NAME/depth/image_raw``: ``sensor_msgs/Image``, ``32FC1`` metres along the optical
  axis, NaN where the sensor returned nothing (REP 118; ``16UC1`` millimetres, 0 for none, is
  read too), registered to the colour image (same size, same pinhole model), with the colour
  image's stamp;
- ``/camera/NAME/color/camera_info``: ``sensor_msgs/CameraInfo`` (``plumb_bob``), with each
  frame.

Every message is stamped with the frame's exposure time (sim clock in the twin) in the camera's
optical frame ``NAME_optical_frame``. QoS: :data:`IMAGES`, reliable, volatile, keep last 2.
Measured on the 2-core test machine (Fast DDS, localhost, 640x480: 0.9 MB colour, 1.2 MB
depth): best effort (ROS's ``sensor_data`` profile) lost 4 of the 6 first frames sent to the
detector node (each was sent three times, 5 s apart), reliable delivered every frame; keep
last 2 bounds the queue, so a slow subscriber gets the newest frames, not a backlog. A publisher
must be reliable too (a reliable subscriber does not match a best-effort publisher). Nothing
here imports ROS.
"""

from __future__ import annotations

from dataclasses import dataclass

from interfaces.contract import Qos, Topic
from interfaces.errors import ConfigError

__all__ = [
    "CAMERA_INFO_TYPE",
    "IMAGES",
    "IMAGE_TYPE",
    "CameraTopics",
    "camera_topics",
]

IMAGES = Qos(depth=2)
"""QoS of the image and camera-info topics: reliable, volatile, keep last 2 (see the module)."""

IMAGE_TYPE = "sensor_msgs/msg/Image"
"""The message type of the colour and depth topics."""

CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
"""The message type of the camera-info topic."""


@dataclass(frozen=True, kw_only=True)
class CameraTopics:
    """The three topics of one camera (see the module)."""

    colour: Topic
    depth: Topic
    info: Topic

    @property
    def all(self) -> tuple[Topic, Topic, Topic]:
        """Colour, depth and camera info, in that order."""
        return (self.colour, self.depth, self.info)


def camera_topics(name: str) -> CameraTopics:
    """The topics of camera ``name`` (a frame name: letters, digits, underscores)."""
    if not name or not name.replace("_", "").isalnum():
        msg = f"camera name {name!r}: must be letters, digits and underscores"
        raise ConfigError(msg)
    base = f"/camera/{name}"
    return CameraTopics(
        colour=Topic(name=f"{base}/color/image_raw", msgtype=IMAGE_TYPE, qos=IMAGES),
        depth=Topic(name=f"{base}/depth/image_raw", msgtype=IMAGE_TYPE, qos=IMAGES),
        info=Topic(name=f"{base}/color/camera_info", msgtype=CAMERA_INFO_TYPE, qos=IMAGES),
    )
