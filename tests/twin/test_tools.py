"""Every tool kind on any station, in PyBullet: scripted picks with the suction cup and the wide
gripper on the Panda and the UR10, the suction cup's vacuum and seal, slip and overload drops,
and the drop reasons.

The TCP is moved with the twin's own joint commands; the joint targets come from PyBullet's
inverse kinematics here in the test only.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pybullet as pb
import pytest
from twin_helpers import box_px, tcp_ik

from interfaces.cell import Cell, default_cell
from interfaces.events import Event, EventType
from interfaces.robots import robot_from_data
from interfaces.tools import tool_from_data
from twin.ground_truth import GroundTruth
from twin.scenario import PhysicsLevel, Scenario, SystemLevel
from twin.sim import ArmCommand, Twin

TOP = 0.07  # m: carry height of the TCP
WIDE_TOP = {"img": [(1, box_px(500, 500, 100, 80))]}  # brick, 60 x 48 mm: a 40 mm lip fits
NARROW_TOP = {"img": [(1, box_px(500, 500, 100, 50))]}  # brick, 60 x 30 mm: it does not
WIDE_13CM = {"img": [(1, box_px(500, 500, 100, 217))]}  # brick, 60 x 130 mm across the belt
WIDE_12CM = {"img": [(1, box_px(500, 500, 100, 200))]}  # brick, 60 x 120 mm


def _cell(robot: str, tool: str, **tool_fields: object) -> Cell:
    """The reference cell with its station's robot and tool replaced (catalogue names)."""
    base = default_cell()
    spec = tool_from_data(tool, "tool")
    if tool_fields:
        spec = replace(spec, **tool_fields)  # type: ignore[arg-type]
    station = replace(base.stations[0], robot=robot_from_data(robot, "robot"), tool=spec)
    return replace(base, stations=(station,))


def _still(friction: float | None = None) -> Scenario:
    physics = (
        PhysicsLevel() if friction is None else PhysicsLevel(friction={"brick": (friction,) * 2})
    )
    return Scenario(
        duration_s=60.0,
        system=SystemLevel(belt_speed_mps=0.0, prefill_m=1.7, repeat_images=False),
        physics=physics,
    )


def _hold(twin: Twin, q: tuple[float, ...], tool: float, seconds: float) -> None:
    end = twin.time_s + seconds
    twin.command(ArmCommand(q, gripper_width_m=tool))
    while twin.time_s < end - 1e-9:
        twin.advance()


def _commands(twin: Twin) -> tuple[float, float]:
    """The tool's (grip, let go) commands: a cup's vacuum on/off, a jaw's closed/open."""
    tool = twin.stations[0].tool
    if tool.spec.kind == "suction_cup":
        return 1.0, 0.0
    return 0.0, tool.max_command


def _grasp_z(twin: Twin, obj: GroundTruth) -> float:
    top = obj.position_m[2] + 0.5 * obj.height_m
    return top + 0.001 if twin.stations[0].tool.spec.kind == "suction_cup" else top - 0.015


def _approach_and_grip(twin: Twin, obj: GroundTruth, seconds: float = 0.8) -> float:
    """Above the object, down onto it, grip; returns the time the grip was commanded."""
    grip, let_go = _commands(twin)
    x, y, _ = obj.position_m
    z = _grasp_z(twin, obj)
    _hold(twin, tcp_ik(twin, (x, y, z + 0.3)), let_go, 3.0)
    _hold(twin, tcp_ik(twin, (x, y, z + 0.1)), let_go, 1.0)
    _hold(twin, tcp_ik(twin, (x, y, z)), let_go, 1.0)
    t_grip = twin.time_s
    _hold(twin, tcp_ik(twin, (x, y, z)), grip, seconds)
    return t_grip


def _carry_to_bin(twin: Twin, obj: GroundTruth) -> None:
    grip, let_go = _commands(twin)
    x, y, _ = obj.position_m
    _hold(twin, tcp_ik(twin, (x, y, 0.3)), grip, 1.0)
    bin_spec = twin.cell.stations[0].bin_for(obj.class_name)
    assert bin_spec is not None
    over = (bin_spec.centre_x_m, bin_spec.centre_y_m, 0.2)
    _hold(twin, tcp_ik(twin, (bin_spec.centre_x_m, 0.35, 0.3)), grip, 1.5)
    _hold(twin, tcp_ik(twin, over), grip, 1.5)
    _hold(twin, tcp_ik(twin, over), let_go, 1.5)


def _of(events: tuple[Event, ...], kind: EventType) -> list[Event]:
    return [e for e in events if e.type is kind]


