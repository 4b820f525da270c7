"""The pick state machine in closed loop with an ideal (kinematic) arm, and its bad inputs."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
import yaml

from control.config import ControllerConfig
from control.ik import yaw_of
from control.kinematic_sim import GripperSpec, ObjectSpec, run_episode
from control.pick import Command, Phase, PickController, TcpMeasurement
from control.poses import drop_point
from control.scheduler import nearest_grasp_yaw
from control.tracking import Track
from interfaces.cell import cell_from_data, load_cell, resolve_cell_path
from interfaces.tools import SuctionCupSpec

FOLLOW_SEQUENCE = [Phase.IDLE, Phase.APPROACH, Phase.DESCEND, Phase.DWELL, Phase.CLOSE, Phase.LIFT]


@pytest.mark.parametrize("speed_mps", [0.2, 0.4, 0.6])
def test_closed_loop_reaches_and_dwells_within_4mm(speed_mps: float) -> None:
    config = ControllerConfig()
    result = run_episode(speed_mps, seed=1, duration_s=4.0)
    assert [phase for _, phase in result.phases][: len(FOLLOW_SEQUENCE)] == FOLLOW_SEQUENCE
    # Kinematic arm: within 4 mm in under 1.2 s, and it stays there through dwell and close.
    # The bound is what the datasheet allows: from the ready pose the TCP goes down 0.12 m to
    # the approach point and 0.06 m more to the grasp point; the Panda's joints 2 and 4 (7.5
    # and 12.5 rad/s^2) allow only 3.1-4.4 m/s^2 vertically there, so the controller plans at
    # 2.5 m/s^2 (motion.max_acceleration) and the two moves alone take
    # 2 sqrt(0.12 / 2.5) + 2 sqrt(0.06 / 2.5) + 2 a / j = 0.83 s, before the catch-up along x.
    assert 0.0 < result.tracking_time_4mm_s < 1.2
    assert result.max_follow_error_m < 0.004
    starts = {phase: t for t, phase in reversed(result.phases)}
    assert starts[Phase.CLOSE] - starts[Phase.DWELL] >= config.pick.dwell_s - 1e-9
    assert result.max_joint_limit_violation_rad == 0.0
    assert result.stats.aborted == {}
    assert result.stats.errors == {}


def test_gripper_closes_during_the_end_of_the_dwell_when_configured() -> None:
    base = ControllerConfig()
    config = replace(base, pick=replace(base.pick, close_overlap_s=base.pick.close_s))
    result = run_episode(0.4, seed=1, duration_s=4.0, config=config)
    starts = {phase: t for t, phase in reversed(result.phases)}
    # the close starts close_s before the dwell's end, so the lift starts dwell_s after the dwell
    # did (close_s earlier than with the default sequence), while the TCP still follows
    assert starts[Phase.CLOSE] - starts[Phase.DWELL] == pytest.approx(
        config.pick.dwell_s - config.pick.close_s, abs=config.motion.control_period_s + 1e-9
    )
    assert starts[Phase.LIFT] - starts[Phase.DWELL] == pytest.approx(
        config.pick.dwell_s, abs=2 * config.motion.control_period_s + 1e-9
    )
    assert result.max_follow_error_m < 0.004
    assert result.stats.aborted == {}


@pytest.mark.parametrize("speed_mps", [0.2, 0.6])
def test_joint_space_approach_meets_the_object_and_picks_it(speed_mps: float) -> None:
    base = ControllerConfig()
    config = replace(base, pick=replace(base.pick, approach_space="joint"))
    result = run_episode(speed_mps, seed=1, duration_s=6.5, config=config)
    assert [phase for _, phase in result.phases][: len(FOLLOW_SEQUENCE)] == FOLLOW_SEQUENCE
    # one joint move to above the object, arriving with its velocity; then within 4 mm
    assert 0.0 < result.tracking_time_4mm_s < 1.2
    assert result.max_follow_error_m < 0.004
    assert sum(result.stats.completed_by_class.values()) == 1
    assert result.max_joint_limit_violation_rad == 0.0
    assert result.stats.aborted == {}
    assert result.stats.errors == {}


def test_a_station_waits_for_a_track_to_move_with_the_belt_before_it_meets_it() -> None:
    """With ``scheduler.settle_tolerance_mps`` a track whose estimate is 0.15 m/s off the
    belt's measured speed is left ``unsettled`` (the arm stays at the ready pose); once the
    estimate agrees with the belt (0.1 s later), the station goes for it."""
    base = ControllerConfig()
    config = replace(base, scheduler=replace(base.scheduler, settle_tolerance_mps=0.08))
    controller = PickController(config)
    unsettled_then: list[bool] = []

    def tracks_at(t_s: float) -> tuple[Track, ...]:
        unsettled_then.append("unsettled" in controller.stats().untargeted)
        vx = 0.4 if t_s >= 0.1 else 0.25
        return (replace(_track(-0.45, t_s), velocity_mps=(vx, 0.0)),)

    commands = _drive(controller, tracks_at, 140)
    first = next(c.t_s for c in commands if c.phase != Phase.IDLE)
    assert 0.1 <= first < 0.12
    assert any(unsettled_then)  # while the estimate was off
    assert "unsettled" not in controller.stats().untargeted  # targeted in the end
    # unset (the default), the same track is met at once, its estimate off or not
    unset = _drive(PickController(base), tracks_at, 20)
    assert next(c.t_s for c in unset if c.phase != Phase.IDLE) < 0.01


def test_full_pick_drops_into_the_class_bin() -> None:
    config = ControllerConfig()
    result = run_episode(0.4, seed=2, duration_s=6.5)
    assert result.stats.completed_by_class == {"brick": 1}
    assert result.release_tcp_m is not None
    # released over the bin: within the drop tolerance of its drop point along x and y, never
    # lower than the drop point
    bx, by, bz = config.bins["brick"]
    x, y, z = result.release_tcp_m
    assert abs(x - bx) <= config.pick.drop_tolerance_m + 1e-3
    assert abs(y - by) <= config.pick.drop_tolerance_m + 1e-3
    assert z >= bz - 1e-3
    assert [phase for _, phase in result.phases][-3:] == [Phase.RELEASE, Phase.RETURN, Phase.IDLE]
    assert result.max_joint_limit_violation_rad == 0.0


def test_a_grip_on_nothing_aborts_is_retried_once_and_never_carried() -> None:
    """Fingers that close past the object (nothing holds them apart) abort the pick as
    ``grip_missed`` without carrying; the object is targeted once more, then given up.

    At 0.15 m/s: within the datasheet joint limits a missed grasp and its retry (lift, return,
    approach, descent, dwell, close) take about 3.2 s after the first close, and the first
    close ends about 1.3 s after the object entered the 0.7 m window; at 0.2 m/s the object
    leaves the window (3.5 s) before the retry could close on it."""
    result = run_episode(0.15, seed=2, duration_s=9.0, gripper=GripperSpec(grippable=False))
    phases = [phase for _, phase in result.phases]
    assert result.stats.aborted == {"grip_missed": 2}
    assert result.stats.targeted == 1  # a retry is not a new target
    assert sum(result.stats.completed_by_class.values()) == 0
    assert Phase.CARRY not in phases
    assert phases.count(Phase.CLOSE) == 2
    assert phases[-1] in (Phase.RETURN, Phase.IDLE)
    assert result.max_joint_limit_violation_rad == 0.0


def test_a_gripped_object_passes_the_grip_check_and_is_carried_to_its_bin() -> None:
    """Fingers stopped by the object stay wider than commanded: no ``grip_missed``."""
    result = run_episode(0.4, seed=2, duration_s=6.5, gripper=GripperSpec())
    assert result.stats.completed_by_class == {"brick": 1}
    assert result.stats.aborted == {}
    width_m = ObjectSpec().width_m
    assert min(result.openings_m) == pytest.approx(width_m, abs=1e-9)  # held apart by it


def test_the_drop_point_is_the_nearest_to_the_tcp_inside_the_bin_less_for_long_objects() -> None:
    """The release point is the point nearest the TCP within ``drop_tolerance_m`` of the bin's
    drop point along x and y, less half the object's length: the base turns least, and no part of
    a long object lands on the bin's wall."""
    config = ControllerConfig()
    bx, by, bz = config.bins["brick"]
    tolerance = config.pick.drop_tolerance_m
    over_the_belt = (bx + 1.0, by + 0.5, bz - 0.05)  # beyond the bin in x and y, lower
    inside = (bx + 0.01, by - 0.02, bz + 0.1)  # within reach of every length below
    for length_m in (0.0, 0.06, 2 * tolerance, 0.3):
        half = max(0.0, tolerance - 0.5 * length_m)
        assert drop_point(config, "brick", over_the_belt, length_m) == pytest.approx(
            (bx + half, by + half, bz), abs=1e-12
        )
        x, y, z = drop_point(config, "brick", inside, length_m)
        assert (x, y) == pytest.approx((bx + min(0.01, half), by - min(0.02, half)), abs=1e-12)
        assert z == inside[2]  # never lower than the TCP: the arm does not dip to release
    assert drop_point(config, "gypsum", inside, 0.0) == config.ready_tcp_position_m


