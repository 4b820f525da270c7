"""A camera's CameraInfo fields and static frames agree with its pinhole model and pose, and
what it sees of the belt is where its projection says."""

from __future__ import annotations

import math

import numpy as np

from interfaces.camera import (
    RgbdCameraSpec,
    belt_view_x_m,
    camera_info,
    project,
    sees_point,
    static_frames,
)
from interfaces.cell import load_cell

SPEC = RgbdCameraSpec(
    name="cam1",
    position_m=(-0.7, 0.5, 1.3),
    rpy_rad=(0.0, math.pi / 2, math.pi / 2),
    width_px=640,
    height_px=224,
    hfov_deg=87.0,
)


def quat_matrix(q: tuple[float, float, float, float]) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_camera_info_is_the_plumb_bob_model_of_the_spec() -> None:
    info = camera_info(SPEC)
    k = np.array(info.k).reshape(3, 3)
    p = np.array(info.p).reshape(3, 4)
    assert info.frame_id == "cam1_optical_frame"
    assert (info.width, info.height) == (640, 224)
    assert info.distortion_model == "plumb_bob"
    assert info.d == (0.0,) * 5
    assert np.allclose(np.array(info.r).reshape(3, 3), np.eye(3))
    assert np.allclose(p[:, :3], k)
    assert np.allclose(p[:, 3], 0.0)
    # K projects a world point where the camera's own projection puts it
    point = np.array([[-0.4, 0.62, 0.05]])
    uv, z = project(point, SPEC.intrinsics, SPEC.worldMoptical())
    opticalMworld = np.linalg.inv(SPEC.worldMoptical())  # noqa: N806
    local = opticalMworld[:3, :3] @ point[0] + opticalMworld[:3, 3]
    homogeneous = k @ local
    assert np.allclose(homogeneous[:2] / homogeneous[2], uv[0], atol=1e-9)
    assert math.isclose(local[2], z[0])


def test_static_frames_chain_to_the_optical_pose_rep_103() -> None:
    link, optical = static_frames(SPEC)
    assert (link.parent, link.child) == ("world", "cam1_link")
    assert (optical.parent, optical.child) == ("cam1_link", "cam1_optical_frame")
    worldMlink = np.eye(4)  # noqa: N806
    worldMlink[:3, :3] = quat_matrix(link.rotation_xyzw)
    worldMlink[:3, 3] = link.translation_m
    linkMoptical = np.eye(4)  # noqa: N806
    linkMoptical[:3, :3] = quat_matrix(optical.rotation_xyzw)
    assert np.allclose(worldMlink @ linkMoptical, SPEC.worldMoptical(), atol=1e-12)
    # looking straight down: the optical z axis points to -z in the world, the link's x too
    assert np.allclose(SPEC.worldMoptical()[:3, 2], (0.0, 0.0, -1.0), atol=1e-12)
    assert np.allclose(worldMlink[:3, 0], (0.0, 0.0, -1.0), atol=1e-12)
    for q in (link.rotation_xyzw, optical.rotation_xyzw):
        assert math.isclose(float(np.linalg.norm(q)), 1.0)


def test_the_belt_a_camera_sees_is_its_footprint() -> None:
    seen = belt_view_x_m(SPEC, centre_y_m=0.5, surface_z_m=0.0)
    assert seen is not None
    half = 1.3 * math.tan(math.radians(43.5))  # 87 degrees across, 1.3 m up
    assert math.isclose(seen[0], -0.7 - half, abs_tol=0.011)
    assert math.isclose(seen[1], -0.7 + half, abs_tol=0.011)
    assert sees_point(SPEC, (-0.7, 0.5, 0.0))
    assert not sees_point(SPEC, (-0.7, 1.5, 0.0))  # beyond the 0.86 m across
    assert not sees_point(SPEC, (-0.7, 0.5, 1.2))  # nearer than depth_min_m
    away = RgbdCameraSpec(position_m=(0.0, 0.5, 1.3), rpy_rad=(0.0, -math.pi / 2, 0.0))
    assert belt_view_x_m(away, centre_y_m=0.5, surface_z_m=0.0) is None


def test_every_shipped_camera_sees_the_belt_upstream_of_the_first_window() -> None:
    for name in ("default", "line", "two_pandas", "suction", "suction_ur10", "wide_gripper"):
        cell = load_cell(name)
        assert cell.cameras, name
        first = min(s.pick_window_x_m[0] for s in cell.stations)
        views = [
            belt_view_x_m(c, centre_y_m=cell.belt.centre_y_m, surface_z_m=0.0) for c in cell.cameras
        ]
        assert all(v is not None for v in views)
        lo = min(v[0] for v in views if v is not None)
        hi = max(v[1] for v in views if v is not None)
        assert lo < first - 0.1, name
        # every pick window is seen whole: the tracker's tracks live only while seen
        assert hi >= max(s.pick_window_x_m[1] for s in cell.stations), name