@pytest.mark.parametrize(
    ("robot", "tool", "polygons"),
    [
        ("panda", "suction_cup", WIDE_TOP),
        ("ur10", "suction_cup", WIDE_TOP),
        ("ur10", "wide_gripper", WIDE_13CM),
    ],
    ids=["panda-suction", "ur10-suction", "ur10-wide-13cm"],
)
def test_every_tool_kind_picks_and_places_on_any_station(
    mesh_polygons: Callable[..., Path], robot: str, tool: str, polygons: dict[str, list[object]]
) -> None:
    with Twin(_still(), dataset_dir=mesh_polygons(polygons), cell=_cell(robot, tool)) as twin:
        obs, _ = twin.reset(seed=0)
        (obj,) = obs.objects
        station = twin.stations[0]
        assert station.robot.spec.name == robot
        t_grip = _approach_and_grip(twin, obj)
        holding = station.tool.joint_report()
        measured = station.tool.measured()
        fingers = [
            pb.getJointState(station.robot.body, station.robot.joint_index(j, "finger"),
                             physicsClientId=twin.client)[0]
            for j in station.tool.joint_names
            if tool == "wide_gripper"
        ]  # fmt: skip
        _carry_to_bin(twin, obj)
        vented = station.tool.joint_report()
        events = twin.events
    (pick,) = _of(events, EventType.PICK_SUCCESS)
    assert pick.object_id == obj.id
    (placed,) = _of(events, EventType.PLACED_IN_BIN)
    assert (placed.object_id, placed.data["correct"]) == (obj.id, True)
    assert not _of(events, EventType.PICK_DROPPED)
    assert not _of(events, EventType.UNINTENDED_CONTACT)
    if tool == "suction_cup":
        # no fingers: the seal and the vacuum's build-up are the grasp
        assert not _of(events, EventType.FINGER_CONTACT)
        assert station.tool.joint_names == ("suction_cup_vacuum",)
        build_up_s = station.tool.spec.build_up_s  # type: ignore[union-attr]
        assert pick.time_s - t_grip == pytest.approx(build_up_s, abs=2 * twin.dt_s)
        assert holding == ([1.0], [0.0])
        assert vented == ([0.0], [0.0])
    else:
        # the fingers close across the belt, on the object's 130 mm long side (``width_m`` is
        # its narrow side), each reporting its own joint position (what /tf's finger links are)
        assert len(_of(events, EventType.FINGER_CONTACT)) >= 2
        assert obj.length_m == pytest.approx(0.13, abs=0.001)
        assert measured == pytest.approx(obj.length_m, abs=0.004)
        assert holding[0] == pytest.approx(fingers, abs=1e-9)
        assert holding[1] == [0.0, 0.0]
        assert sum(holding[0]) == pytest.approx(measured, abs=1e-9)
        # the two prismatic fingers close independently: each stops where the object's side
        # is (a few mm off the TCP), together they span the measured opening
        assert sum(fingers) == pytest.approx(measured, abs=1e-3)
        assert fingers == pytest.approx([0.5 * measured] * 2, abs=0.004)
        assert vented[0] == pytest.approx([0.07, 0.07], abs=1e-3)  # open again


def test_a_suction_cup_without_a_seal_holds_no_vacuum_and_picks_nothing(
    mesh_polygons: Callable[..., Path],
) -> None:
    """A 40 mm lip on a 30 mm wide top face leaks: no vacuum, no pick."""
    with Twin(
        _still(), dataset_dir=mesh_polygons(NARROW_TOP), cell=_cell("panda", "suction_cup")
    ) as twin:
        obs, _ = twin.reset(seed=0)
        (obj,) = obs.objects
        _approach_and_grip(twin, obj, seconds=1.0)
        vacuum = twin.stations[0].tool.measured()
        overlapped = _of(twin.events, EventType.TCP_OVERLAP_START)
        picks = _of(twin.events, EventType.PICK_SUCCESS)
    assert overlapped  # the lip was on the object
    assert vacuum == 0.0
    assert picks == []


def test_a_tilted_cup_does_not_seal(mesh_polygons: Callable[..., Path]) -> None:
    with Twin(
        _still(), dataset_dir=mesh_polygons(WIDE_TOP), cell=_cell("ur10", "suction_cup")
    ) as twin:
        obs, _ = twin.reset(seed=0)
        (obj,) = obs.objects
        x, y, _ = obj.position_m
        z = _grasp_z(twin, obj) + 0.004  # the tilted lip's low edge just touches
        _hold(twin, tcp_ik(twin, (x, y, z + 0.1), tilt_rad=0.45), 0.0, 3.0)
        _hold(twin, tcp_ik(twin, (x, y, z), tilt_rad=0.45), 0.0, 1.0)
        _hold(twin, tcp_ik(twin, (x, y, z), tilt_rad=0.45), 1.0, 1.0)
        assert _of(twin.events, EventType.TCP_OVERLAP_START)
        assert twin.stations[0].tool.measured() == 0.0
        assert not _of(twin.events, EventType.PICK_SUCCESS)