def _track(x0: float, t_s: float = 0.0, *, vx: float = 0.4, y: float = 0.5) -> Track:
    """The track of an object that was at ``x0`` at t = 0, as estimated at ``t_s``."""
    return Track(
        track_id=1,
        stamp_s=t_s,
        class_name="wood",
        class_confidence=1.0,
        position_m=(x0 + vx * t_s, y),
        velocity_mps=(vx, 0.0),
        position_std_m=0.001,
        yaw_rad=0.2,
        length_m=0.1,
        width_m=0.04,
        height_m=0.03,
        hits=10,
        confirmed=True,
        last_update_s=0.0,
    )


def _drive(
    controller: PickController,
    tracks_at: Callable[[float], tuple[Track, ...]],
    ticks: int,
    belt: tuple[float, float] = (0.4, 0.0),
    dt_s: float = 0.005,
) -> list[Command]:
    """Run the controller with an ideal arm; every joint command must be within the limits."""
    kin = controller.kinematics
    q = controller.q_ready
    commands: list[Command] = []
    for k in range(ticks):
        t_s = k * dt_s
        pose = kin.fk(q)
        x, y, z = (float(v) for v in pose.translation)
        measured = TcpMeasurement(position_m=(x, y, z), yaw_rad=yaw_of(pose))
        command = controller.update(t_s, measured, tracks_at(t_s), belt)
        q = np.asarray(command.joint_positions_rad)
        assert kin.within_limits(q)
        commands.append(command)
    return commands


