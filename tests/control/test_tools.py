"""The controller's side of the tool: every number it plans with comes from the tool's spec."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from control.config import ControllerConfig
from control.errors import ControlConfigError
from control.scheduler import approach_z_m, blocked_by, grasp_height_m, schedule
from control.tools import Footprint, make_tool
from control.tracking import Track
from interfaces.cell import default_cell
from interfaces.materials import shipped_table
from interfaces.tools import ParallelJawSpec, tool_from_data

XARM = tool_from_data("xarm_gripper", "tool")
SHIPPED = shipped_table()
"""A parallel gripper other than the Panda hand: 85 mm opening, the spec's default pads."""


def _config_with_tool(tool: ParallelJawSpec) -> ControllerConfig:
    """The reference cell with its station carrying ``tool``."""
    cell = default_cell()
    station = replace(cell.stations[0], tool=tool)
    return ControllerConfig(cell=replace(cell, stations=(station,)))


def _track(track_id: int, y: float, *, width: float = 0.05, height: float = 0.04) -> Track:
    return Track(
        track_id=track_id,
        stamp_s=0.0,
        class_name="brick",
        class_confidence=1.0,
        position_m=(-0.1, y),
        velocity_mps=(0.2, 0.0),
        position_std_m=0.001,
        yaw_rad=0.0,
        length_m=max(0.12, width),
        width_m=width,
        height_m=height,
        hits=10,
        confirmed=True,
        last_update_s=0.0,
    )


def test_the_measured_opening_is_twice_the_mean_of_the_finger_joints() -> None:
    tool = make_tool(XARM, SHIPPED)
    assert tool.joint_names == XARM.joints
    a, b = XARM.joints
    assert tool.measured({a: 0.02, b: 0.03}) == pytest.approx(0.05)
    assert math.isnan(tool.measured({a: 0.02}))  # a finger missing
    assert math.isnan(tool.measured({a: 0.02, b: math.nan}))
    assert math.isnan(tool.measured({}))


def test_the_grasp_command_is_the_width_less_the_squeeze_within_the_opening() -> None:
    tool = make_tool(XARM, SHIPPED)
    assert tool.open_command == XARM.max_opening_m == 0.085
    assert tool.grasp_command(0.05, 0.01) == pytest.approx(0.04)
    assert tool.grasp_command(0.2, 0.01) == 0.085  # no wider than the opening
    assert tool.grasp_command(0.004, 0.01) == 0.0  # no narrower than closed
    assert tool.clip_command(0.09) == 0.085
    assert tool.clip_command(-0.01) == 0.0
    assert math.isnan(tool.clip_command(math.nan))


def test_fingers_closed_to_the_command_hold_nothing() -> None:
    tool = make_tool(XARM, SHIPPED)
    assert tool.holds_nothing(0.0405, 0.04, 0.001)  # closed to the command: nothing between
    assert not tool.holds_nothing(0.0415, 0.04, 0.001)  # held apart by an object
    assert not tool.holds_nothing(math.nan, 0.04, 0.001)  # not measured: no verdict


def test_what_fits_depends_on_the_spec() -> None:
    flat_pads = replace(XARM, pad_height_m=0.03)
    tool = make_tool(flat_pads, SHIPPED)
    limit = XARM.max_opening_m - 0.015
    fits = {"length_m": 0.12, "height_m": 0.04, "width_margin_m": 0.015}
    assert tool.misfit(width_m=limit - 1e-4, **fits) is None
    assert tool.misfit(width_m=limit + 1e-4, **fits) == "too_wide"
    # the narrow side counts, whichever the tracker called the length
    assert tool.misfit(length_m=0.05, width_m=0.3, height_m=0.04, width_margin_m=0.015) is None
    assert tool.misfit(length_m=0.12, width_m=0.05, height_m=0.029, width_margin_m=0.0) == (
        "too_flat"
    )
    assert tool.misfit(length_m=0.12, width_m=0.05, height_m=0.031, width_margin_m=0.0) is None


def test_the_blocking_footprints_come_from_the_spec() -> None:
    spec = replace(XARM, finger_width_m=0.03, finger_depth_m=0.02, hand_width_m=0.3)
    fingers, hand = make_tool(spec, SHIPPED).footprints(0.01)
    assert fingers == Footprint(
        half_along_m=0.015 + 0.01, half_across_m=0.0425 + 0.02 + 0.01, clear_above_tcp_m=None
    )
    assert hand == Footprint(
        half_along_m=spec.hand_depth_m / 2 + 0.01,
        half_across_m=0.15 + 0.01,
        clear_above_tcp_m=spec.palm_above_tcp_m,
    )


def test_the_scheduler_plans_with_the_stations_tool() -> None:
    """The same objects: a 70 mm wide one fits the xArm gripper (85 mm) but not the Panda hand
    (80 mm, less the 15 mm margin); a tall neighbour 0.16 m across the jaw is under a 40 cm hand
    but clear of the Panda's 21 cm one."""
    panda = ControllerConfig()
    xarm = _config_with_tool(XARM)
    wide = _track(1, 0.5, width=0.07)
    assert schedule([wide], now_s=0.0, tcp_position_m=(0.0, 0.45, 0.3), config=panda).target is None
    chosen = schedule([wide], now_s=0.0, tcp_position_m=(0.0, 0.45, 0.3), config=xarm).target
    assert chosen is not None
    assert chosen.track_id == 1
    target, tall = _track(1, 0.5), _track(2, 0.66, height=0.2)
    big_hand = _config_with_tool(replace(panda.station.tool, hand_width_m=0.4))
    assert blocked_by(target, [target, tall], panda) is None
    assert blocked_by(target, [target, tall], big_hand) == 2


