"""The physical bound of a pursuit: how soon an arm, within its datasheet joint limits, can be on
a piece moving with the belt, starting at rest at its waiting pose.

A parallel-jaw gripper must come down over a piece, so the bound has two time-optimal legs:
one joint-space move (Ruckig, the datasheet's velocity, acceleration and jerk limits) from rest
at the waiting pose to the pose ``pick.approach_height_m`` above the grasp point, arriving with
the belt's velocity, then one joint-space move from there down to the grasp point, moving with
the belt all the while. The piece is met at the earliest point of the pick window where both
legs fit (the window's entry, when the arm is already near it), at each of a set of lateral
positions and headings the station can take. No collision is checked and no controller latency
counted: a lower bound of what the tracking time to 4 mm can be (``docs/metrics.md``), which
starts when the controller chooses its target and ends once its TCP stays within 4 mm of the
grasp point.

Run it with ``cdw-twin bench bound --json``.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from control.config import ControllerConfig, load_config, params_path
from control.errors import PlanningError
from control.ik import Kinematics, tool_pose
from control.planner import JointPlanner
from control.scheduler import grasp_z_m

FloatArray = NDArray[np.float64]

MEET_STEP_M = 0.02
"""Spacing (m) of the meeting points tried along the pick window."""

HEADINGS_RAD: tuple[float, ...] = tuple(math.radians(d) for d in range(0, 180, 30))
"""Headings tried by default: a parallel jaw is symmetric, so half a turn covers them all."""


@dataclass(frozen=True, kw_only=True)
class BoundCase:
    """One piece: lateral position ``y_m``, heading ``yaw_rad``, height ``height_m`` and the
    belt speed ``speed_mps``; the bound ``bound_s`` (inf: no meeting in the window) and where
    the piece is met, ``meet_x_m``."""

    y_m: float
    yaw_rad: float
    height_m: float
    speed_mps: float
    bound_s: float
    meet_x_m: float


def _leg_s(
    planner: JointPlanner,
    q_from: FloatArray,
    dq_from: FloatArray,
    q_to: FloatArray,
    dq_to: FloatArray,
) -> float:
    """Time-optimal duration (s) of a joint-space move between two moving states."""
    planner.reset(q_from, dq_from)
    return planner.duration_s(q_to, dq_to)


def pursuit_bound(
    config: ControllerConfig,
    kinematics: Kinematics,
    q_wait: FloatArray,
    *,
    y_m: float,
    yaw_rad: float,
    height_m: float,
    speed_mps: float,
) -> BoundCase:
    """The bound for one piece (see the module): the least time over the meeting points of the
    pick window, each point tried with the two legs and the piece's travel to it from where it
    was when the pursuit began (a pursuit begins when the piece is as far upstream as the legs
    take: the bound is the legs' time)."""
    planner = JointPlanner(kinematics, config.motion)
    grasp_z = grasp_z_m(height_m, config)
    approach_z = grasp_z + config.pick.approach_height_m
    belt = np.array([speed_mps, 0.0, 0.0, 0.0])
    x_min, x_max = config.pick_window_x_m
    best_s, best_x = math.inf, math.nan
    for x in np.arange(x_min, x_max + 1e-9, MEET_STEP_M):
        seed = np.array(q_wait)
        seed[0] = math.atan2(y_m - config.base_position_m[1], float(x) - config.base_position_m[0])
        above = kinematics.solve(tool_pose((float(x), y_m, approach_z), yaw_rad), seed)
        if not above.success:
            continue
        q_above = np.asarray(above.q)
        dq_above = kinematics.joint_velocity(q_above, belt)
        x_down = float(x)
        down = kinematics.solve(tool_pose((x_down, y_m, grasp_z), yaw_rad), q_above)
        if not down.success:
            continue
        q_down = np.asarray(down.q)
        dq_down = kinematics.joint_velocity(q_down, belt)
        try:
            first_s = _leg_s(planner, q_wait, np.zeros_like(q_wait), q_above, dq_above)
            second_s = _leg_s(planner, q_above, dq_above, q_down, dq_down)
        except PlanningError:
            continue
        total_s = first_s + second_s
        if x + speed_mps * second_s > x_max:
            continue  # met too late to be down before the window's end
        if total_s < best_s:
            best_s, best_x = total_s, float(x)
    return BoundCase(
        y_m=y_m,
        yaw_rad=yaw_rad,
        height_m=height_m,
        speed_mps=speed_mps,
        bound_s=best_s,
        meet_x_m=best_x,
    )


def bound_table(
    config: ControllerConfig,
    *,
    speeds_mps: tuple[float, ...] = (0.2, 0.4, 0.6),
    ys_m: tuple[float, ...] | None = None,
    yaws_rad: tuple[float, ...] = HEADINGS_RAD,
    height_m: float = 0.04,
) -> dict[str, object]:
    """The bound at each speed over lateral positions (default: the station's followable band,
    ``scheduler.min_reach_m`` .. ``max_reach_m`` across the belt at the window's middle,
    clipped to the belt) and headings, as JSON-ready data: per speed the median, mean, p90 and
    extremes over the cases that have a meeting, and the cases themselves."""
    kinematics = Kinematics.of_station(config.station, config.ik)
    ready = kinematics.solve(
        tool_pose(config.ready_tcp_position_m, config.ready_yaw_rad),
        np.asarray(config.robot.ready_joint_positions_rad, dtype=np.float64),
    )
    q_wait = np.array(ready.q)
    belt = config.belt
    if ys_m is None:
        base_y = config.base_position_m[1]
        low = max(belt.centre_y_m - belt.width_m / 2, base_y + config.scheduler.min_reach_m)
        high = min(belt.centre_y_m + belt.width_m / 2, base_y + config.scheduler.max_reach_m)
        ys_m = tuple(float(y) for y in np.arange(low + 0.025, high - 0.024, 0.05))
    per_speed: dict[str, object] = {}
    for speed in speeds_mps:
        cases = [
            pursuit_bound(
                config, kinematics, q_wait, y_m=y, yaw_rad=yaw, height_m=height_m, speed_mps=speed
            )
            for y in ys_m
            for yaw in yaws_rad
        ]
        times = np.array([c.bound_s for c in cases if math.isfinite(c.bound_s)])
        per_speed[f"{speed:g}"] = {
            "cases": len(cases),
            "met": int(times.size),
            "median_s": float(np.median(times)) if times.size else None,
            "mean_s": float(np.mean(times)) if times.size else None,
            "p90_s": float(np.percentile(times, 90)) if times.size else None,
            "min_s": float(times.min()) if times.size else None,
            "max_s": float(times.max()) if times.size else None,
        }
    return {
        "station": config.station.name,
        "robot": config.robot.name,
        "waiting_tcp_m": list(config.ready_tcp_position_m),
        "approach_height_m": config.pick.approach_height_m,
        "piece_height_m": height_m,
        "lateral_positions_m": [round(y, 3) for y in ys_m],
        "headings_deg": [round(math.degrees(a)) for a in yaws_rad],
        "speeds": per_speed,
    }


def configure(parser: argparse.ArgumentParser) -> None:
    """``cdw-twin bench bound`` options."""
    parser.add_argument(
        "--cell", default=None, help="cell file or shipped name (default: the reference cell)"
    )
    parser.add_argument("--station", default="", help="station name (default: the first)")
    parser.add_argument(
        "--params", default="default", help="controller parameter file or shipped name"
    )
    parser.add_argument("--json", action="store_true", help="print JSON")


def run(args: argparse.Namespace) -> int:
    """Print the bound per speed."""
    from interfaces.cell import load_cell

    cell = load_cell(args.cell)
    config = load_config(params_path(args.params, Path.cwd()), cell=cell, station=args.station)
    table = bound_table(config)
    if args.json:
        print(json.dumps(table, indent=2))
    else:
        for speed, row in dict(table["speeds"]).items():  # type: ignore[call-overload]
            print(f"{speed} m/s: bound median {row['median_s']:.3f} s, p90 {row['p90_s']:.3f} s")
    return 0
