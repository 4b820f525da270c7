"""The top view: what a camera above sees of upright and tipped-over objects."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from twin.top_view import top_view

L, W, H = 0.16, 0.054, 0.03  # a wooden stick (throughput seed 2, object 34)


def _quat(rotation: Rotation) -> tuple[float, float, float, float]:
    x, y, z, w = rotation.as_quat()  # scipy's order is x, y, z, w
    return (float(x), float(y), float(z), float(w))


def _same_axis(a_rad: float, b_rad: float) -> bool:
    """Headings of an axis (no direction) agree modulo pi."""
    d = (a_rad - b_rad) % math.pi
    return min(d, math.pi - d) < 1e-9


@pytest.mark.parametrize("turn_rad", [0.0, 0.4, -2.0, 3.1])
@pytest.mark.parametrize("footprint_yaw_rad", [0.0, 0.7, -1.3])
def test_an_upright_object_shows_its_footprint_at_its_yaw(
    turn_rad: float, footprint_yaw_rad: float
) -> None:
    seen = top_view(_quat(Rotation.from_euler("z", turn_rad)), footprint_yaw_rad, L, W, H)
    assert _same_axis(seen.yaw_rad, turn_rad + footprint_yaw_rad)
    assert (seen.length_m, seen.width_m, seen.height_m) == pytest.approx((L, W, H), abs=1e-12)


@pytest.mark.parametrize("roll_rad", [math.pi / 2, -math.pi / 2, 1.2, 2.0, math.pi])
def test_a_stick_rolled_about_its_long_axis_keeps_its_heading(roll_rad: float) -> None:
    # body long axis at 0.5 rad; the object is turned by 1.0 rad on the belt and rolled about
    # that long axis: the camera sees the same heading whatever the roll (Euler yaw does not)
    footprint_yaw = 0.5
    long_axis = np.array([math.cos(footprint_yaw), math.sin(footprint_yaw), 0.0])
    rotation = Rotation.from_euler("z", 1.0) * Rotation.from_rotvec(roll_rad * long_axis)
    seen = top_view(_quat(rotation), footprint_yaw, L, W, H)
    assert _same_axis(seen.yaw_rad, 1.5)
    assert seen.length_m == pytest.approx(L, abs=1e-12)
    c, s = abs(math.cos(roll_rad)), abs(math.sin(roll_rad))
    assert seen.width_m == pytest.approx(W * c + H * s, abs=1e-12)
    assert seen.height_m == pytest.approx(W * s + H * c, abs=1e-12)


def test_a_stick_on_its_side_shows_its_height_as_width() -> None:
    seen = top_view(_quat(Rotation.from_euler("x", 90, degrees=True)), 0.0, L, W, H)
    assert _same_axis(seen.yaw_rad, 0.0)
    assert (seen.length_m, seen.width_m, seen.height_m) == pytest.approx((L, H, W), abs=1e-12)


def test_an_object_on_its_end_shows_its_width_and_height() -> None:
    # a brick 8 x 5 x 4 cm stood on its end: the 8 cm edge is vertical, the 5 x 4 face is seen
    seen = top_view(_quat(Rotation.from_euler("y", 90, degrees=True)), 0.0, 0.08, 0.05, 0.04)
    assert _same_axis(seen.yaw_rad, math.pi / 2)  # the 5 cm width runs along world y
    assert (seen.length_m, seen.width_m, seen.height_m) == pytest.approx(
        (0.05, 0.04, 0.08), abs=1e-12
    )


def test_a_slight_tilt_grows_the_seen_extents_like_a_projection() -> None:
    tilt = 0.1  # rad about the width axis
    seen = top_view(_quat(Rotation.from_euler("y", tilt)), 0.0, L, W, H)
    assert _same_axis(seen.yaw_rad, 0.0)
    assert seen.length_m == pytest.approx(L * math.cos(tilt) + H * math.sin(tilt))
    assert seen.width_m == pytest.approx(W)
    assert seen.height_m == pytest.approx(H * math.cos(tilt) + L * math.sin(tilt))
