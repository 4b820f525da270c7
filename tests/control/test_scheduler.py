"""Scheduling: priorities, urgency and the reason for every untargeted object."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from control.config import ControllerConfig, SchedulerConfig
from control.errors import ControlConfigError
from control.scheduler import (
    approach_time_s,
    blocked_by,
    descend_after_s,
    estimated_mass_kg,
    grasp_height_m,
    grasp_z_m,
    move_time_s,
    schedule,
    unsettled,
    yaw_turn_s,
)
from control.tracking import Track
from interfaces.cell import load_cell
from interfaces.tools import SuctionCupSpec
from interfaces.untargeted import UNTARGETED_REASONS

TCP = (0.0, 0.45, 0.30)


def _track(
    track_id: int,
    x: float,
    *,
    y: float = 0.5,
    width: float = 0.05,
    vx: float = 0.2,
    height: float = 0.04,
    **fields: Any,
) -> Track:
    """A confirmed brick at ``(x, y)``; ``fields`` replace other fields of the track."""
    track = Track(
        track_id=track_id,
        stamp_s=0.0,
        class_name="brick",
        class_confidence=1.0,
        position_m=(x, y),
        velocity_mps=(vx, 0.0),
        position_std_m=0.001,
        yaw_rad=0.0,
        length_m=max(0.12, width),
        width_m=width,
        height_m=height,
        hits=10,
        confirmed=True,
        last_update_s=0.0,
    )
    return replace(track, **fields)


def _reasons(result_untargeted: tuple[object, ...]) -> dict[int, str]:
    return {u.track_id: u.reason for u in result_untargeted}  # type: ignore[attr-defined]


def test_every_untargeted_object_has_its_reason() -> None:
    config = ControllerConfig()
    tracks = [
        _track(1, -0.2),
        _track(2, -0.15, y=0.3, width=0.09),
        _track(3, -0.1, y=0.95),
        _track(4, 0.3),
        _track(5, -1.5),
        _track(6, -0.1, class_confidence=0.1),
        _track(7, 0.0),
        _track(8, -0.05, y=0.3),
    ]
    result = schedule(tracks, now_s=0.0, tcp_position_m=TCP, config=config, excluded_ids={8})
    reasons = _reasons(result.untargeted)
    assert result.target is not None
    assert result.target.track_id == 7
    assert reasons == {
        1: "lower_priority",
        2: "too_wide",
        3: "out_of_reach",
        4: "too_late",
        5: "upstream",
        6: "low_confidence",
        8: "excluded",
    }
    assert set(reasons.values()) <= set(UNTARGETED_REASONS)
    # From TCP the tool goes 0.22 m down to 6 cm above track 7, then 6 cm down to its grasp
    # point; at the Cartesian 2.5 m/s^2 the Panda's joints 2 and 4 can follow (datasheet 7.5 and
    # 12.5 rad/s^2: 3.1-4.4 m/s^2 vertically at these poses) that is at least
    # 2 sqrt(0.22 / 2.5) + 2 sqrt(0.06 / 2.5) = 0.90 s before the time margin.
    assert 0.9 < result.intercept_s < 1.2
    assert math.isclose(result.time_left_s, (0.35 - 0.0) / 0.2)


def test_class_priority_beats_urgency() -> None:
    priorities = {"concrete": 1.0, "brick": 1.0, "wood": 5.0, "rubber": 1.0}
    config = ControllerConfig(scheduler=SchedulerConfig(class_priorities=priorities))
    tracks = [_track(1, 0.0), _track(2, -0.2, class_name="wood")]
    result = schedule(tracks, now_s=0.0, tcp_position_m=TCP, config=config)
    assert result.target is not None
    assert result.target.track_id == 2
    assert _reasons(result.untargeted) == {1: "lower_priority"}


def test_narrow_side_decides_graspability() -> None:
    config = ControllerConfig()
    tool = config.station.tool
    limit = tool.max_opening_m - config.scheduler.grasp_width_margin_m
    long_thin = _track(1, -0.1, width=limit - 0.001)
    result = schedule([long_thin], now_s=0.0, tcp_position_m=TCP, config=config)
    assert result.target is not None
    wide = _track(2, -0.1, width=limit + 0.001)
    result = schedule([wide], now_s=0.0, tcp_position_m=TCP, config=config)
    assert result.target is None
    assert _reasons(result.untargeted) == {2: "too_wide"}


def test_a_neighbour_where_the_fingers_come_down_blocks_the_pick() -> None:
    config = ControllerConfig()
    tool = config.station.tool
    sched = config.scheduler
    reach = tool.max_opening_m / 2 + tool.finger_depth_m + sched.clearance_m
    target = _track(1, -0.1)
    # neighbours across the narrow side (y), footprints 5 cm wide: one reaches into the
    # keep-out rectangle by 1 mm, the other stays 1 mm clear of it
    inside = _track(2, -0.1, y=0.5 + reach + 0.025 - 0.001)
    outside = _track(3, -0.1, y=0.5 + reach + 0.025 + 0.001)
    # along the long side (x) the fingers need only their own width plus the clearance
    ahead = _track(4, -0.1 + 0.06 + tool.finger_width_m / 2 + sched.clearance_m + 0.001)
    result = schedule([target, inside], now_s=0.0, tcp_position_m=TCP, config=config)
    assert result.target is None  # same widths: each is in the other's keep-out rectangle
    assert _reasons(result.untargeted) == {1: "blocked", 2: "blocked"}
    for clear in (outside, ahead):
        result = schedule([target, clear], now_s=0.0, tcp_position_m=TCP, config=config)
        assert "blocked" not in _reasons(result.untargeted).values()


def test_a_tall_neighbour_under_the_hand_blocks_the_pick() -> None:
    config = ControllerConfig()
    tool = config.station.tool
    sched = config.scheduler
    fingers = tool.max_opening_m / 2 + tool.finger_depth_m + sched.clearance_m
    hand = tool.hand_width_m / 2 + sched.clearance_m
    target = _track(1, -0.1)
    # across the jaw, clear of the fingers but under the hand (footprints 5 cm wide)
    y = 0.5 + fingers + 0.025 + 0.005
    assert y - 0.025 < 0.5 + hand
    palm_z = grasp_z_m(target.height_m, config) + tool.palm_above_tcp_m - sched.clearance_m
    low = _track(2, -0.1, y=y, height=palm_z - config.belt.surface_z_m - 0.002)
    tall = _track(3, -0.1, y=y, height=palm_z - config.belt.surface_z_m + 0.002)
    beyond = _track(4, -0.1, y=0.5 + hand + 0.025 + 0.002, height=0.2)
    assert blocked_by(target, [target, low], config) is None
    assert blocked_by(target, [target, tall], config) == 3
    assert blocked_by(target, [target, beyond], config) is None


def test_unknown_class_has_no_bin_and_nothing_is_targeted_when_empty() -> None:
    config = ControllerConfig()
    result = schedule(
        [_track(1, -0.1, class_name="glass")], now_s=0.0, tcp_position_m=TCP, config=config
    )
    assert result.target is None
    assert _reasons(result.untargeted) == {1: "no_bin"}
    empty = schedule([], now_s=0.0, tcp_position_m=TCP, config=config)
    assert empty.target is None
    assert empty.untargeted == ()


def test_move_time_is_monotonic_and_bounded() -> None:
    times = [move_time_s(d, 0.8, 12.0, 300.0) for d in np.linspace(0.0, 1.0, 400)]
    assert times == sorted(times)
    assert times[0] == 0.0
    assert times[-1] >= 1.0 / 0.8


def test_intercept_is_the_earliest_feasible_meeting() -> None:
    config = ControllerConfig()
    motion = config.motion
    v, a, j = motion.max_velocity[0], motion.max_acceleration[0], motion.max_jerk[0]
    ready = config.ready_tcp_position_m
    z = grasp_height_m(_track(1, 0.0), config) + config.pick.approach_height_m

    def move_s(track: Track, t_s: float) -> float:
        x, y = track.position_at(t_s)
        vx = track.velocity_mps[0]
        # meeting it moving against it (upstream of the TCP), the TCP turns round: |vx| / a more
        turn_s = abs(vx) / a if (x - ready[0]) * vx < 0.0 else 0.0
        return move_time_s(math.dist(ready, (x, y, z)), v, a, j) + turn_s

    for x0, vx in ((-1.2, 0.6), (-0.8, 0.4), (-0.5, 0.2), (0.2, 0.6), (-0.15, 0.0)):
        track = _track(1, x0, vx=vx)
        t_s = approach_time_s(track, 0.0, ready, config)
        assert move_s(track, t_s) <= t_s + 1e-12, (x0, vx)
        # nothing earlier works: checked on a fine grid below the answer
        for early in np.arange(0.0, t_s - 2e-3, 1e-3):
            assert move_s(track, float(early)) > early, (x0, vx, early)


def test_fast_object_far_upstream_is_not_targeted_before_it_can_be_met_in_the_window() -> None:
    config = ControllerConfig()
    ready = config.ready_tcp_position_m
    track = _track(1, -1.2, vx=0.6)
    result = schedule([track], now_s=0.0, tcp_position_m=ready, config=config)
    assert result.target is None
    assert _reasons(result.untargeted) == {1: "upstream"}
    # once it is close enough, it is targeted and the meeting point is inside the window
    for x0 in np.arange(-1.2, -0.3, 0.01):
        near = _track(1, float(x0), vx=0.6)
        result = schedule([near], now_s=0.0, tcp_position_m=ready, config=config)
        if result.target is not None:
            break
    assert result.target is not None
    meet_s = approach_time_s(result.target, 0.0, ready, config)
    x_meet, _ = result.target.position_at(meet_s)
    x_min, x_max = config.pick_window_x_m
    assert x_min <= x_meet <= x_max
    assert x_meet - x_min < 0.6 * 0.02, "targeted as soon as the meeting point enters the window"


def test_an_object_lying_on_another_is_grasped_at_its_own_height() -> None:
    config = ControllerConfig()
    tool = config.station.tool
    on_belt = _track(1, -0.1)
    stacked = _track(2, -0.1, base_z_m=config.belt.surface_z_m + 0.05)
    below_surface = _track(3, -0.1, base_z_m=config.belt.surface_z_m - 0.001)
    assert grasp_height_m(on_belt, config) == grasp_z_m(0.04, config)
    assert grasp_height_m(stacked, config) == pytest.approx(grasp_z_m(0.04, config) + 0.05)
    assert grasp_height_m(below_surface, config) == grasp_z_m(0.04, config)
    # a low object lying on another reaches the palm of a hand grasping a neighbour
    sched = config.scheduler
    fingers = tool.max_opening_m / 2 + tool.finger_depth_m + sched.clearance_m
    y = 0.5 + fingers + 0.025 + 0.005
    low = _track(4, -0.1, y=y, height=0.03)
    raised = _track(5, -0.1, y=y, height=0.03, base_z_m=config.belt.surface_z_m + 0.05)
    assert blocked_by(on_belt, [on_belt, low], config) is None
    assert blocked_by(on_belt, [on_belt, raised], config) == 5


def test_the_tool_turn_to_the_grasp_yaw_delays_the_meeting() -> None:
    config = ControllerConfig()
    pick, motion = config.pick, config.motion
    ready = config.ready_tcp_position_m
    track = _track(1, -0.2, vx=0.3)  # grasp yaws 0 and pi
    aligned = approach_time_s(track, 0.0, ready, config, tcp_yaw_rad=0.0)
    assert aligned == approach_time_s(track, 0.0, ready, config)
    assert approach_time_s(track, 0.0, ready, config, tcp_yaw_rad=math.pi) == aligned
    # a quarter turn: the descent may begin descend_yaw_lead_s before the turn ends
    quarter_s = move_time_s(
        math.pi / 2, motion.max_velocity[3], motion.max_acceleration[3], motion.max_jerk[3]
    )
    assert yaw_turn_s(track, math.pi / 2, config) == pytest.approx(
        quarter_s - pick.descend_yaw_lead_s
    )
    turned = approach_time_s(track, 0.0, ready, config, tcp_yaw_rad=math.pi / 2)
    assert turned >= quarter_s - pick.descend_yaw_lead_s
    assert turned > aligned
    # the nearer of the two grasp yaws counts: a turn of 0.1 rad either way is the same
    assert yaw_turn_s(track, 0.1, config) == pytest.approx(yaw_turn_s(track, math.pi - 0.1, config))


def test_a_suction_cup_targets_only_objects_it_holds_inside_the_window() -> None:
    """The twin grants a grasp only inside the station's pick window, and a cup holds the
    object only once its vacuum has built up, ``close_s`` after it reached the top: objects met
    near the window's end, whose hold would come after they left it, are ``too_late``; every
    target is held inside the window."""
    config = ControllerConfig(cell=load_cell("suction"))
    timing = config.timing
    assert timing.dwell_s == 0.0
    held_after_s = timing.close_s  # the build-up and its margin
    assert held_after_s > 0.0
    x_max = config.pick_window_x_m[1]
    met_inside_but_late = 0
    for x in np.arange(-0.3, x_max, 0.005):
        track = _track(1, float(x), vx=0.4, width=0.08)
        result = schedule([track], now_s=0.0, tcp_position_m=TCP, config=config)
        intercept_s = approach_time_s(track, 0.0, TCP, config) + descend_after_s(config)
        if result.target is not None:
            assert track.position_at(result.intercept_s + held_after_s)[0] <= x_max
        elif track.position_at(intercept_s)[0] <= x_max:
            assert _reasons(result.untargeted) == {1: "too_late"}
            met_inside_but_late += 1
    assert met_inside_but_late > 0


def test_an_object_nearer_the_base_than_the_least_reach_is_out_of_reach() -> None:
    """A suction cup on its 15 cm stem, held vertical, cannot follow the belt at the belt's
    near edge in front of the base (the arm would fold beyond its joint limits): with
    ``min_reach_m`` such an object is ``out_of_reach``, one further out still a target."""
    base = ControllerConfig(cell=load_cell("suction"))
    config = replace(base, scheduler=replace(base.scheduler, min_reach_m=0.3))
    near, far = _track(1, -0.1, y=0.22, width=0.08), _track(2, -0.1, y=0.45, width=0.08)
    assert _reasons(schedule([near], now_s=0.0, tcp_position_m=TCP, config=base).untargeted) == {}
    result = schedule([near], now_s=0.0, tcp_position_m=TCP, config=config)
    assert result.target is None
    assert _reasons(result.untargeted) == {1: "out_of_reach"}
    target = schedule([far], now_s=0.0, tcp_position_m=TCP, config=config).target
    assert target is not None
    assert target.track_id == 2


def test_the_density_of_the_too_heavy_check_is_the_cells_class_tables() -> None:
    """``scheduler.check_mass`` estimates a piece's mass with its class's density in the cell's
    class table (what a run's resolved cell carries: the dataset's). ``tiles`` is a class only
    the table gives a density (no parameter file names it): a cup leaves a tiles piece too heavy
    by that density and takes one 10 % lighter; without ``check_mass`` it checks no mass; an
    explicit ``class_density_kg_m3`` overrides the table's."""
    from interfaces.cell import resolve_cell
    from interfaces.materials import table_from_data

    table = table_from_data(
        {"classes": {"tiles": {"density_kg_m3": 3000.0, "seal_efficiency": 0.5}}},
        "test table",
        load_cell("suction").materials,
    )
    cell = resolve_cell(load_cell("suction"), table)
    assert cell.classes == ("tiles",)
    base = ControllerConfig(cell=cell)
    checked = replace(
        base,
        scheduler=replace(
            base.scheduler, check_mass=True, fill_fraction=1.0, carry_acceleration_mps2=10.0
        ),
    )
    cup = base.station.tool
    assert isinstance(cup, SuctionCupSpec)
    most_kg = cup.holding_force("tiles", table) / (9.81 + 10.0)
    assert most_kg == pytest.approx(60e3 * math.pi * 0.02**2 * 0.5 / 19.81)  # the table's eta
    box_m3 = 0.12 * 0.08
    heavy = _track(1, -0.1, width=0.08, height=1.1 * most_kg / 3000.0 / box_m3, class_name="tiles")
    light = _track(2, -0.1, width=0.08, height=0.9 * most_kg / 3000.0 / box_m3, class_name="tiles")
    assert estimated_mass_kg(heavy, checked) == pytest.approx(1.1 * most_kg)
    assert estimated_mass_kg(heavy, base) is None
    result = schedule([heavy], now_s=0.0, tcp_position_m=TCP, config=checked)
    assert _reasons(result.untargeted) == {1: "too_heavy"}
    target = schedule([light], now_s=0.0, tcp_position_m=TCP, config=checked).target
    assert target is not None
    assert target.track_id == 2
    assert schedule([heavy], now_s=0.0, tcp_position_m=TCP, config=base).target is not None
    lighter = replace(
        checked, scheduler=replace(checked.scheduler, class_density_kg_m3={"tiles": 1000.0})
    )
    assert estimated_mass_kg(heavy, lighter) == pytest.approx(1.1 * most_kg / 3.0)


