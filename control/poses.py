"""Where the arm goes: a joint-space meeting with a moving object, the grasp yaw the wrist can
reach, and the release point and pose over a bin (pure functions of the kinematics).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from control.config import ControllerConfig
from control.errors import PlanningError
from control.ik import Kinematics, tool_pose, yaw_of
from control.planner import JointPlanner
from control.scheduler import approach_z_m, grasp_xy_at, nearest_grasp_yaw
from control.tracking import Track

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]

WRIST_MARGIN_RAD = 0.15
"""Least room on the tool-turning joint at the intercept for the nearest grasp yaw."""

JOINT_APPROACH_GUESS_S = 0.6
"""First guess (s) of a joint-space approach's duration (the fixed point starts there)."""


@dataclass(frozen=True, kw_only=True, eq=False)
class JointGoal:
    """A joint-space goal ``q`` ``(n_arm,) float`` (carry, release, return, idle, joint approach).

    Reached at rest, or (the joint-space approach, which meets a moving object) with joint
    velocities ``dq`` ``(n_arm,)`` at the planned absolute time ``arrive_s``.
    """

    q: FloatArray
    dq: FloatArray | None = None
    arrive_s: float = -math.inf


@dataclass(frozen=True, kw_only=True, eq=False)
class JointApproach:
    """The joint-space approach's goal: above the target at ``arrive_s`` with its velocity."""

    goal: JointGoal
    yaw_rad: float


def _best_pose(
    kinematics: Kinematics,
    position_m: Vec3,
    yaws: tuple[float, ...],
    seed: FloatArray,
    q_now: FloatArray,
) -> tuple[FloatArray, float] | None:
    """Of the tool poses at ``position_m`` with one of ``yaws``, the solution whose slowest
    joint would take the least time from ``q_now`` at the velocity limits (None: no solution)."""
    vmax = np.maximum(kinematics.velocity_limit_rps, 1e-6)
    best: tuple[float, FloatArray, float] | None = None
    for yaw in yaws:
        result = kinematics.solve(tool_pose(position_m, yaw), seed)
        if not result.success:
            continue
        cost = float(np.max(np.abs(np.asarray(result.q) - q_now) / vmax))
        if best is None or cost < best[0]:
            best = (cost, np.array(result.q), yaw)
    return None if best is None else (best[1], best[2])


def _turned_ready(
    kinematics: Kinematics, config: ControllerConfig, q_ready: FloatArray, x_m: float, y_m: float
) -> FloatArray:
    """The ready posture turned at the base towards ``(x_m, y_m)``."""
    base = config.base_position_m
    ready = config.ready_tcp_position_m
    turn = math.atan2(y_m - base[1], x_m - base[0]) - math.atan2(
        ready[1] - base[1], ready[0] - base[0]
    )
    seed = np.array(q_ready)
    seed[0] = np.clip(seed[0] + turn, kinematics.lower_rad[0], kinematics.upper_rad[0])
    return seed


def meeting_lead_s(config: ControllerConfig) -> float:
    """How far ahead of a tick (s) the object's prediction is that the setpoint must be on when
    the joint-space approach hands over to the Cartesian one: the Cartesian goal is the object
    ``motion.command_latency_s`` on, and the arrival check compares the setpoint with that goal
    one control period back (``PickController._arrived``). Aimed elsewhere, the hand-over starts
    ``v`` times the difference off (5 mm at 0.6 m/s), and the Cartesian approach spends up to
    0.6 s catching up with the object instead of descending."""
    return config.motion.command_latency_s - config.motion.control_period_s


def solve_meeting(  # noqa: PLR0913 (keyword-only: the state it plans from, and where)
    track: Track,
    t_s: float,
    *,
    kinematics: Kinematics,
    joint_planner: JointPlanner,
    config: ControllerConfig,
    q_now: FloatArray,
    q_ready: FloatArray,
    tcp_yaw_rad: float,
    clear_rise_m: float = 0.0,
) -> JointApproach | None:
    """Where and when a joint-space move from the current joint state meets ``track``,
    ``clear_rise_m`` above its usual approach height (:func:`control.scheduler.clearance_rise_m`).

    The meeting time is a fixed point: the time-optimal duration of the move (Ruckig, from the
    current joint state of ``joint_planner``) to the pose above where the object will be then.
    (An object still upstream of the pick window then is left to the scheduler, ``upstream``:
    committing to it earlier would plan the move on a young track's velocity, far ahead.)
    The IK is seeded by the ready posture turned at the base towards the meeting point; of the
    grasp yaws the one that moves the joints least is kept (a tool whose grasp does not depend
    on the object's yaw takes the yaw of that turned ready posture, so its wrist keeps the ready
    angle from pick to pick). None when no pose or move is found.
    """
    period_rad = config.tool.grasp_yaw_period_rad
    vx, vy = track.velocity_mps
    z = approach_z_m(track, config, clear_rise_m)
    dt_s = JOINT_APPROACH_GUESS_S
    lead_s = meeting_lead_s(config)
    if kinematics.beyond_reach((*grasp_xy_at(track, config, t_s + dt_s + lead_s), z)):
        return None  # the first guess's pose fails every yaw before any iteration
    near = nearest_grasp_yaw(track.yaw_rad, tcp_yaw_rad, period_rad)
    yaws: tuple[float, ...] = (near, near + period_rad)
    if period_rad == 0.0:
        x, y = grasp_xy_at(track, config, t_s + dt_s + lead_s)
        yaws = (yaw_of(kinematics.fk(_turned_ready(kinematics, config, q_ready, x, y))),)
    q_goal: FloatArray | None = None
    yaw_goal = near
    for _ in range(5):
        x, y = grasp_xy_at(track, config, t_s + dt_s + lead_s)
        seed = _turned_ready(kinematics, config, q_ready, x, y) if q_goal is None else q_goal
        best = _best_pose(kinematics, (x, y, z), yaws, seed, q_now)
        if best is None:
            return None
        q_goal, yaw_goal = best
        yaws = (yaw_goal,)
        dq_goal = kinematics.joint_velocity(q_goal, np.array([vx, vy, 0.0, 0.0]))
        try:
            duration_s = joint_planner.duration_s(q_goal, dq_goal)
        except PlanningError:
            return None
        previous_s, dt_s = dt_s, duration_s
        if abs(dt_s - previous_s) < 0.005:
            break
    assert q_goal is not None  # the first iteration returned or set it
    x, y = grasp_xy_at(track, config, t_s + dt_s + lead_s)
    result = kinematics.solve(tool_pose((x, y, z), yaw_goal), q_goal)
    if not result.success:
        return None
    q_goal = np.array(result.q)
    dq_goal = kinematics.joint_velocity(q_goal, np.array([vx, vy, 0.0, 0.0]))
    goal = JointGoal(q=q_goal, dq=dq_goal, arrive_s=t_s + dt_s)
    return JointApproach(goal=goal, yaw_rad=yaw_goal)


