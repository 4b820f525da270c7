"""The top view: what a camera above sees of upright and tipped-over objects."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from twin.top_view import TopView, top_view

L, W, H = 0.16, 0.054, 0.03  # a wooden stick (throughput seed 2, object 34)


def _quat(rotation: Rotation) -> tuple[float, float, float, float]:
    x, y, z, w = rotation.as_quat()  # scipy's order is x, y, z, w
    return (float(x), float(y), float(z), float(w))


def _prism(footprint: list[tuple[float, float]], height: float) -> np.ndarray:
    """Vertices of a prism over ``footprint``, centred on its centre of mass (as meshgen's)."""
    ring = np.array(footprint, dtype=float)
    x, y = ring[:, 0], ring[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    centroid = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6 * area)
    flat = ring - centroid
    bottom = np.column_stack((flat, np.full(len(flat), -0.5 * height)))
    top = np.column_stack((flat, np.full(len(flat), 0.5 * height)))
    return np.vstack((bottom, top))


def _box(length: float, width: float, height: float, yaw: float = 0.0) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    corners = [(sx * length / 2, sy * width / 2) for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    return _prism([(c * a - s * b, s * a + c * b) for a, b in corners], height)


def _view(rotation: Rotation, yaw: float, length: float, width: float, height: float) -> TopView:
    return top_view(
        _quat(rotation),
        yaw,
        length_m=length,
        width_m=width,
        height_m=height,
        vertices_m=lambda: _box(length, width, height, yaw),
    )


def _same_axis(a_rad: float, b_rad: float) -> bool:
    """Headings of an axis (no direction) agree modulo pi."""
    d = (a_rad - b_rad) % math.pi
    return min(d, math.pi - d) < 1e-9


@pytest.mark.parametrize("turn_rad", [0.0, 0.4, -2.0, 3.1])
@pytest.mark.parametrize("footprint_yaw_rad", [0.0, 0.7, -1.3])
def test_an_upright_object_shows_its_footprint_at_its_yaw(
    turn_rad: float, footprint_yaw_rad: float
) -> None:
    seen = _view(Rotation.from_euler("z", turn_rad), footprint_yaw_rad, L, W, H)
    assert _same_axis(seen.yaw_rad, turn_rad + footprint_yaw_rad)
    assert (seen.length_m, seen.width_m, seen.height_m) == pytest.approx((L, W, H), abs=1e-12)
    assert seen.below_m == pytest.approx(H / 2)


@pytest.mark.parametrize("roll_rad", [math.pi / 2, -math.pi / 2, 1.45, 1.8, math.pi])
def test_a_stick_rolled_about_its_long_axis_keeps_its_heading(roll_rad: float) -> None:
    # body long axis at 0.5 rad; the object is turned by 1.0 rad on the belt and rolled about
    # that long axis: the camera sees the same heading whatever the roll (Euler yaw does not)
    footprint_yaw = 0.5
    long_axis = np.array([math.cos(footprint_yaw), math.sin(footprint_yaw), 0.0])
    rotation = Rotation.from_euler("z", 1.0) * Rotation.from_rotvec(roll_rad * long_axis)
    seen = _view(rotation, footprint_yaw, L, W, H)
    assert _same_axis(seen.yaw_rad, 1.5)
    assert seen.length_m == pytest.approx(L, abs=1e-12)
    c, s = abs(math.cos(roll_rad)), abs(math.sin(roll_rad))
    assert seen.width_m == pytest.approx(W * c + H * s, abs=1e-12)
    assert seen.height_m == pytest.approx(W * s + H * c, abs=1e-12)
    assert seen.below_m == pytest.approx(seen.height_m / 2, abs=1e-12)


def test_an_object_on_its_end_shows_its_width_and_height() -> None:
    # a brick 8 x 5 x 4 cm stood on its end: the 8 cm edge is vertical, the 5 x 4 face is seen
    seen = _view(Rotation.from_euler("y", 90, degrees=True), 0.0, 0.08, 0.05, 0.04)
    assert _same_axis(seen.yaw_rad, math.pi / 2)  # the 5 cm width runs along world y
    assert (seen.length_m, seen.width_m, seen.height_m) == pytest.approx(
        (0.05, 0.04, 0.08), abs=1e-12
    )


def test_an_irregular_object_on_its_side_is_as_tall_as_its_outline_not_its_box() -> None:
    """A triangle-ish brick stood on its side: its height is the outline's extent across the
    belt, which is less than its bounding rectangle turned up would say (the controller grasped
    above the real top of such a brick when the box was used)."""
    outline = [(0.0, 0.0), (0.12, 0.0), (0.02, 0.09)]  # bounding box 12 x 9 cm
    height = 0.05
    vertices = _prism(outline, height)
    roll = Rotation.from_euler("x", 90, degrees=True)  # footprint's y turns up
    seen = top_view(
        _quat(roll), 0.0, length_m=0.12, width_m=0.09, height_m=height, vertices_m=lambda: vertices
    )
    assert seen.height_m == pytest.approx(0.09, abs=1e-12)
    centroid_y = 0.03  # of the outline: (0 + 0 + 0.09) / 3
    assert seen.below_m == pytest.approx(centroid_y, abs=1e-12)  # the lowest edge, not half
    assert (seen.length_m, seen.width_m) == pytest.approx((0.12, height), abs=1e-12)
    assert _same_axis(seen.yaw_rad, 0.0)


def test_a_small_tilt_keeps_the_recorded_footprint() -> None:
    seen = _view(Rotation.from_euler("y", 0.05), 0.3, L, W, H)  # under 5 degrees
    assert (seen.yaw_rad, seen.length_m, seen.width_m, seen.height_m) == pytest.approx(
        (0.3, L, W, H), abs=1e-12
    )


@pytest.mark.parametrize("tilt_deg", [25.0, 40.0, 60.0])
def test_a_propped_object_is_as_tall_as_its_raised_end(tilt_deg: float) -> None:
    """Propped on another piece, a stick's raised end is its top: the height a camera above
    measures is the vertical extent, not its thickness, and its underside the lowest corner."""
    tilt = math.radians(tilt_deg)
    seen = _view(Rotation.from_euler("y", tilt), 0.0, L, W, H)
    height = L * math.sin(tilt) + H * math.cos(tilt)
    assert _same_axis(seen.yaw_rad, 0.0)
    assert seen.length_m == pytest.approx(L * math.cos(tilt) + H * math.sin(tilt), abs=1e-12)
    assert seen.width_m == pytest.approx(W, abs=1e-12)
    assert seen.height_m == pytest.approx(height, abs=1e-12)
    assert seen.below_m == pytest.approx(height / 2, abs=1e-12)
    assert seen.height_m > 2.5 * H  # the thickness would put the top far too low


def test_a_tilt_near_a_face_grows_the_seen_extents_like_a_projection() -> None:
    tilt = math.pi / 2 - 0.2  # on its end, 0.2 rad off
    seen = _view(Rotation.from_euler("y", tilt), 0.0, L, W, H)
    assert _same_axis(seen.yaw_rad, 0.0)
    assert seen.length_m == pytest.approx(L * math.cos(tilt) + H * math.sin(tilt))
    assert seen.width_m == pytest.approx(W)
    assert seen.height_m == pytest.approx(H * math.cos(tilt) + L * math.sin(tilt))


def test_upright_objects_never_read_their_mesh() -> None:
    def unread() -> np.ndarray:
        raise AssertionError("the mesh was read for an upright object")

    for rotation in (Rotation.from_euler("z", 0.7), Rotation.from_euler("y", 4, degrees=True)):
        seen = top_view(_quat(rotation), 0.3, length_m=L, width_m=W, height_m=H, vertices_m=unread)
        assert (seen.length_m, seen.width_m, seen.height_m) == (L, W, H)
