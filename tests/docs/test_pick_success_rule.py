"""The page's TCP-box rule (``docs/interfaces.md``, "Pick success") in the real twin: the box
overlaps an object when it reaches the object's collision shape, the union of its convex pieces
(not its hull, not its centre of mass), up to the box's z half extent above the top. The Panda's
TCP is put at measured offsets from two pieces lying on a stopped belt, and the twin's
``tcp_overlap_start`` events are read."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path

import pytest
from twin_helpers import box_px, hold, tcp_ik

from interfaces.events import EventType
from tests.docs.conftest import Page
from twin.scenario import Scenario, SystemLevel
from twin.sim import ArmCommand, Twin

M_PER_PX = 0.6 / 1000.0
L_PX = [(0, 0), (150, 0), (150, 50), (50, 50), (50, 150), (0, 150)]
"""An L of two arms 150 px (90 mm) long and 50 px (30 mm) thick, in image pixels (u, v)."""
NOTCH_PX = (90.0, 90.0)
"""Inside the L's convex hull, 24 mm from the L itself."""
ARM_PX = (100.0, 25.0)
"""On one arm of the L."""


def _centroid(points: list[tuple[float, float]]) -> tuple[float, float]:
    """The area centroid of a simple polygon."""
    area = cx = cy = 0.0
    for (u0, v0), (u1, v1) in zip(points, points[1:] + points[:1], strict=True):
        cross = u0 * v1 - u1 * v0
        area += cross
        cx += (u0 + u1) * cross
        cy += (v0 + v1) * cross
    return cx / (3 * area), cy / (3 * area)


def _shifted(points: list[tuple[float, float]], du: float, dv: float) -> list[tuple[float, float]]:
    return [(u + du, v + dv) for u, v in points]


def _overlaps(
    twin: Twin,
    object_id: int,
    at_m: tuple[float, float, float],
    *,
    yaw_rad: float = 0.0,
    opening_m: float = 0.08,
) -> bool:
    """Bring the TCP down to ``at_m`` (its motors' offset corrected by what it measures), hold
    it there, and say whether the twin's events leave the TCP box overlapping ``object_id``
    there; then lift it away."""
    x, y, z = at_m
    hold(
        twin,
        ArmCommand(tcp_ik(twin, (x, y, z + 0.1), yaw_rad=yaw_rad), gripper_width_m=opening_m),
        1.0,
    )
    before = len(twin.events)
    aim = list(at_m)
    for _ in range(3):
        q = tcp_ik(twin, (aim[0], aim[1], aim[2]), yaw_rad=yaw_rad)
        hold(twin, ArmCommand(q, gripper_width_m=opening_m), 0.5)
        tcp = twin.stations[0].tool.tcp_pose()[0]
        aim = [a + (want - got) for a, want, got in zip(aim, at_m, tcp, strict=True)]
    assert max(abs(want - got) for want, got in zip(at_m, tcp, strict=True)) < 5e-4, tcp
    edges = [
        e.type
        for e in twin.events[before:]
        if e.object_id == object_id
        and e.type in (EventType.TCP_OVERLAP_START, EventType.TCP_OVERLAP_END)
    ]
    found = bool(edges) and edges[-1] is EventType.TCP_OVERLAP_START  # overlapping now
    hold(
        twin,
        ArmCommand(tcp_ik(twin, (x, y, z + 0.1), yaw_rad=yaw_rad), gripper_width_m=opening_m),
        0.6,
    )
    return found


def test_the_tcp_box_overlaps_the_collision_shape_up_to_its_half_height_above_the_top(
    interfaces_page: Page, mesh_polygons: Callable[..., Path]
) -> None:
    box = box_px(400, 500, 60, 40)  # 36 mm along the belt, 24 mm across
    ell = _shifted([(float(u), float(v)) for u, v in L_PX], 560, 425)
    ell_centre = _centroid(ell)
    scenario = Scenario(
        duration_s=60.0,
        system=SystemLevel(belt_speed_mps=0.0, prefill_m=1.7, repeat_images=False),
    )
    with Twin(scenario, dataset_dir=mesh_polygons({"img": [(1, box), (1, ell)]})) as twin:
        obs, _ = twin.reset(seed=0)
        pieces = sorted(obs.objects, key=lambda o: o.position_m[1])  # the box is at smaller y
        square, bent = pieces
        half_x, half_y, half_z = twin.stations[0].tool.spec.tcp_half_extents_m
        text = interfaces_page.flat("Pick success")
        stated = re.search(r"half extents \(([^)]*)\) m for the Panda hand", text)
        assert stated
        assert [float(v) for v in stated.group(1).split(",")] == [half_x, half_y, half_z]
        surface = twin.cell.belt.surface_z_m
        x, y, _ = square.position_m
        top = surface + square.height_m
        # above the top: overlapping up to the z half extent (to the physics' margin, 1 mm)
        assert _overlaps(twin, square.id, (x, y, top + half_z - 0.002))
        assert not _overlaps(twin, square.id, (x, y, top + half_z + 0.003))
        # beside it, below its top: up to the x half extent from its outline (along the belt)
        edge = x + 0.5 * square.length_m
        assert _overlaps(twin, square.id, (edge + half_x - 0.003, y, top - 0.005))
        assert not _overlaps(twin, square.id, (edge + half_x + 0.004, y, top - 0.005))
        # in the L's notch: inside its convex hull but not near it, no overlap; on its arm, one
        cx, cy, _ = bent.position_m
        bent_top = surface + bent.height_m

        def world(point_px: tuple[float, float], z_m: float) -> tuple[float, float, float]:
            """A point of the image in the world, from the L's centroid (image down is +x)."""
            du, dv = point_px[0] - ell_centre[0], point_px[1] - ell_centre[1]
            return (cx + dv * M_PER_PX, cy + du * M_PER_PX, z_m)

        # the closed fingers (their long side across the TCP's y) along the notch's diagonal
        notch = world(_shifted([NOTCH_PX], 560, 425)[0], bent_top - 0.005)
        assert not _overlaps(twin, bent.id, notch, yaw_rad=-math.pi / 4, opening_m=0.0)
        arm = world(_shifted([ARM_PX], 560, 425)[0], bent_top + 0.5 * half_z)
        assert _overlaps(twin, bent.id, arm, yaw_rad=-math.pi / 4, opening_m=0.0)
        events = twin.events
        rate_hz = twin.cell.physics.physics_hz
    # events.jsonl's time_s is its step over the physics rate (docs/interfaces.md, "Events")
    assert all(e.time_s == pytest.approx(e.step / rate_hz, abs=1e-9) for e in events)