def best_grasp_yaw(
    track: Track,
    intercept_s: float,
    *,
    kinematics: Kinematics,
    config: ControllerConfig,
    q_now: FloatArray,
    tcp_yaw_rad: float,
) -> float:
    """The grasp yaw, of the nearest two the tool allows, that the wrist can reach.

    The one nearest the current yaw, unless the last joint (the one that turns the tool,
    +-2.9 rad on the Panda) would end within :data:`WRIST_MARGIN_RAD` of a limit at the
    predicted intercept point; then the one with more room there. A tool whose grasp does not
    depend on the object's yaw keeps the current yaw.
    """
    period_rad = config.tool.grasp_yaw_period_rad
    if period_rad == 0.0:
        return tcp_yaw_rad
    near = nearest_grasp_yaw(track.yaw_rad, tcp_yaw_rad, period_rad)
    dt_s = intercept_s if math.isfinite(intercept_s) else 0.0
    x = track.position_m[0] + track.velocity_mps[0] * dt_s
    y = track.position_m[1] + track.velocity_mps[1] * dt_s
    z = approach_z_m(track, config)
    other = near - period_rad if near > tcp_yaw_rad else near + period_rad
    best, best_room = near, -math.inf
    lower, upper = kinematics.lower_rad[-1], kinematics.upper_rad[-1]
    for yaw in (near, other):
        result = kinematics.solve(tool_pose((x, y, z), yaw), q_now)
        if not result.success:
            continue
        q = np.asarray(result.q)
        room = float(min(q[-1] - lower, upper - q[-1]))
        if room >= WRIST_MARGIN_RAD:
            return yaw
        if room > best_room:
            best, best_room = yaw, room
    return best


def drop_point(config: ControllerConfig, class_name: str, tcp_m: Vec3, length_m: float) -> Vec3:
    """Where to release an object of ``class_name``, ``length_m`` long, carried from ``tcp_m``.

    Anywhere over the square of half-width ``pick.drop_tolerance_m`` less half the object's
    length around the drop point of the station's bin for the class (the bins are axis-aligned
    squares, so no part of the object ends up over a wall): the point of it nearest the TCP, so
    the base turns and the arm folds no more than it must. Raised to the TCP's height if that
    is higher. Without a bin for the class, the ready position.
    """
    configured = config.bins.get(class_name)
    if configured is None:
        return config.ready_tcp_position_m
    bx, by, bz = configured
    half = max(0.0, config.pick.drop_tolerance_m - 0.5 * length_m)
    return (
        min(max(tcp_m[0], bx - half), bx + half),
        min(max(tcp_m[1], by - half), by + half),
        max(bz, tcp_m[2]),
    )


def drop_pose(
    kinematics: Kinematics,
    config: ControllerConfig,
    drop_m: Vec3,
    q_now: FloatArray,
    tcp_xy_yaw: tuple[float, float, float],
) -> FloatArray | None:
    """Joint positions that put the TCP at ``drop_m``: the current posture ``q_now`` turned
    about the base to it (None when the IK finds none).

    The IK is seeded by ``q_now`` with the base joint turned by the bearing from the TCP
    (``tcp_xy_yaw``: its x, y and yaw now) to the drop point, and the tool's yaw turns with it
    (either of the yaws the tool allows, whichever leaves the last joint nearer its current
    angle): the carry is mostly a turn of the base joint and the wrist hardly moves.
    """
    base = config.base_position_m
    x, y, yaw_now = tcp_xy_yaw
    turn = math.atan2(drop_m[1] - base[1], drop_m[0] - base[0]) - math.atan2(
        y - base[1], x - base[0]
    )
    lower, upper = float(kinematics.lower_rad[0]), float(kinematics.upper_rad[0])
    turns = [turn + k * 2 * math.pi for k in (-1, 0, 1)]
    inside = [a for a in turns if lower <= q_now[0] + a <= upper] or [turn]
    turn = min(inside, key=abs)
    seed = np.array(q_now)
    seed[0] = np.clip(seed[0] + turn, lower, upper)
    best: FloatArray | None = None
    period_rad = config.tool.grasp_yaw_period_rad
    yaws = (yaw_now + turn,) if period_rad == 0.0 else (yaw_now + turn, yaw_now + turn + period_rad)
    for yaw in yaws:
        result = kinematics.solve(tool_pose(drop_m, yaw), seed)
        if result.success and (
            best is None or abs(result.q[-1] - q_now[-1]) < abs(best[-1] - q_now[-1])
        ):
            best = np.array(result.q)
    return best