def test_a_suction_cup_drops_an_object_it_cannot_carry_at_the_arms_acceleration(
    mesh_polygons: Callable[..., Path],
) -> None:
    """The seal efficiency is set so the cup holds the brick at rest with 1.5 g: the lift's
    acceleration (several m/s^2) overloads it."""
    meshes = mesh_polygons(WIDE_TOP)
    with Twin(_still(), dataset_dir=meshes, cell=_cell("ur10", "suction_cup")) as probe:
        (obj,) = probe.reset(seed=0)[0].objects
    cup = _cell("ur10", "suction_cup").stations[0].tool
    area_m2 = math.pi * (0.5 * cup.cup_diameter_m) ** 2  # type: ignore[union-attr]
    eta = 1.5 * obj.mass_kg * 9.81 / (cup.vacuum_kPa * 1000.0 * area_m2)  # type: ignore[union-attr]
    cell = _cell("ur10", "suction_cup", seal_efficiency={"brick": eta})
    with Twin(_still(), dataset_dir=meshes, cell=cell) as twin:
        twin.reset(seed=0)
        _approach_and_grip(twin, obj, seconds=0.5)  # held, at rest
        held_at_rest = [g.id for g in twin.observe_objects() if g.held]
        _carry_to_bin(twin, obj)
        events = twin.events
    assert held_at_rest == [obj.id]
    (pick,) = _of(events, EventType.PICK_SUCCESS)
    (drop,) = _of(events, EventType.PICK_DROPPED)
    assert drop.object_id == obj.id
    assert drop.data["reason"] == "suction_overload"
    assert drop.time_s > pick.time_s + 0.3  # when the lift started
    assert not _of(events, EventType.PLACED_IN_BIN)


def test_a_wide_gripper_drops_an_object_that_slips_under_acceleration(
    mesh_polygons: Callable[..., Path],
) -> None:
    """Friction 0.08, grip 100 N: the pads carry 16 N, the 1 kg brick weighs 9.6 N: held at
    rest, it slips out when the arm accelerates."""
    with Twin(
        _still(friction=0.08),
        dataset_dir=mesh_polygons(WIDE_12CM),
        cell=_cell("ur10", "wide_gripper"),
    ) as twin:
        obs, _ = twin.reset(seed=0)
        (obj,) = obs.objects
        assert obj.mass_kg * 9.81 < 0.08 * 200.0
        _approach_and_grip(twin, obj, seconds=0.5)
        held_at_rest = [g.id for g in twin.observe_objects() if g.held]
        _carry_to_bin(twin, obj)
        events = twin.events
    assert held_at_rest == [obj.id]
    (pick,) = _of(events, EventType.PICK_SUCCESS)  # not grasped again while slipping
    (drop,) = _of(events, EventType.PICK_DROPPED)
    assert (drop.object_id, drop.data["reason"]) == (obj.id, "slipped")
    assert drop.time_s > pick.time_s + 0.3
    assert not _of(events, EventType.PLACED_IN_BIN)


def test_a_wide_gripper_carries_the_same_object_with_enough_friction(
    mesh_polygons: Callable[..., Path],
) -> None:
    with Twin(
        _still(friction=0.6),
        dataset_dir=mesh_polygons(WIDE_12CM),
        cell=_cell("ur10", "wide_gripper"),
    ) as twin:
        obs, _ = twin.reset(seed=0)
        (obj,) = obs.objects
        _approach_and_grip(twin, obj, seconds=0.5)
        _carry_to_bin(twin, obj)
        events = twin.events
    assert not _of(events, EventType.PICK_DROPPED)
    assert [e.object_id for e in _of(events, EventType.PLACED_IN_BIN)] == [obj.id]


def test_opening_away_from_the_bins_is_a_drop_with_reason_released(
    mesh_polygons: Callable[..., Path],
) -> None:
    with Twin(_still(), dataset_dir=mesh_polygons(NARROW_TOP)) as twin:  # the Panda hand
        obs, _ = twin.reset(seed=0)
        (obj,) = obs.objects
        _approach_and_grip(twin, obj, seconds=0.5)
        x, y, _ = obj.position_m
        _hold(twin, tcp_ik(twin, (x, y, 0.3)), 0.0, 1.0)
        _hold(twin, tcp_ik(twin, (x, y, 0.3)), 0.08, 0.5)
        events = twin.events
    (drop,) = _of(events, EventType.PICK_DROPPED)
    assert (drop.object_id, drop.data["reason"], drop.data["station"]) == (
        obj.id,
        "released",
        "panda",
    )


