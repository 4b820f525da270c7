"""The cell's camera over ROS 2, as a stranger takes it: a plain rclpy client that knows only
``docs/interfaces.md`` subscribes to the camera's images, its ``CameraInfo`` and ``/tf_static``
of a twin node in another process, and checks them against each other and the cell file."""

from __future__ import annotations

import math
import os
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from process_helpers import finish, start_twin_node

from interfaces.camera import camera_info
from interfaces.cell import load_cell

CELL = load_cell("default")
CAMERA = CELL.cameras[0]
BASE = f"/camera/{CAMERA.name}"


def _rotate(q: Any, v: tuple[float, float, float]) -> np.ndarray:
    """``v`` rotated by the unit quaternion ``q`` (a ``geometry_msgs/Quaternion``)."""
    x, y, z, w = q.x, q.y, q.z, q.w
    rot = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    return rot @ np.asarray(v)


def _take(env: dict[str, str], twin: subprocess.Popen[bytes]) -> dict[str, list[Any]]:
    """Every message of the camera's topics and ``/tf_static`` until ``twin`` ends."""
    import rclpy
    from rclpy.experimental.events_executor import EventsExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, Image
    from tf2_msgs.msg import TFMessage

    images = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE)
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    got: dict[str, list[Any]] = {}
    saved = dict(os.environ)
    os.environ.update(env)
    rclpy.init()
    try:
        node = rclpy.create_node("camera_client")
        executor = EventsExecutor()
        executor.add_node(node)
        for topic, kind, qos in (
            (f"{BASE}/color/image_raw", Image, images),
            (f"{BASE}/depth/image_raw", Image, images),
            (f"{BASE}/color/camera_info", CameraInfo, images),
            ("/tf_static", TFMessage, latched),
        ):
            got[topic] = []
            node.create_subscription(kind, topic, got[topic].append, qos)
        end = time.monotonic() + 60.0
        while twin.poll() is None and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
    finally:
        rclpy.shutdown()
        os.environ.clear()
        os.environ.update(saved)
    return got


@pytest.mark.usefixtures("require_interfaces")
def test_a_stranger_sees_the_camera_images_info_and_frames(
    ros_env: dict[str, str], builtin_meshes: Path, tmp_path: Path
) -> None:
    duration_s = 3.0
    twin = start_twin_node(
        ros_env,
        [
            *("--dataset", str(builtin_meshes), "--out", str(tmp_path / "run")),
            *("--duration", str(duration_s), "--speed", "0.4", "--prefill", "1.5"),
        ],
    )
    got = _take(ros_env, twin)
    assert finish(twin, 60.0) == 0
    colour = got[f"{BASE}/color/image_raw"]
    depth = got[f"{BASE}/depth/image_raw"]
    info = got[f"{BASE}/color/camera_info"]
    print(f"received {len(colour)} colour, {len(depth)} depth, {len(info)} info")
    assert len(colour) >= 10, f"{len(colour)} colour frames in {duration_s} s at 15 Hz"
    assert len(depth) >= 10
    assert len(info) >= 10
    expected = camera_info(CAMERA)
    for msg in info:
        assert (msg.width, msg.height) == (CAMERA.width_px, CAMERA.height_px)
        assert msg.distortion_model == "plumb_bob"
        assert np.allclose(msg.k, expected.k)
        assert msg.header.frame_id == f"{CAMERA.name}_optical_frame"
    for msg in colour:
        assert (msg.encoding, msg.step) == ("rgb8", 3 * msg.width)
        assert (msg.width, msg.height) == (CAMERA.width_px, CAMERA.height_px)
        assert msg.header.frame_id == f"{CAMERA.name}_optical_frame"
    for msg in depth:
        assert (msg.encoding, msg.step, msg.is_bigendian) == ("32FC1", 4 * msg.width, 0)
    # stamps: sim time of the exposure, the same on a frame's three messages
    stamps = {m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in colour}
    assert all(0.0 <= s <= duration_s for s in stamps)
    depth_by_stamp = {m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec: m for m in depth}
    info_stamps = {m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in info}
    assert stamps & set(depth_by_stamp) & info_stamps

    # /tf_static: NAME_link in world, NAME_optical_frame in NAME_link, z forward (down here)
    transforms = {
        (t.header.frame_id, t.child_frame_id): t.transform
        for msg in got["/tf_static"]
        for t in msg.transforms
    }
    link = transforms[("world", f"{CAMERA.name}_link")]
    optical = transforms[(f"{CAMERA.name}_link", f"{CAMERA.name}_optical_frame")]
    height_m = link.translation.z - CELL.belt.surface_z_m
    forward = _rotate(link.rotation, tuple(_rotate(optical.rotation, (0.0, 0.0, 1.0))))
    assert forward[2] < -0.9, f"the optical z axis points {forward} in world: not down"

    # depth in metres along the optical axis: the belt under the image centre lies about the
    # camera's height over it away, corrected for the axis' tilt
    frame = depth_by_stamp[min(depth_by_stamp)]
    image = np.frombuffer(bytes(frame.data), dtype="<f4").reshape(frame.height, frame.width)
    h, w = image.shape
    centre = image[h // 2 - 20 : h // 2 + 20, w // 2 - 20 : w // 2 + 20]
    belt_m = float(np.nanmax(centre))
    expected_m = height_m / -forward[2]
    assert math.isclose(belt_m, expected_m, abs_tol=0.03), (belt_m, expected_m)
    finite = image[np.isfinite(image)]
    assert finite.size > 0.5 * image.size
    assert finite.min() >= CAMERA.depth_min_m - 1e-6
    assert finite.max() <= CAMERA.depth_max_m + 1e-6