def test_ruckig_error_aborts_and_keeps_joint_commands_in_limits() -> None:
    controller = PickController(ControllerConfig())
    fine = _track(-0.45)

    def tracks_at(t_s: float) -> tuple[Track, ...]:
        # After 0.1 s the target's velocity estimate explodes beyond the Cartesian limits.
        if t_s < 0.1:
            return (fine,)
        return (
            Track(
                **{
                    **fine.__dict__,
                    "stamp_s": t_s,
                    "position_m": fine.position_at(t_s),
                    "velocity_mps": (3.0, 0.0),
                }
            ),
        )

    commands = _drive(controller, tracks_at, 200)
    stats = controller.stats()
    assert stats.aborted.get("ruckig_error", 0) == 1
    assert stats.errors["ruckig_error"] >= 1
    assert commands[-1].phase in (Phase.RETURN, Phase.IDLE, Phase.LIFT)
    assert commands[-1].target_id is None


def test_ik_failure_aborts_and_brakes_within_the_limits() -> None:
    config = ControllerConfig()
    controller = PickController(config)

    def tracks_at(t_s: float) -> tuple[Track, ...]:
        # The estimate jumps far beyond the arm's reach after the target was chosen.
        return (_track(-0.45, t_s, y=0.5 if t_s < 0.1 else 1.4),)

    commands = _drive(controller, tracks_at, 300)
    stats = controller.stats()
    assert stats.targeted >= 1
    assert stats.aborted.get("ik_failure", 0) >= 1
    assert stats.errors["ik_failure"] >= 1
    failed = next(i for i, c in enumerate(commands) if c.target_id is None and i > 0)
    # Through the IK failures the joints slow down within their datasheet acceleration (the
    # arm cannot stop dead) and stay inside their limits.
    kin = controller.kinematics
    q = np.array([c.joint_positions_rad for c in commands[failed - 5 : failed + 5]])
    dt_s = config.motion.control_period_s
    accel = np.asarray(config.robot.joint_max_acceleration_rps2)
    assert np.all(np.abs(np.diff(q, 2, axis=0)) <= accel * dt_s * dt_s * (1 + 1e-9))
    assert all(kin.within_limits(row) for row in q)