def test_a_cup_leaves_an_object_it_could_not_carry() -> None:
    """With the classes' densities, a cup leaves (``too_heavy``) an object whose estimated mass
    (seen box x fill x density) its holding force on that class could not carry at gravity
    plus the carry's acceleration; a lighter one it targets. Without densities it targets
    both (no estimate)."""
    base = ControllerConfig(cell=load_cell("suction"))
    cup = base.station.tool
    assert isinstance(cup, SuctionCupSpec)
    dense = replace(
        base.scheduler,
        class_density_kg_m3={"brick": 1900.0},
        fill_fraction=1.0,
        carry_acceleration_mps2=10.0,
    )
    config = replace(base, scheduler=dense)
    most_kg = cup.holding_force("brick", base.cell.materials) / (9.81 + 10.0)
    box_m3 = 0.12 * 0.08  # the tracks' footprint: 12 x 8 cm
    light_h, heavy_h = 0.9 * most_kg / 1900.0 / box_m3, 1.1 * most_kg / 1900.0 / box_m3
    light = _track(1, -0.1, width=0.08, height=light_h)
    heavy = _track(2, -0.1, width=0.08, height=heavy_h)
    assert estimated_mass_kg(heavy, config) == pytest.approx(1.1 * most_kg)
    assert estimated_mass_kg(heavy, base) is None
    result = schedule([heavy], now_s=0.0, tcp_position_m=TCP, config=config)
    assert result.target is None
    assert _reasons(result.untargeted) == {2: "too_heavy"}
    target = schedule([light], now_s=0.0, tcp_position_m=TCP, config=config).target
    assert target is not None
    assert target.track_id == 1
    assert schedule([heavy], now_s=0.0, tcp_position_m=TCP, config=base).target is not None


