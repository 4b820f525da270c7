"""A frame's ROS messages survive rclpy's serialization: the pixels, the pinhole model and the
camera's frames come back as they went."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message

from interfaces.camera import RgbdCameraSpec, RgbdFrame, camera_info, project
from interfaces.camera_topics import camera_topics
from twin.camera.errors import RenderError
from twin.camera.ros_images import colour_message, depth_message, info_message
from twin.scene import camera_frames, tf_message_cdr

SPEC = RgbdCameraSpec(
    name="cam2",
    position_m=(-4.95, 0.5, 1.3),
    rpy_rad=(0.0, math.pi / 2, math.pi / 2),
    width_px=64,
    height_px=24,
    hfov_deg=87.0,
)


def frame() -> RgbdFrame:
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.3, 1.3, (24, 64)).astype(np.float32)
    depth[3, 5] = np.nan
    return RgbdFrame(
        camera="cam2",
        stamp_s=12.3456789,
        rgb=rng.integers(0, 256, (24, 64, 3), dtype=np.uint8),
        depth_m=depth,
        intrinsics=SPEC.intrinsics,
        worldMoptical=SPEC.worldMoptical(),
    )


def test_colour_and_depth_images_round_trip() -> None:
    from sensor_msgs.msg import Image

    f = frame()
    for msg, encoding in ((colour_message(f, SPEC), "rgb8"), (depth_message(f, SPEC), "32FC1")):
        back = deserialize_message(serialize_message(msg), Image)
        assert back.encoding == encoding
        assert back.header.frame_id == "cam2_optical_frame"
        assert (back.header.stamp.sec, back.header.stamp.nanosec) == (12, 345678900)
        assert (back.height, back.width) == (24, 64)
        data = np.frombuffer(bytes(back.data), dtype=np.uint8)
        if encoding == "rgb8":
            assert back.step == 64 * 3
            assert np.array_equal(data.reshape(24, 64, 3), f.rgb)
        else:
            assert back.step == 64 * 4
            assert back.is_bigendian == 0
            depth = data.view("<f4").reshape(24, 64)
            assert np.array_equal(np.isnan(depth), np.isnan(f.depth_m))
            assert np.array_equal(depth[~np.isnan(depth)], f.depth_m[~np.isnan(f.depth_m)])


def test_camera_info_projects_as_the_camera_does() -> None:
    from sensor_msgs.msg import CameraInfo

    back = deserialize_message(serialize_message(info_message(SPEC, 1.5)), CameraInfo)
    assert back.distortion_model == "plumb_bob"
    assert back.header.frame_id == camera_info(SPEC).frame_id
    p = np.array(back.p).reshape(3, 4)
    point = np.array([-4.7, 0.6, 0.04])
    opticalMworld = np.linalg.inv(SPEC.worldMoptical())  # noqa: N806
    local = np.append(opticalMworld[:3, :3] @ point + opticalMworld[:3, 3], 1.0)
    uvw = p @ local
    uv, _ = project(point[None], SPEC.intrinsics, SPEC.worldMoptical())
    assert np.allclose(uvw[:2] / uvw[2], uv[0])


def test_the_cameras_static_frames_round_trip_in_a_tf_message() -> None:
    from tf2_msgs.msg import TFMessage

    back = deserialize_message(tf_message_cdr(camera_frames([SPEC]), 0, 0), TFMessage)
    names = [(t.header.frame_id, t.child_frame_id) for t in back.transforms]
    assert names == [("world", "cam2_link"), ("cam2_link", "cam2_optical_frame")]
    link = back.transforms[0].transform
    assert (link.translation.x, link.translation.y, link.translation.z) == (-4.95, 0.5, 1.3)


def test_topics_and_bad_frames() -> None:
    assert camera_topics("cam2").colour.name == "/camera/cam2/color/image_raw"
    assert camera_topics("cam2").depth.name == "/camera/cam2/depth/image_raw"
    assert camera_topics("cam2").info.name == "/camera/cam2/color/camera_info"
    f = frame()
    bad = RgbdFrame(
        camera="cam2",
        stamp_s=-1.0,
        rgb=f.rgb,
        depth_m=f.depth_m,
        intrinsics=f.intrinsics,
        worldMoptical=f.worldMoptical,
    )
    with pytest.raises(RenderError, match=r"stamp_s = -1\.0"):
        colour_message(bad, SPEC)