def test_lost_target_aborts_the_approach() -> None:
    controller = PickController(ControllerConfig())

    def tracks_at(t_s: float) -> tuple[Track, ...]:
        return (_track(-0.45, t_s),) if t_s < 0.05 else ()

    commands = _drive(controller, tracks_at, 200)
    assert controller.stats().aborted == {"target_lost": 1}
    assert commands[-1].target_id is None
    # the node's warning quotes what was aborted, where and when
    assert controller.last_error.startswith("target_lost in approach at t=")
    assert controller.last_error.endswith("track 1 (wood)")


def test_grasp_yaw_is_across_the_narrow_side() -> None:
    period = ControllerConfig().tool.grasp_yaw_period_rad
    assert period == math.pi  # a parallel gripper grasps alike at yaw and yaw + pi
    assert nearest_grasp_yaw(0.2, math.pi / 2, period) == pytest.approx(0.2)
    assert nearest_grasp_yaw(-1.4, math.pi / 2, period) == pytest.approx(-1.4 + math.pi)
    # The tool's finger axis (sin yaw, -cos yaw) is perpendicular to the object's long side.
    yaw = nearest_grasp_yaw(0.7, 1.5, period)
    finger_axis = (math.sin(yaw), -math.cos(yaw))
    long_side = (math.cos(0.7), math.sin(0.7))
    assert abs(finger_axis[0] * long_side[0] + finger_axis[1] * long_side[1]) < 1e-12


def test_fast_object_from_upstream_is_met_inside_the_window() -> None:
    """At 0.6 m/s from far upstream: no descent before the object is under the fingers."""
    config = ControllerConfig()
    controller = PickController(config)
    x0, vx = -1.3, 0.6
    dt_s = config.motion.control_period_s
    commands = _drive(
        controller, lambda t: (_track(x0, t, vx=vx),), ticks=360, belt=(vx, 0.0), dt_s=dt_s
    )
    x_min = config.pick_window_x_m[0]
    following = [c for c in commands if c.phase in (Phase.APPROACH, Phase.DESCEND, Phase.DWELL)]
    assert any(c.phase == Phase.DWELL for c in following)
    for c in following:
        assert c.setpoint.position_m[0] >= x_min - 1e-6, "the arm never chases upstream"
    first_descend = next(c for c in commands if c.phase == Phase.DESCEND)
    object_x = x0 + vx * first_descend.t_s
    assert object_x >= x_min
    assert abs(first_descend.setpoint.position_m[0] - object_x) < 0.02


@pytest.mark.parametrize("approach_space", ["cartesian", "joint"])
def test_a_controller_on_another_station_picks_in_its_window_and_drops_in_its_bin(
    approach_space: str,
) -> None:
    """The upstream station of the two-Panda cell stands at x = -1.5: its ready pose, pick
    window and bins are the cell file's, in world coordinates, and the kinematic closed loop
    picks an object inside that window and releases it over that station's bin."""
    base = ControllerConfig(cell=load_cell("two_pandas"), station_name="upstream")
    config = replace(base, pick=replace(base.pick, approach_space=approach_space))
    assert config.ready_tcp_position_m == pytest.approx((-1.8, 0.5, 0.2), abs=1e-12)
    assert config.pick_window_x_m == (-1.85, -1.15)
    assert config.bins["brick"] == (-1.83, 0.07, 0.15)
    x0, speed = -2.3, 0.4
    result = run_episode(
        speed, seed=2, duration_s=7.0, config=config, obj=ObjectSpec(x0_m=x0), gripper=GripperSpec()
    )
    assert result.stats.completed_by_class == {"brick": 1}
    assert result.stats.aborted == {}
    assert result.max_follow_error_m < 0.004
    starts = {phase: t for t, phase in reversed(result.phases)}
    x_min, x_max = config.pick_window_x_m
    assert x_min <= x0 + speed * starts[Phase.DWELL] < x0 + speed * starts[Phase.LIFT] <= x_max
    assert result.release_tcp_m is not None
    bx, by, _ = config.bins["brick"]
    x, y, _ = result.release_tcp_m
    assert abs(x - bx) <= config.pick.drop_tolerance_m + 1e-3
    assert abs(y - by) <= config.pick.drop_tolerance_m + 1e-3
    assert result.max_joint_limit_violation_rad == 0.0