def test_a_suction_cup_loses_its_seal_when_the_object_is_knocked_off_the_lip(
    mesh_polygons: Callable[..., Path],
) -> None:
    with Twin(
        _still(), dataset_dir=mesh_polygons(WIDE_TOP), cell=_cell("panda", "suction_cup")
    ) as twin:
        obs, _ = twin.reset(seed=0)
        (obj,) = obs.objects
        _approach_and_grip(twin, obj, seconds=0.5)
        x, y, _ = obj.position_m
        _hold(twin, tcp_ik(twin, (x, y, 0.3)), 1.0, 1.0)
        assert [g.id for g in twin.observe_objects() if g.held] == [obj.id]
        assert twin._monitor is not None
        body = twin._monitor.body_of(obj.id)
        assert body is not None
        for _ in range(24):  # a blow far beyond what the cup's fixture withstands
            position, _ = pb.getBasePositionAndOrientation(body, physicsClientId=twin.client)
            pb.applyExternalForce(
                body, -1, (0.0, 3000.0, 0.0), position, pb.WORLD_FRAME, physicsClientId=twin.client
            )
            twin.advance()
        events = twin.events
    (drop,) = _of(events, EventType.PICK_DROPPED)
    assert (drop.object_id, drop.data["reason"]) == (obj.id, "seal_lost")


def test_the_suction_cups_stem_touching_an_object_not_under_it_is_unintended(
    mesh_polygons: Callable[..., Path],
) -> None:
    """The lip beside the object (not over it), the stem's side against its top edge."""
    with Twin(
        _still(), dataset_dir=mesh_polygons(WIDE_TOP), cell=_cell("ur10", "suction_cup")
    ) as twin:
        obs, _ = twin.reset(seed=0)
        (obj,) = obs.objects
        x, y, _ = obj.position_m
        top = obj.position_m[2] + 0.5 * obj.height_m
        beside = y + 0.5 * obj.width_m + 0.022  # the stem's 25 mm radius reaches 3 mm in
        _hold(twin, tcp_ik(twin, (x, beside, top + 0.1)), 0.0, 3.0)
        _hold(twin, tcp_ik(twin, (x, beside, top - 0.02)), 0.0, 1.0)
        events = twin.events
    unintended = _of(events, EventType.UNINTENDED_CONTACT)
    assert [(e.object_id, e.data["link"]) for e in unintended][:1] == [(obj.id, "suction_cup_stem")]
    assert not _of(events, EventType.TCP_OVERLAP_START)
    assert np.isfinite(top)


def test_the_tcp_acceleration_spreads_a_one_step_velocity_jump_over_its_window() -> None:
    """Sampled every physics step (a tool does it from its ``tick``), a velocity jump within one
    step, as when an object is fixed to the TCP, counts as that jump over the 20 ms window (not
    over the 4 ms step, five times as much); a steady acceleration is measured as it is."""
    from twin.tools import ACCELERATION_WINDOW_S, TcpAccelerometer

    client = pb.connect(pb.DIRECT)
    try:
        body = pb.createMultiBody(
            baseMass=0.0,
            linkMasses=[1.0],
            linkCollisionShapeIndices=[-1],
            linkVisualShapeIndices=[-1],
            linkPositions=[[0.0, 0.0, 0.0]],
            linkOrientations=[[0.0, 0.0, 0.0, 1.0]],
            linkInertialFramePositions=[[0.0, 0.0, 0.0]],
            linkInertialFrameOrientations=[[0.0, 0.0, 0.0, 1.0]],
            linkParentIndices=[0],
            linkJointTypes=[pb.JOINT_PRISMATIC],
            linkJointAxis=[[1.0, 0.0, 0.0]],
            physicsClientId=client,
        )
        meter = TcpAccelerometer(body, 0, client)
        dt_s = 1.0 / 240.0
        for k in range(12):  # steady at 0.3 m/s
            pb.resetJointState(body, 0, 0.0, 0.3, physicsClientId=client)
            meter.sample(k * dt_s)
        pb.resetJointState(body, 0, 0.0, 0.4, physicsClientId=client)  # one step: +0.1 m/s
        jump = meter.magnitude(12 * dt_s)
        assert jump == pytest.approx(0.1 / ACCELERATION_WINDOW_S, rel=0.25)
        assert jump < 0.5 * 0.1 / dt_s
        for k in range(13, 40):  # then 2 m/s^2, steadily
            pb.resetJointState(body, 0, 0.0, 0.4 + 2.0 * (k - 12) * dt_s, physicsClientId=client)
            steady = meter.magnitude(k * dt_s)
        assert steady == pytest.approx(2.0, rel=1e-6)
        meter.reset()
        assert meter.magnitude(40 * dt_s) == 0.0
    finally:
        pb.disconnect(physicsClientId=client)
