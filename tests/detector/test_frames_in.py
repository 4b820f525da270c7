"""The detector node's pure logic: image messages decoded, colour and depth paired by stamp,
camera info read, detections turned into message fields; the camera topics' names."""

from __future__ import annotations

import array
import math

import numpy as np
import pytest

from detector.errors import FrameError
from detector.frames_in import FramePairer, detection_values, image_array, intrinsics_from_info
from interfaces.camera import RgbdCameraSpec, camera_info
from interfaces.camera_topics import IMAGES, camera_topics
from interfaces.detections import Detection
from interfaces.errors import ConfigError


def test_colour_and_depth_images_decode_with_padding_and_byte_order() -> None:
    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    padded = np.zeros((2, 12), dtype=np.uint8)  # step 12 > 9 bytes of pixels a row
    padded[:, :9] = rgb.reshape(2, 9)
    out = image_array(
        encoding="rgb8",
        height=2,
        width=3,
        step=12,
        is_bigendian=0,
        data=array.array("B", padded.tobytes()),
        where="/camera/c/color/image_raw",
    )
    np.testing.assert_array_equal(out, rgb)
    bgr = image_array(
        encoding="bgr8", height=2, width=3, step=9, is_bigendian=0, data=rgb.tobytes(), where="t"
    )
    np.testing.assert_array_equal(bgr, rgb[..., ::-1])
    depth = np.array([[0.5, np.nan], [1.25, 3.0]], dtype=np.float32)
    for order, flag in (("<f4", 0), (">f4", 1)):
        back = image_array(
            encoding="32FC1",
            height=2,
            width=2,
            step=8,
            is_bigendian=flag,
            data=depth.astype(order).tobytes(),
            where="t",
        )
        np.testing.assert_array_equal(back, depth)
        assert back.dtype == np.float32
    millimetres = np.array([[0, 1500]], dtype="<u2").tobytes()
    metres = image_array(
        encoding="16UC1", height=1, width=2, step=4, is_bigendian=0, data=millimetres, where="t"
    )
    assert math.isnan(metres[0, 0])
    assert metres[0, 1] == pytest.approx(1.5)


def test_a_malformed_image_names_its_topic_and_field() -> None:
    topic = "/camera/top/color/image_raw"
    with pytest.raises(FrameError, match=r"/camera/top/color/image_raw: encoding = 'mono8'"):
        image_array(
            encoding="mono8", height=1, width=1, step=1, is_bigendian=0, data=b"\0", where=topic
        )
    with pytest.raises(FrameError, match=r"step = 5: a rgb8 row needs at least 6 bytes"):
        image_array(
            encoding="rgb8", height=1, width=2, step=5, is_bigendian=0, data=b"\0" * 6, where=topic
        )
    with pytest.raises(FrameError, match="data holds 5 bytes, step \\* height = 12"):
        image_array(
            encoding="rgb8", height=2, width=2, step=6, is_bigendian=0, data=b"\0" * 5, where=topic
        )


def test_camera_info_gives_the_pinhole_model() -> None:
    spec = RgbdCameraSpec(width_px=320, height_px=240, hfov_deg=70.0)
    info = camera_info(spec)
    k = intrinsics_from_info(width=info.width, height=info.height, k=info.k, where="info")
    assert k == spec.intrinsics
    with pytest.raises(FrameError, match="info: k has 4 values"):
        intrinsics_from_info(width=2, height=2, k=[1.0] * 4, where="info")
    with pytest.raises(FrameError, match="info: width_px"):
        intrinsics_from_info(width=0, height=2, k=info.k, where="info")


def test_colour_and_depth_pair_by_stamp_whichever_comes_first() -> None:
    pairer = FramePairer(max_pending=2)
    rgb = np.zeros((4, 5, 3), dtype=np.uint8)
    depth = np.ones((4, 5), dtype=np.float32)
    assert pairer.add_colour(100, rgb) is None
    assert pairer.add_depth(200, depth) is None
    pair = pairer.add_depth(100, depth * 2)
    assert pair is not None
    assert pair.stamp_ns == 100
    assert pair.depth_m is not None
    assert float(pair.depth_m[0, 0]) == 2.0
    second = pairer.add_colour(200, rgb)
    assert second is not None
    assert second.stamp_ns == 200
    # an image whose partner never comes is dropped once a newer pair completes
    assert pairer.add_colour(300, rgb) is None
    assert pairer.add_colour(400, rgb) is None
    assert pairer.add_depth(400, depth) is not None
    assert pairer.dropped == 1
    pairer.add_colour(500, rgb)
    with pytest.raises(FrameError, match="must be registered"):
        pairer.add_depth(500, np.ones((2, 2), dtype=np.float32))
    colour_only = FramePairer(with_depth=False)
    alone = colour_only.add_colour(7, rgb)
    assert alone is not None
    assert alone.depth_m is None


def test_detection_fields_keep_nan_for_no_suction_point() -> None:
    det = Detection(
        class_name="brick",
        confidence=0.8,
        x_m=1.0,
        y_m=2.0,
        z_m=0.1,
        yaw_rad=0.3,
        length_m=0.2,
        width_m=0.1,
        height_m=0.05,
    )
    values = detection_values(det)
    assert values.position_m == (1.0, 2.0, 0.1)
    assert (values.length_m, values.width_m, values.height_m) == (0.2, 0.1, 0.05)
    assert math.isnan(values.suction_radius_m)


def test_camera_topics_are_the_documented_names() -> None:
    topics = camera_topics("zone_1")
    assert topics.colour.name == "/camera/zone_1/color/image_raw"
    assert topics.depth.name == "/camera/zone_1/depth/image_raw"
    assert topics.info.name == "/camera/zone_1/color/camera_info"
    assert topics.colour.msgtype == "sensor_msgs/msg/Image"
    assert topics.info.msgtype == "sensor_msgs/msg/CameraInfo"
    assert all(t.qos == IMAGES for t in topics.all)
    with pytest.raises(ConfigError, match="camera name 'a/b'"):
        camera_topics("a/b")