def _station_config(robot: str, tool: str) -> ControllerConfig:
    """The reference cell with its station's robot and tool replaced by catalog names."""
    path = resolve_cell_path("default")
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    data["stations"][0].update(robot=robot, tool=tool)
    return ControllerConfig(cell=cell_from_data(data, str(path), base_dir=path.parent))


@pytest.mark.parametrize(
    ("robot", "tool"),
    [
        ("panda", "suction_cup"),
        ("panda", "wide_gripper"),
        ("ur10", "suction_cup"),
        ("ur10", "wide_gripper"),
    ],
)
def test_the_controller_picks_with_flange_tools_on_the_panda_and_the_ur10(
    robot: str, tool: str
) -> None:
    """The station URDF's tool frame and the tool's own grasp (a cup seals on the top, a wide
    gripper closes around a 10 cm block the Panda hand cannot take) pick the object and drop
    it in its bin, within the joint limits."""
    config = _station_config(robot, tool)
    obj = ObjectSpec(width_m=0.1, length_m=0.16, height_m=0.05)
    result = run_episode(0.4, seed=2, duration_s=7.0, config=config, obj=obj, gripper=GripperSpec())
    assert result.stats.completed_by_class == {"brick": 1}
    assert result.stats.aborted == {}
    assert result.stats.errors == {}
    assert result.max_joint_limit_violation_rad == 0.0
    assert result.release_tcp_m is not None
    bx, by, _ = config.bins["brick"]
    assert abs(result.release_tcp_m[0] - bx) <= config.pick.drop_tolerance_m + 1e-3
    assert abs(result.release_tcp_m[1] - by) <= config.pick.drop_tolerance_m + 1e-3


def test_a_suction_cup_that_does_not_seal_aborts_and_carries_nothing() -> None:
    config = _station_config("panda", "suction_cup")
    obj = ObjectSpec(width_m=0.1, length_m=0.16, height_m=0.05)
    result = run_episode(
        0.4, seed=2, duration_s=7.0, config=config, obj=obj, gripper=GripperSpec(grippable=False)
    )
    assert result.stats.completed_by_class == {}
    assert result.stats.aborted.get("grip_missed", 0) >= 1
    assert Phase.CARRY not in [phase for _, phase in result.phases]


def _drive_cup(
    controller: PickController,
    tracks_at: Callable[[float], tuple[Track, ...]],
    ticks: int,
    vacuum_at: Callable[[float, list[Command]], float],
    belt: tuple[float, float] = (0.4, 0.0),
) -> list[Command]:
    """:func:`_drive` with a suction cup whose measured vacuum is ``vacuum_at(t_s, commands so
    far)`` while the vacuum is commanded on (0 while it is off)."""
    kin = controller.kinematics
    dt_s = 1.0 / 120.0
    q = controller.q_ready
    commands: list[Command] = []
    for k in range(ticks):
        t_s = k * dt_s
        pose = kin.fk(q)
        x, y, z = (float(v) for v in pose.translation)
        on = bool(commands) and commands[-1].tool_command >= 0.5
        vacuum = vacuum_at(t_s, commands) if on else 0.0
        measured = TcpMeasurement(position_m=(x, y, z), yaw_rad=yaw_of(pose), tool_measured=vacuum)
        command = controller.update(t_s, measured, tracks_at(t_s), belt)
        q = np.asarray(command.joint_positions_rad)
        assert kin.within_limits(q)
        commands.append(command)
    return commands


def _first(commands: list[Command], phase: Phase) -> Command:
    return next(c for c in commands if c.phase == phase)


def _slab(t_s: float) -> Track:
    """:func:`_track` wide enough for the suction cup's lip (8 cm)."""
    return replace(_track(-0.45, t_s, y=0.5), width_m=0.08)


