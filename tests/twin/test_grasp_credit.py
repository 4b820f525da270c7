"""The object credited with ``pick_success`` is the one the tool actually holds."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from twin_helpers import box_px, hold, tcp_ik

from interfaces.events import EventType
from twin.scenario import Scenario, SystemLevel
from twin.sim import ArmCommand, Twin

# two bricks 12 mm long (along the belt) and 40 mm across, 2 mm apart along the belt: the
# Panda hand's 20 mm wide finger pads, closing across the belt on one, touch the other as well
SIDE_BY_SIDE = {"img": [(1, box_px(500, 500, 20, 67)), (1, box_px(500, 523, 20, 67))]}


def test_the_gripped_object_is_credited_not_its_neighbour(
    mesh_polygons: Callable[..., Path],
) -> None:
    """The hand closes on the second object; the first lies beside it, between the finger pads
    too. The second is the one credited, fixed to the hand and placed with its success (the
    first used to be credited and fixed to the hand, while the gripped one was carried off by
    friction and placed without a success)."""
    scenario = Scenario(
        duration_s=30.0,
        system=SystemLevel(belt_speed_mps=0.0, prefill_m=1.7, repeat_images=False),
    )
    with Twin(scenario, dataset_dir=mesh_polygons(SIDE_BY_SIDE)) as twin:
        obs, _ = twin.reset(seed=0)
        first, target = sorted(obs.objects, key=lambda o: o.id)
        assert abs(first.position_m[0] - target.position_m[0]) < 0.016  # side by side
        x, y, z = target.position_m
        z += 0.5 * target.height_m - 0.015
        hold(twin, ArmCommand(tcp_ik(twin, (x, y, z + 0.3)), gripper_width_m=0.08), 2.0)
        hold(twin, ArmCommand(tcp_ik(twin, (x, y, z + 0.1)), gripper_width_m=0.08), 1.0)
        hold(twin, ArmCommand(tcp_ik(twin, (x, y, z)), gripper_width_m=0.08), 1.0)
        hold(twin, ArmCommand(tcp_ik(twin, (x, y, z)), gripper_width_m=0.0), 0.5)
        # both are squeezed between the pads
        touched = {e.object_id for e in twin.events if e.type is EventType.FINGER_CONTACT}
        assert touched == {first.id, target.id}
        hold(twin, ArmCommand(tcp_ik(twin, (x, y, 0.3)), gripper_width_m=0.0), 1.0)
        held = [g.id for g in twin.observe_objects() if g.held]
        bin_spec = twin.cell.stations[0].bin_for(target.class_name)
        assert bin_spec is not None
        over = (bin_spec.centre_x_m, bin_spec.centre_y_m, 0.2)
        hold(
            twin,
            ArmCommand(tcp_ik(twin, (bin_spec.centre_x_m, 0.35, 0.3)), gripper_width_m=0.0),
            1.0,
        )
        hold(twin, ArmCommand(tcp_ik(twin, over), gripper_width_m=0.0), 1.5)
        hold(twin, ArmCommand(tcp_ik(twin, over), gripper_width_m=0.08), 1.5)
        events = twin.events
    picks = [e.object_id for e in events if e.type is EventType.PICK_SUCCESS]
    assert picks == [target.id]
    assert held == [target.id]
    placed = [e.object_id for e in events if e.type is EventType.PLACED_IN_BIN]
    assert target.id in placed
