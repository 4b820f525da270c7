"""The pick window: a grasp is a pick only where the object's centre of mass is inside it."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pybullet as pb
import pytest
from twin_helpers import box_px, hold, tcp_ik

from interfaces.events import EventType
from twin.scenario import Scenario, SystemLevel
from twin.sim import ArmCommand, Twin

ONE_BOX = {"img": [(1, box_px(500, 500, 100, 50))]}  # brick, 60 x 30 mm footprint


@pytest.mark.parametrize(
    ("beyond_end_m", "credited"),
    [(-0.024, True), (0.024, False)],
    ids=["inside-the-window", "just-past-the-window"],
)
def test_a_grasp_is_credited_only_inside_the_pick_window(
    mesh_polygons: Callable[..., Path], beyond_end_m: float, credited: bool
) -> None:
    """The object is parked on the stopped belt 24 mm before or after the window's end (0.35 m)
    and grasped by the book (dwell, opposite finger contacts, pressing): the grasp just past
    the window is no pick (it was credited at x = 0.374 m), the one inside still is."""
    meshes = mesh_polygons(ONE_BOX)
    scenario = Scenario(
        duration_s=30.0,
        system=SystemLevel(belt_speed_mps=0.0, prefill_m=1.7, repeat_images=False),
    )
    with Twin(scenario, dataset_dir=meshes) as twin:
        obs, _ = twin.reset(seed=0)
        (obj,) = obs.objects
        assert twin._monitor is not None
        body = twin._monitor.body_of(obj.id)
        assert body is not None
        (_, y, z), orientation = pb.getBasePositionAndOrientation(body, physicsClientId=twin.client)
        end_m = twin.cell.stations[0].pick_window_x_m[1]
        home = twin.cell.stations[0].robot.home_joint_positions

        def park(x_m: float) -> None:  # as the belt would carry it there, then stopped
            pb.resetBasePositionAndOrientation(
                body, (x_m, y, z + 0.001), orientation, physicsClientId=twin.client
            )
            hold(twin, ArmCommand(home), 0.5)

        park(end_m - 0.024)  # inside: it enters the window
        x = end_m + beyond_end_m
        park(x)
        grasp_z = z + 0.5 * obj.height_m - 0.02  # 2 cm below the top: the palm stays clear
        hold(twin, ArmCommand(tcp_ik(twin, (x, y, grasp_z + 0.3)), gripper_width_m=0.08), 2.0)
        hold(twin, ArmCommand(tcp_ik(twin, (x, y, grasp_z + 0.1)), gripper_width_m=0.08), 1.0)
        hold(twin, ArmCommand(tcp_ik(twin, (x, y, grasp_z)), gripper_width_m=0.08), 1.0)
        hold(twin, ArmCommand(tcp_ik(twin, (x, y, grasp_z)), gripper_width_m=0.0), 0.5)
        (gt,) = twin.observe_objects()
        events = [e for e in twin.events if e.object_id == obj.id]
        counts = twin.counts()
    kinds = [e.type for e in events]
    assert EventType.ENTERED_WORKSPACE in kinds
    # the grasp itself happened either way: overlap for the dwell, both fingers on the object
    assert EventType.TCP_OVERLAP_START in kinds
    assert kinds.count(EventType.FINGER_CONTACT) == 2
    assert gt.position_m[0] == pytest.approx(x, abs=0.01)
    if credited:
        (pick,) = [e for e in events if e.type is EventType.PICK_SUCCESS]
        assert pick.data["position_m"][0] <= end_m
        assert gt.held
        assert (counts.picked, counts.missed) == (1, 0)
    else:
        assert EventType.PICK_SUCCESS not in kinds
        assert not gt.held
        # it left the window downstream unpicked: a miss
        assert EventType.MISSED in kinds
        assert (counts.picked, counts.missed) == (0, 1)