def test_a_cup_lifts_only_once_its_vacuum_is_full() -> None:
    """A seal made late in the close: the vacuum is still building up (above the threshold of
    "holds nothing") when ``close_s`` ends. The twin holds the object only once the vacuum is
    full; the cup waits for that and then lifts, with no abort."""
    config = _station_config("panda", "suction_cup")
    controller = PickController(config)
    tool = config.station.tool
    assert isinstance(tool, SuctionCupSpec)
    late_s = config.timing.close_s + 0.5 * tool.build_up_s  # full this long after the close began

    def vacuum_at(t_s: float, commands: list[Command]) -> float:
        close = next((c.t_s for c in commands if c.phase == Phase.CLOSE), None)
        if close is None:
            return 0.0
        return 1.0 if t_s >= close + late_s else 0.5

    commands = _drive_cup(controller, lambda t: (_slab(t),), 420, vacuum_at)
    close, lift = _first(commands, Phase.CLOSE), _first(commands, Phase.LIFT)
    assert lift.t_s - close.t_s >= late_s
    assert lift.t_s - close.t_s <= late_s + 2.0 / 120.0
    assert controller.stats().aborted == {}
    assert Phase.CARRY in [c.phase for c in commands]


def _searching_cup(search_m: float) -> ControllerConfig:
    config = _station_config("panda", "suction_cup")
    return replace(config, pick=replace(config.pick, seal_search_m=search_m))


def test_a_cup_that_finds_no_top_where_it_was_seen_goes_lower_until_it_seals() -> None:
    """The top lies 8 mm below where it was seen: the cup reads no vacuum at the grasp point.
    With a 12 mm seal search the setpoint goes down (the arm has caught up: the measured TCP
    is the commanded one here) until the lip touches, then stops there and lifts once the
    vacuum is full: a pick, not a miss; never more than the search's depth lower."""
    config = _searching_cup(0.012)
    controller = PickController(config)
    start: list[float] = []
    touched: list[float] = []

    def vacuum_at(t_s: float, commands: list[Command]) -> float:
        last = commands[-1]
        if last.phase != Phase.CLOSE and not touched:
            return 0.0
        if not start:
            assert last.grasp_point_m is not None
            start.append(last.grasp_point_m[2])
        if not touched and last.setpoint.position[2] <= start[0] - 0.008:
            touched.append(t_s)
        return 0.0 if not touched else min(1.0, (t_s - touched[0]) / 0.15)

    commands = _drive_cup(controller, lambda t: (_slab(t),), 600, vacuum_at)
    closing = [c.setpoint.position[2] for c in commands if c.phase == Phase.CLOSE]
    assert start
    lowest_below_m = start[0] - min(closing)
    assert 0.008 <= lowest_below_m <= 0.010  # the lip's touch is read a tick or two later
    assert controller.stats().aborted == {}
    assert Phase.CARRY in [c.phase for c in commands]


def test_a_cup_that_never_seals_searches_at_most_its_depth_and_time_then_misses() -> None:
    config = _searching_cup(0.012)
    controller = PickController(config)
    commands = _drive_cup(controller, lambda t: (_slab(t),), 600, lambda t, c: 0.0)
    closing = [c for c in commands if c.phase == Phase.CLOSE]
    assert controller.stats().aborted == {"grip_missed": 1}
    grasp = closing[0].grasp_point_m
    assert grasp is not None
    depth_m = grasp[2] - min(c.setpoint.position[2] for c in closing)
    assert 0.010 <= depth_m <= 0.012 + 1e-4
    close_s = closing[-1].t_s - closing[0].t_s
    pick = config.pick
    assert close_s <= config.timing.close_s + pick.seal_search_max_s + 2.0 / 120.0
    assert close_s >= config.timing.close_s + pick.seal_search_max_s - 2.0 / 120.0