def test_a_cup_leaves_a_propped_piece_whose_face_is_tilted_beyond_its_lip() -> None:
    """The camera reports the tilt of the face at the suction point: beyond the lip's limit
    (less the margin) the cup leaves the piece (``too_tilted``) for a station downstream; a
    level piece beside it is its target."""
    config = ControllerConfig(cell=load_cell("suction"))
    cup = config.station.tool
    assert isinstance(cup, SuctionCupSpec)
    face = {"suction_radius_m": 0.035, "suction_offset_m": (0.0, 0.0)}
    propped = replace(_track(1, -0.1, width=0.08), **face, suction_tilt_rad=cup.max_tilt_rad + 0.05)
    level = replace(_track(2, -0.3, width=0.08), **face, suction_tilt_rad=0.02)
    result = schedule([propped, level], now_s=0.0, tcp_position_m=TCP, config=config)
    assert _reasons(result.untargeted) == {1: "too_tilted"}
    assert result.target is not None
    assert result.target.track_id == 2


def test_a_track_moving_off_the_belts_speed_is_unsettled_when_the_line_says_so() -> None:
    """``scheduler.settle_tolerance_mps``: a track whose velocity differs from the belt's
    measured one by more than it (a young track's estimate, a piece still sliding) is not met
    yet; unset, every track counts as settled, and so does every track while the belt's
    velocity is unknown."""
    base = ControllerConfig()
    line = replace(base, scheduler=replace(base.scheduler, settle_tolerance_mps=0.08))
    young = _track(1, -0.3, vx=0.45)
    settled = _track(2, -0.3, vx=0.55)
    assert unsettled(young, (0.6, 0.0), line)
    assert not unsettled(settled, (0.6, 0.0), line)
    assert unsettled(replace(settled, velocity_mps=(0.6, 0.1)), (0.6, 0.0), line)  # sideways
    assert not unsettled(young, (0.6, 0.0), base)
    assert not unsettled(young, (math.nan, math.nan), line)
    assert "unsettled" in UNTARGETED_REASONS
    with pytest.raises(ControlConfigError, match="settle_tolerance_mps"):
        replace(base.scheduler, settle_tolerance_mps=0.0)