def test_a_tool_kind_the_controller_does_not_know_is_refused() -> None:
    unknown = replace(XARM, kind="suction_cup")  # type: ignore[arg-type]
    with pytest.raises(ControlConfigError, match=r"tool\.kind = 'suction_cup'"):
        make_tool(unknown, SHIPPED)


def test_a_cup_fits_by_the_disc_the_camera_reports_on_the_top_and_grasps_at_its_centre() -> None:
    """A concave piece: its narrow side (6 cm) holds a 40 mm lip with the 15 mm margin, but
    the largest disc on its top is 3.5 cm across: too small. The cup aims at that disc's
    centre; without a reported disc it judges by the narrow side and aims at the centre."""
    cup = make_tool(tool_from_data("suction_cup", "tool"), SHIPPED)
    size = {"length_m": 0.2, "width_m": 0.06, "height_m": 0.03, "width_margin_m": 0.015}
    assert cup.misfit(**size) is None
    assert cup.misfit(**size, face_radius_m=0.0175) == "too_small"
    assert cup.misfit(**size, face_radius_m=0.028) is None
    assert cup.misfit(**{**size, "width_m": 0.05}) == "too_small"
    assert cup.fit_margin_m(**size, face_radius_m=0.03) == pytest.approx(0.06 - 0.04 - 0.015)
    track = replace(_track(1, 0.5), suction_offset_m=(-0.03, 0.01), suction_radius_m=0.03)
    assert cup.grasp_offset_m(track) == (-0.03, 0.01)
    assert cup.grasp_offset_m(_track(1, 0.5)) == (0.0, 0.0)
    jaws = make_tool(XARM, SHIPPED)
    assert jaws.misfit(**size, face_radius_m=0.001) == jaws.misfit(**size)


def test_jaws_close_about_the_centre_unless_it_may_lie_off_the_piece() -> None:
    """The jaws close about the object's centre while the centre lies inside the largest disc
    the camera reports on the top (the material is there); a bent piece's centre lies in its
    crook, further from the disc's centre than its radius, and the jaws close about the disc's
    centre instead (the piece is there). No disc reported: the centre."""
    jaws = make_tool(XARM, SHIPPED)
    level = _track(1, 0.5)
    inside = replace(level, suction_offset_m=(-0.02, 0.01), suction_radius_m=0.03)
    bent = replace(level, suction_offset_m=(-0.05, 0.02), suction_radius_m=0.025)
    assert jaws.grasp_offset_m(inside) == (0.0, 0.0)
    assert jaws.grasp_offset_m(bent) == (-0.05, 0.02)
    assert jaws.grasp_offset_m(level) == (0.0, 0.0)


def test_cup_and_jaws_go_down_to_the_suction_point_on_a_tipped_piece() -> None:
    """On a tipped or propped piece the suction point lies below the top (the upturned face
    slopes down from it): the cup's grasp point is that much lower, never higher, and so is
    the jaws' (the piece's middle lies that much below its raised end)."""
    cup = _config_with_tool(tool_from_data("suction_cup", "tool"))
    jaws = _config_with_tool(XARM)
    level = _track(1, 0.5)
    tipped = replace(level, suction_radius_m=0.03, suction_below_top_m=0.012)
    proud = replace(level, suction_radius_m=0.03, suction_below_top_m=-0.005)
    assert grasp_height_m(tipped, cup) == pytest.approx(grasp_height_m(level, cup) - 0.012)
    assert grasp_height_m(proud, cup) == grasp_height_m(level, cup)
    assert grasp_height_m(tipped, jaws) == pytest.approx(grasp_height_m(level, jaws) - 0.012)
    assert grasp_height_m(proud, jaws) == grasp_height_m(level, jaws)
    # the approach still ends above the top: the cup does not come in sideways into it
    assert approach_z_m(tipped, cup) == pytest.approx(approach_z_m(level, cup))
    assert approach_z_m(level, cup) == pytest.approx(
        grasp_height_m(level, cup) + cup.pick.approach_height_m
    )


def test_a_cup_leaves_a_face_tilted_beyond_its_lip_and_jaws_do_not_mind() -> None:
    """A piece propped on another shows a tilted face: the cup's lip seals within
    ``max_tilt_rad`` (0.35 rad for the catalogue's cup); the cup leaves faces within 3 degrees
    of that (``too_tilted``), takes a level or an unknown one, and jaws take any."""
    spec = tool_from_data("suction_cup", "tool")
    cup = make_tool(spec, SHIPPED)
    size = {"length_m": 0.2, "width_m": 0.08, "height_m": 0.03, "width_margin_m": 0.015}
    limit = spec.max_tilt_rad - math.radians(3.0)
    assert cup.misfit(**size, face_radius_m=0.035, face_tilt_rad=0.0) is None
    assert cup.misfit(**size, face_radius_m=0.035, face_tilt_rad=limit - 1e-3) is None
    assert cup.misfit(**size, face_radius_m=0.035, face_tilt_rad=limit + 1e-3) == "too_tilted"
    assert cup.misfit(**size, face_radius_m=0.035, face_tilt_rad=math.nan) is None
    jaws = make_tool(XARM, SHIPPED)
    assert jaws.misfit(**size, face_tilt_rad=1.0) == jaws.misfit(**size)