def test_a_cup_that_holds_the_object_lifts_it_and_carries_it_to_its_bin_whatever_else() -> None:
    """The vacuum is full during the descent (the lip sealed as it touched): the cup lifts at
    once, without waiting for the close; and the object, held, is carried to its bin, never
    let go away from a bin, even though the target then passes the pick window's end (which
    aborts a pick that holds nothing)."""
    config = _station_config("panda", "suction_cup")
    controller = PickController(config)
    x_max = config.pick_window_x_m[1]
    descended: list[float] = []

    def vacuum_at(t_s: float, commands: list[Command]) -> float:
        if commands[-1].phase == Phase.DESCEND and not descended:
            descended.append(t_s)
        return 1.0 if descended and t_s >= descended[0] + 0.05 else 0.0

    def tracks_at(t_s: float) -> tuple[Track, ...]:
        track = _slab(t_s)
        if descended and t_s >= descended[0] + 0.05:  # the estimate jumps past the window
            track = replace(track, position_m=(x_max + 0.1, track.position_m[1]))
        return (track,)

    commands = _drive_cup(controller, tracks_at, 500, vacuum_at)
    phases = [c.phase for c in commands]
    assert Phase.CLOSE not in phases
    lift = _first(commands, Phase.LIFT)
    assert lift.t_s - descended[0] <= 0.05 + 2.0 / 120.0
    assert Phase.CARRY in phases
    carried = [c for c in commands if lift.t_s <= c.t_s < _first(commands, Phase.RELEASE).t_s]
    assert all(c.tool_command == 1.0 for c in carried)  # the vacuum stays on to the bin
    assert controller.stats().aborted == {}
    assert controller.stats().completed_by_class == {"wood": 1}


def _fast_cup_config(margin: float) -> ControllerConfig:
    """A Panda with the suction cup told to descend at 5 m/s^2 (jerk 1500 m/s^3), with
    ``motion.posture_acceleration_margin`` ``margin``."""
    config = _station_config("panda", "suction_cup")
    motion = replace(
        config.motion,
        max_acceleration=(5.0, 5.0, 5.0, 20.0),
        max_jerk=(1500.0, 1500.0, 1500.0, 2000.0),
        posture_acceleration_margin=margin,
    )
    return replace(config, motion=motion)


def _below_grasp_point_m(margin: float) -> tuple[float, int]:
    """How far below the grasp point the joint commands go, in the descent and the seal (NaN:
    the cup never got to descend), for an object near the base (0.35 m out, where a vertical
    tool's height takes the shoulder's and elbow's largest accelerations), and how many joint
    commands were slowed to the velocity limits."""
    controller = PickController(_fast_cup_config(margin))

    def near_base(t_s: float) -> tuple[Track, ...]:
        return (replace(_track(-0.8, t_s, y=0.35), width_m=0.08),)

    commands = _drive_cup(controller, near_base, 480, lambda t, c: 0.0)
    kin = controller.kinematics
    below = [
        c.grasp_point_m[2] - float(kin.fk(np.asarray(c.joint_positions_rad)).translation[2])
        for c in commands
        if c.phase in (Phase.DESCEND, Phase.CLOSE) and c.grasp_point_m is not None
    ]
    return (max(below) if below else math.nan), controller.stats().rate_limited


def test_a_descent_near_the_base_keeps_to_what_the_joints_can_follow() -> None:
    """Near the base a 5 m/s^2 approach and descent ask the shoulder and elbow for more than
    their datasheet accelerations: the joint commands are slowed to the limits and lag, and
    then either overshoot the grasp point by centimetres catching up (the lip presses the
    object into the belt) or never catch up with the object before it leaves the window (which
    of the two depends on the last digits of the arithmetic). With the posture margin the
    motion is planned within what the joints can follow: no command is slowed, and the
    commands stay on the grasp point."""
    below_m, slowed = _below_grasp_point_m(0.0)
    assert slowed > 0
    assert math.isnan(below_m) or below_m > 0.01
    below_m, slowed = _below_grasp_point_m(0.8)
    assert slowed == 0
    assert below_m < 0.002


def test_an_idle_station_that_found_nothing_looks_again_after_its_replan_period(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``scheduler.replan_period_s``: no target in sight, the scheduler runs once per period,
    not at every control update; 0 (the default) keeps every update."""
    import control.phases as pick_module  # the phase machine calls the scheduler

    calls: list[float] = []
    original = pick_module.schedule

    def counting(*args: Any, **kwargs: Any) -> Any:
        calls.append(float(kwargs["now_s"]))
        return original(*args, **kwargs)

    monkeypatch.setattr(pick_module, "schedule", counting)
    base = _station_config("panda", "suction_cup")
    for period_s, expected in ((0.0, 120), (0.05, 20)):
        config = replace(base, scheduler=replace(base.scheduler, replan_period_s=period_s))
        calls.clear()
        _drive_cup(PickController(config), lambda t: (), 120, lambda t, c: 0.0)
        assert len(calls) == pytest.approx(expected, abs=1)
