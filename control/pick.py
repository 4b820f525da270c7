"""The pick state machine as pure logic: one :meth:`PickController.update` per control tick.

Sequence per object: ``approach`` (Ruckig to a point above the predicted grasp point, arriving
with the object's velocity), ``descend`` (to the grasp point, still moving with it), ``dwell``
(track it for ``dwell_s``), ``close`` (gripper closes while tracking), ``lift``, ``carry`` (to the
drop point above the class bin), ``release``, ``return`` (towards the ready pose; a new target may
be taken from there). With ``pick.approach_space: joint`` the next target is chosen as soon as
the release ends, and the approach begins as one joint-space move, planned once, that arrives
above the object with its velocity; the Cartesian approach then takes over. Errors (lost
target, Ruckig error, IK failure) abort the pick, are counted, and never produce a joint command
outside the limits: the last valid joint command is held.
"""

from __future__ import annotations

import contextlib
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from enum import StrEnum

import numpy as np
from numpy.typing import NDArray

from control.config import ControllerConfig
from control.errors import ControlError, IkError, PlanningError
from control.ik import Kinematics, tool_pose, yaw_of
from control.planner import (
    CartesianPlanner,
    CartesianState,
    CartesianTarget,
    FeedbackTerm,
    JointCommander,
    JointPlanner,
)
from control.scheduler import Schedule, grasp_height_m, nearest_half_turn, schedule
from control.tracking import Track

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]


class Phase(StrEnum):
    """Phases of the pick sequence."""

    IDLE = "idle"
    APPROACH = "approach"
    DESCEND = "descend"
    DWELL = "dwell"
    CLOSE = "close"
    LIFT = "lift"
    CARRY = "carry"
    RELEASE = "release"
    RETURN = "return"


WRIST_MARGIN_RAD = 0.15
"""Least room on the tool-turning joint at the intercept for the nearest grasp yaw."""

FOLLOWING_PHASES = frozenset({Phase.DESCEND, Phase.DWELL, Phase.CLOSE})
"""Phases in which the TCP moves with the object and the feedback term is active."""

JOINT_APPROACH_GUESS_S = 0.6
"""First guess (s) of a joint-space approach's duration (the fixed point starts there)."""

MAX_APPROACH_LEAD_S = 1.0
"""Cap (s) on the approach's lead: it aims where the object will be that much later.

The lead starts at the scheduler's estimate of the time to get above the object and shrinks by
one control period per tick (the goal is the predicted meeting point, fixed in space), or to
Ruckig's time left to reach the goal when that is shorter; at zero the approach follows the
object itself. (A lead that could grow diverges when the arm is barely faster than the belt.)"""


@dataclass(frozen=True, kw_only=True)
class TcpMeasurement:
    """Measured tool: TCP ``position_m`` ``(x, y, z)`` in the world frame, ``yaw_rad``, and the
    gripper's ``opening_m`` (from the finger joints; NaN when not measured, which turns off the
    grip check)."""

    position_m: Vec3
    yaw_rad: float
    opening_m: float = math.nan


@dataclass(frozen=True, kw_only=True)
class Command:
    """Everything the arm and gripper are told in one control tick.

    ``setpoint`` is the Ruckig state, ``commanded_position_m`` the setpoint plus feedback that
    went into the IK, ``joint_positions_rad`` ``(n_arm,)`` is always within the joint limits,
    ``grasp_point_m`` is the predicted grasp point of the target (None without a target).
    """

    t_s: float
    phase: Phase
    target_id: int | None
    setpoint: CartesianState
    commanded_position_m: Vec3
    joint_positions_rad: tuple[float, ...]
    gripper_width_m: float
    grasp_point_m: Vec3 | None


@dataclass(frozen=True, kw_only=True)
class PickStats:
    """Counters since construction.

    ``untargeted`` counts objects that were never targeted, by the last reason the scheduler gave;
    ``aborted`` counts aborted picks by reason (``target_lost``, ``too_late``, ``ruckig_error``,
    ``ik_failure``, ``grip_missed``: the fingers closed on nothing); ``errors`` counts every
    Ruckig/IK error, also outside a pick;
    ``rate_limited`` counts joint commands slowed to the joint velocity limits;
    ``sync_fallbacks`` counts Ruckig plans (Cartesian steps and joint moves) whose time
    synchronisation failed and that were solved without it (see
    :func:`control.planner.calculate_synchronised`).
    """

    targeted: int
    completed: int
    completed_by_class: Mapping[str, int]
    aborted: Mapping[str, int]
    untargeted: Mapping[str, int]
    errors: Mapping[str, int]
    rate_limited: int = 0
    sync_fallbacks: int = 0


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


class PickController:
    """Pick state machine; pure logic, driven by :meth:`update` at the control rate."""

    def __init__(
        self,
        config: ControllerConfig,
        *,
        kinematics: Kinematics | None = None,
        q_init: FloatArray | None = None,
    ) -> None:
        """Prepare the controller at the ready pose, or at ``q_init`` ``(n_arm,)`` if given.

        Raises ``ControlError`` when the ready pose has no IK solution.
        """
        self._cfg = config
        self._kin = kinematics if kinematics is not None else Kinematics(config.robot, config.ik)
        robot = config.robot
        ready = self._kin.solve(
            tool_pose(robot.ready_tcp_position_m, robot.ready_yaw_rad),
            np.asarray(robot.ready_joint_positions_rad, dtype=np.float64),
        )
        if not ready.success:
            msg = (
                f"robot.ready_tcp_position_m {robot.ready_tcp_position_m} with ready_yaw_rad "
                f"{robot.ready_yaw_rad} has no IK solution near ready_joint_positions_rad"
            )
            raise ControlError(msg)
        self.q_ready: FloatArray = np.array(ready.q)
        """Joint positions ``(n_arm,)`` of the ready pose."""
        q0 = self.q_ready if q_init is None else np.asarray(q_init, dtype=np.float64)
        oMtool = self._kin.fk(q0)  # noqa: N806
        p = oMtool.translation
        start = CartesianState(position=(float(p[0]), float(p[1]), float(p[2]), yaw_of(oMtool)))
        self._ready_target = CartesianTarget(
            position=(*robot.ready_tcp_position_m, robot.ready_yaw_rad)
        )
        self._planner = CartesianPlanner(config.motion, start)
        self._joint_planner = JointPlanner(self._kin, config.motion)
        self._joint_mode = False
        self._joint_remaining_s = 0.0
        self._approach_lead_s = 0.0
        self._approach_waiting = False
        self._joint_approach: JointApproach | None = None
        self._meetings: dict[int, JointApproach | None] = {}
        self._meetings_t_s = math.nan
        self._yaw_remaining_s = 0.0
        self._drop_q = np.array(self.q_ready)
        self._commander = JointCommander(self._kin, config.motion, q0)
        self._feedback = FeedbackTerm(config.motion)
        self._phase = Phase.RETURN
        self._phase_start_s = -math.inf
        self._target: Track | None = None
        self._target_seen_s = -math.inf
        self._grasp_yaw_rad = robot.ready_yaw_rad
        self._intercept_estimate_s = math.nan
        self._carrying = False
        self._lift_target: CartesianTarget | None = None
        self._ticks_since_command = 1
        self._tracking_start_s = math.nan
        self._excluded: set[int] = set()
        self._grip_misses: Counter[int] = Counter()
        self._measured = TcpMeasurement(position_m=(math.nan,) * 3, yaw_rad=math.nan)
        self._targeted_ids: set[int] = set()
        self._untargeted: dict[int, str] = {}
        self._targeted = 0
        self._completed = 0
        self._completed_by_class: Counter[str] = Counter()
        self._aborted: Counter[str] = Counter()
        self._errors: Counter[str] = Counter()
        self.last_error = ""
        """The message of the latest Ruckig/IK error (empty before the first)."""

    @property
    def phase(self) -> Phase:
        """The current phase."""
        return self._phase

    @property
    def tracking_start_s(self) -> float:
        """Time the current target was chosen (NaN without a target)."""
        return self._tracking_start_s

    @property
    def intercept_estimate_s(self) -> float:
        """The scheduler's estimate of the time to intercept the current target (at choice)."""
        return self._intercept_estimate_s

    @property
    def kinematics(self) -> Kinematics:
        """The kinematics the controller commands with."""
        return self._kin

    def set_class_priorities(self, priorities: Mapping[str, float]) -> None:
        """Replace the scheduler's class priorities (larger is picked first) from now on."""
        scheduler = replace(self._cfg.scheduler, class_priorities=dict(priorities))
        self._cfg = replace(self._cfg, scheduler=scheduler)

    def stats(self) -> PickStats:
        """Counters of targeted, completed, aborted and untargeted objects."""
        return PickStats(
            targeted=self._targeted,
            completed=self._completed,
            completed_by_class=dict(self._completed_by_class),
            aborted=dict(self._aborted),
            untargeted=dict(Counter(self._untargeted.values())),
            errors=dict(self._errors),
            rate_limited=self._commander.rate_limited,
            sync_fallbacks=self._planner.sync_fallbacks + self._joint_planner.sync_fallbacks,
        )

    def _set_phase(self, phase: Phase, t_s: float) -> None:
        self._phase = phase
        self._phase_start_s = t_s
        if phase in (Phase.CARRY, Phase.RETURN):
            self._joint_remaining_s = math.inf  # until the new joint move's first step

    def _abort(self, reason: str, t_s: float) -> None:
        self._aborted[reason] += 1
        if self._target is not None:
            track_id = self._target.track_id
            if reason == "grip_missed":
                self._grip_misses[track_id] += 1
            if reason != "grip_missed" or self._grip_misses[track_id] > self._cfg.pick.grip_retries:
                self._excluded.add(track_id)
            else:
                self._targeted_ids.discard(track_id)  # may be scheduled again
        following = self._phase in FOLLOWING_PHASES
        self._target = None
        self._tracking_start_s = math.nan
        self._carrying = False
        if following:
            self._start_lift(t_s)
        else:
            self._set_phase(Phase.RETURN, t_s)

    def _start_lift(self, t_s: float) -> None:
        state = self._planner.state
        x, y, z, yaw = state.position
        vx, vy = state.velocity[0], state.velocity[1]
        stop_s = 0.1
        self._lift_target = CartesianTarget(
            position=(x + vx * stop_s, y + vy * stop_s, z + self._cfg.pick.lift_height_m, yaw)
        )
        self._set_phase(Phase.LIFT, t_s)

    def _start_pick(self, track: Track, decision: Schedule, t_s: float) -> None:
        intercept_s = decision.intercept_s
        self._target = track
        self._target_seen_s = t_s
        if track.track_id not in self._grip_misses:  # a retry is not a new target
            self._targeted += 1
        self._targeted_ids.add(track.track_id)
        self._untargeted.pop(track.track_id, None)
        self._tracking_start_s = t_s
        self._intercept_estimate_s = intercept_s
        self._feedback.reset()
        self._joint_approach = None
        if self._cfg.pick.approach_space == "joint" and self._joint_mode:
            # the joint planner continues from the current joint move
            self._joint_approach = self._plan_joint_approach(track, t_s)
        self._joint_mode = self._joint_approach is not None
        self._grasp_yaw_rad = (
            self._joint_approach.yaw_rad
            if self._joint_approach is not None
            else self._best_grasp_yaw(track, intercept_s)
        )
        self._approach_lead_s = min(decision.approach_s, MAX_APPROACH_LEAD_S)
        self._approach_waiting = False
        self._yaw_remaining_s = math.inf  # until the first Cartesian step of this pick
        self._set_phase(Phase.APPROACH, t_s)
        self._joint_remaining_s = math.inf  # until the new joint move's first step

    def _joint_meeting(self, track: Track, t_s: float) -> JointApproach | None:
        """Where and when a joint-space move from the current joint state meets ``track``.

        The meeting time is a fixed point: the time-optimal duration of the move (Ruckig, from
        the current joint state) to the pose above where the object will be then (upstream of
        the pick window when the object is still too far away: the scheduler then waits). The
        IK is seeded by the ready posture turned at the base towards the meeting point; of the
        two grasp yaws the one that moves the joints least is kept. None when no pose or move
        is found. Cached per track for the tick ``t_s`` (the scheduler's estimate and the
        chosen move are the same computation).
        """
        if t_s != self._meetings_t_s:
            self._meetings.clear()
            self._meetings_t_s = t_s
        if track.track_id not in self._meetings:
            self._meetings[track.track_id] = self._solve_meeting(track, t_s)
        return self._meetings[track.track_id]

    def _solve_meeting(self, track: Track, t_s: float) -> JointApproach | None:
        kin, cfg = self._kin, self._cfg
        vx, vy = track.velocity_mps
        z = grasp_height_m(track, cfg) + cfg.pick.approach_height_m
        base = cfg.robot.base_position_m
        ready = cfg.robot.ready_tcp_position_m
        q_now = np.array(self._commander.q)
        vmax = np.maximum(kin.velocity_limit_rps, 1e-6)
        dt_s = JOINT_APPROACH_GUESS_S
        near = nearest_half_turn(track.yaw_rad, self._planner.state.position[3])
        yaws: tuple[float, ...] = (near, near + math.pi)
        q_goal: FloatArray | None = None
        yaw_goal = near
        for _ in range(5):
            x, y = track.position_at(t_s + dt_s)
            if q_goal is None:
                turn = math.atan2(y - base[1], x - base[0]) - math.atan2(
                    ready[1] - base[1], ready[0] - base[0]
                )
                seed = np.array(self.q_ready)
                seed[0] = np.clip(seed[0] + turn, kin.lower_rad[0], kin.upper_rad[0])
            else:
                seed = q_goal
            best: tuple[float, FloatArray, float] | None = None
            for yaw in yaws:
                result = kin.solve(tool_pose((x, y, z), yaw), seed)
                if not result.success:
                    continue
                cost = float(np.max(np.abs(np.asarray(result.q) - q_now) / vmax))
                if best is None or cost < best[0]:
                    best = (cost, np.array(result.q), yaw)
            if best is None:
                return None
            _, q_goal, yaw_goal = best
            yaws = (yaw_goal,)
            dq_goal = kin.joint_velocity(q_goal, np.array([vx, vy, 0.0, 0.0]))
            try:
                duration_s = self._joint_planner.duration_s(q_goal, dq_goal)
            except PlanningError:
                return None
            previous_s, dt_s = dt_s, duration_s
            if abs(dt_s - previous_s) < 0.005:
                break
        assert q_goal is not None  # the first iteration returned or set it
        x, y = track.position_at(t_s + dt_s)
        result = kin.solve(tool_pose((x, y, z), yaw_goal), q_goal)
        if not result.success:
            return None
        q_goal = np.array(result.q)
        dq_goal = kin.joint_velocity(q_goal, np.array([vx, vy, 0.0, 0.0]))
        goal = JointGoal(q=q_goal, dq=dq_goal, arrive_s=t_s + dt_s)
        return JointApproach(goal=goal, yaw_rad=yaw_goal)

    def _plan_joint_approach(self, track: Track, t_s: float) -> JointApproach | None:
        """Start the joint-space move of :meth:`_joint_meeting`; None when there is none."""
        meeting = self._joint_meeting(track, t_s)
        if meeting is None:
            return None
        goal = meeting.goal
        assert goal.dq is not None
        try:
            self._joint_planner.start_move(goal.q, goal.dq, min_duration_s=goal.arrive_s - t_s)
        except PlanningError:
            return None
        return meeting

    def _best_grasp_yaw(self, track: Track, intercept_s: float) -> float:
        """The grasp yaw, of the two a parallel gripper allows, that the wrist can reach.

        The one nearest the current yaw, unless the last joint (the one that turns the tool,
        +-2.9 rad on the Panda) would end within ``WRIST_MARGIN_RAD`` of a limit at the
        predicted intercept point; then the one with more room there.
        """
        current = self._planner.state.position[3]
        near = nearest_half_turn(track.yaw_rad, current)
        dt_s = intercept_s if math.isfinite(intercept_s) else 0.0
        x = track.position_m[0] + track.velocity_mps[0] * dt_s
        y = track.position_m[1] + track.velocity_mps[1] * dt_s
        z = grasp_height_m(track, self._cfg) + self._cfg.pick.approach_height_m
        other = near - math.pi if near > current else near + math.pi
        best, best_room = near, -math.inf
        for yaw in (near, other):
            result = self._kin.solve(tool_pose((x, y, z), yaw), self._commander.q)
            if not result.success:
                continue
            q = np.asarray(result.q)
            room = float(min(q[-1] - self._kin.lower_rad[-1], self._kin.upper_rad[-1] - q[-1]))
            if room >= WRIST_MARGIN_RAD:
                return yaw
            if room > best_room:
                best, best_room = yaw, room
        return best

    def _schedule(self, t_s: float, tracks: Sequence[Track]) -> None:
        estimate = None
        if self._cfg.pick.approach_space == "joint" and self._joint_mode:

            def estimate(track: Track) -> float:
                meeting = self._joint_meeting(track, t_s)
                return math.inf if meeting is None else meeting.goal.arrive_s - t_s

        result = schedule(
            tracks,
            now_s=t_s,
            tcp_position_m=self._planner.state.position_m,
            config=self._cfg,
            excluded_ids=self._excluded | self._targeted_ids,
            tcp_yaw_rad=self._planner.state.position[3],
            approach_estimate=estimate,
        )
        for item in result.untargeted:
            if item.track_id not in self._targeted_ids:
                self._untargeted[item.track_id] = item.reason
        if result.target is not None:
            self._start_pick(result.target, result, t_s)

    def _object_state(
        self, t_s: float, belt_velocity_mps: tuple[float, float], *, now_s: float | None = None
    ) -> tuple[Vec3, Vec3] | None:
        """Predicted grasp point and velocity of the target at ``t_s``.

        While the target is not in the current tracks (``now_s`` after the last sighting), it is
        extrapolated with the measured belt velocity.
        """
        track = self._target
        if track is None:
            return None
        velocity = track.velocity_mps
        unseen = (t_s if now_s is None else now_s) > self._target_seen_s
        if unseen and all(math.isfinite(v) for v in belt_velocity_mps):
            velocity = belt_velocity_mps
        dt_s = t_s - track.stamp_s
        x = track.position_m[0] + velocity[0] * dt_s
        y = track.position_m[1] + velocity[1] * dt_s
        return (x, y, grasp_height_m(track, self._cfg)), (velocity[0], velocity[1], 0.0)

    def _track_target(self, t_s: float, tracks: Sequence[Track]) -> bool:
        """Refresh the target snapshot; False when it has been lost for too long."""
        if self._target is None:
            return False
        for track in tracks:
            if track.track_id == self._target.track_id:
                self._target = track
                self._target_seen_s = t_s
                self._grasp_yaw_rad = nearest_half_turn(track.yaw_rad, self._grasp_yaw_rad)
                return True
        return t_s - self._target_seen_s <= self._cfg.pick.lost_timeout_s

    def _following_target(
        self,
        t_s: float,
        belt_velocity_mps: tuple[float, float],
        height_m: float,
        *,
        lead_s: float = 0.0,
    ) -> tuple[CartesianTarget, Vec3]:
        """Ruckig goal ``height_m`` above the target's grasp point, and the grasp point itself.

        The goal is the target's predicted state when the command takes effect, ``lead_s``
        later still (the approach aims where the object will be when the arm gets there).
        """
        t_cmd = t_s + self._cfg.motion.command_latency_s
        obj = self._object_state(t_cmd + lead_s, belt_velocity_mps, now_s=t_s)
        now = obj if lead_s == 0.0 else self._object_state(t_cmd, belt_velocity_mps, now_s=t_s)
        if obj is None or now is None:
            msg = "following without a target"
            raise ControlError(msg)
        (x, y, z), (vx, vy, _) = obj
        target = CartesianTarget(
            position=(x, y, z + height_m, self._grasp_yaw_rad),
            velocity=(vx, vy, 0.0, 0.0),
        )
        return target, now[0]

    def _not_upstream(self, target: CartesianTarget) -> CartesianTarget:
        """An approach target upstream of the pick window waits at its entry, at rest.

        Chasing an object upstream takes the arm to the edge of its workspace; it meets the
        object where the window begins instead, and follows it from there.
        """
        x_min = self._cfg.belt.pick_window_x_m[0]
        if target.position[0] >= x_min:
            return target
        return CartesianTarget(position=(x_min, *target.position[1:]))

    def _arrived(self, target: CartesianTarget, height_m: float) -> bool:
        """True when the setpoint is on the moving target (position and velocity)."""
        del height_m
        state = self._planner.state
        period_s = self._cfg.motion.control_period_s
        previous = [
            p - v * period_s for p, v in zip(target.position[:3], target.velocity[:3], strict=True)
        ]
        relative_speed = math.dist(state.velocity[:3], target.velocity[:3])
        return (
            math.dist(state.position_m, previous) <= self._cfg.pick.arrive_tolerance_m
            and relative_speed <= self._cfg.pick.arrive_speed_tolerance_mps
        )

    def _plan(
        self, t_s: float, tracks: Sequence[Track], belt_velocity_mps: tuple[float, float]
    ) -> tuple[CartesianTarget | JointGoal, Vec3 | None]:
        """Run the phase transitions and return this tick's Ruckig goal and aim point."""
        pick = self._cfg.pick
        period_s = self._cfg.motion.control_period_s
        phase = self._phase
        almost_ready = phase == Phase.RETURN and (
            self._joint_mode
            and (
                self._joint_remaining_s <= pick.schedule_before_ready_s
                or pick.approach_space == "joint"
            )
        )
        if phase == Phase.IDLE or almost_ready:
            self._schedule(t_s, tracks)
            phase = self._phase
        if phase in (Phase.APPROACH, *FOLLOWING_PHASES):
            if not self._track_target(t_s, tracks) and phase == Phase.APPROACH:
                self._abort("target_lost", t_s)
                return self._plan(t_s, (), belt_velocity_mps)
            obj = self._object_state(t_s, belt_velocity_mps)
            x_now = obj[0][0] if obj is not None else math.inf
            if phase in (Phase.APPROACH, Phase.DESCEND, Phase.DWELL) and (
                x_now > self._cfg.belt.pick_window_x_m[1]
            ):
                self._abort("too_late", t_s)
                return self._plan(t_s, (), belt_velocity_mps)
        if phase == Phase.APPROACH and self._joint_approach is not None:
            plan = self._joint_approach
            if not (self._joint_mode and self._joint_remaining_s <= period_s):
                obj = self._object_state(t_s, belt_velocity_mps, now_s=t_s)
                return plan.goal, obj[0] if obj is not None else None
            self._joint_approach = None  # above the object, moving with it: Cartesian from here
            self._approach_lead_s = 0.0
            self._grasp_yaw_rad = nearest_half_turn(
                self._grasp_yaw_rad, self._planner.state.position[3]
            )
        if phase == Phase.APPROACH:
            target, aim = self._following_target(
                t_s, belt_velocity_mps, pick.approach_height_m, lead_s=self._approach_lead_s
            )
            waiting = self._not_upstream(target)
            self._approach_waiting = waiting is not target
            if self._approach_waiting:  # the meeting point is not in the window yet: wait there
                return waiting, aim
            yaw_error = abs(self._planner.state.position[3] - target.position[3])
            on_object = self._approach_lead_s <= period_s  # not on a point ahead of it
            yaw_ready = (
                yaw_error < pick.yaw_tolerance_rad
                or self._yaw_remaining_s <= pick.descend_yaw_lead_s
            )
            if on_object and yaw_ready and self._arrived(target, pick.approach_height_m):
                self._set_phase(Phase.DESCEND, t_s)
                phase = Phase.DESCEND
            else:
                return target, aim
        if phase == Phase.DESCEND:
            target, aim = self._following_target(t_s, belt_velocity_mps, 0.0)
            if self._arrived(target, 0.0):
                self._set_phase(Phase.DWELL, t_s)
            return target, aim
        if phase == Phase.DWELL:
            target, aim = self._following_target(t_s, belt_velocity_mps, 0.0)
            yaw_error = abs(self._planner.state.position[3] - target.position[3])
            dwelt = t_s - self._phase_start_s >= pick.dwell_s - pick.close_overlap_s
            if dwelt and yaw_error < pick.yaw_tolerance_rad:
                self._set_phase(Phase.CLOSE, t_s)
            return target, aim
        if phase == Phase.CLOSE:
            if t_s - self._phase_start_s >= pick.close_s:
                if self._closed_on_nothing():
                    self._abort("grip_missed", t_s)
                    return self._plan(t_s, (), belt_velocity_mps)
                self._carrying = True
                self._start_lift(t_s)
                return self._plan(t_s, tracks, belt_velocity_mps)
            return self._following_target(t_s, belt_velocity_mps, 0.0)
        if phase == Phase.LIFT and self._carrying and self._closed_on_nothing():
            self._abort("grip_missed", t_s)  # the fingers finished closing on nothing
            self._set_phase(Phase.LIFT, t_s)  # the lift goes on, with the gripper open
        if phase == Phase.LIFT:
            lift = self._lift_target
            if lift is None or (
                self._planner.state.position[2] >= lift.position[2] - 0.2 * pick.lift_height_m
            ):
                if self._carrying:
                    self._start_carry(t_s)
                else:
                    self._set_phase(Phase.RETURN, t_s)
                return self._plan(t_s, tracks, belt_velocity_mps)
            return lift, None
        if phase == Phase.CARRY:
            goal = JointGoal(q=self._drop_q)
            if self._joint_remaining_s <= period_s and self._at_joint_goal(goal):
                self._set_phase(Phase.RELEASE, t_s)
            return goal, None
        if phase == Phase.RELEASE:
            if t_s - self._phase_start_s >= pick.release_s:
                self._completed += 1
                if self._target is not None:
                    self._completed_by_class[self._target.class_name] += 1
                self._target = None
                self._carrying = False
                self._tracking_start_s = math.nan
                self._set_phase(Phase.RETURN, t_s)
                return self._plan(t_s, tracks, belt_velocity_mps)
            return JointGoal(q=self._drop_q), None
        goal = JointGoal(q=self.q_ready)
        if (
            phase == Phase.RETURN
            and self._joint_remaining_s <= period_s
            and self._at_joint_goal(goal)
        ):
            self._set_phase(Phase.IDLE, t_s)
        return goal, None

    def _closed_on_nothing(self) -> bool:
        """True when the gripper, commanded to close, is measured within
        ``pick.grip_check_margin_m`` of its commanded opening: nothing stopped the fingers.

        A gripped object holds them apart: over 41 closes in two realtime throughput runs of the
        twin, fingers on an object stayed at least 1.4 mm wider than commanded, and fingers that
        missed closed to within 0.4 mm of it in 0.2 s.
        """
        opening = self._measured.opening_m
        if not math.isfinite(opening):
            return False
        return opening - self._closing_width_m() < self._cfg.pick.grip_check_margin_m

    def _at_joint_goal(self, goal: JointGoal) -> bool:
        return bool(np.max(np.abs(self._commander.q - goal.q)) < 1e-4)

    def _start_carry(self, t_s: float) -> None:
        """Solve the drop pose once: the current posture turned about the base to the bin.

        The drop point is :meth:`_drop_point`. The IK is seeded by the current joints with the
        base joint turned by the bearing from the TCP to the drop point, and the tool's yaw
        turns with it (either of the two yaws a parallel gripper allows, whichever leaves the
        last joint nearer its current angle): the carry is mostly a turn of the base joint and
        the wrist hardly moves.
        """
        robot = self._cfg.robot
        target = self._target
        class_name, length_m = ("", 0.0) if target is None else (target.class_name, target.length_m)
        base = robot.base_position_m
        q_now = np.array(self._commander.q)
        x, y, z, yaw_now = self._planner.state.position
        drop = self._drop_point(class_name, (x, y, z), length_m)
        turn = math.atan2(drop[1] - base[1], drop[0] - base[0]) - math.atan2(
            y - base[1], x - base[0]
        )
        lower, upper = float(self._kin.lower_rad[0]), float(self._kin.upper_rad[0])
        turns = [turn + k * 2 * math.pi for k in (-1, 0, 1)]
        inside = [a for a in turns if lower <= q_now[0] + a <= upper] or [turn]
        turn = min(inside, key=abs)
        seed = np.array(q_now)
        seed[0] = np.clip(seed[0] + turn, lower, upper)
        best: FloatArray | None = None
        for yaw in (yaw_now + turn, yaw_now + turn + math.pi):
            result = self._kin.solve(tool_pose(drop, yaw), seed)
            if result.success and (
                best is None or abs(result.q[-1] - q_now[-1]) < abs(best[-1] - q_now[-1])
            ):
                best = np.array(result.q)
        if best is not None:
            self._drop_q = best
        else:
            self._errors["ik_failure"] += 1
            self._aborted["drop_unreachable"] += 1
            self.last_error = f"{self._phase}: no IK solution for the drop point {drop}"
            self._drop_q = self._commander.q
        self._set_phase(Phase.CARRY, t_s)

    def _drop_point(self, class_name: str, tcp_m: Vec3, length_m: float) -> Vec3:
        """Where to release an object of ``class_name``, ``length_m`` long, carried from ``tcp_m``.

        Anywhere over the square of half-width ``pick.drop_tolerance_m`` less half the object's
        length around the class's configured drop point (the bins are axis-aligned squares, so
        no part of the object ends up over a wall): the point of it nearest the TCP, so the base
        turns and the arm folds no more than it must. Raised to the TCP's height if that is
        higher. Without a bin for the class, the ready position.
        """
        configured = self._cfg.bins.get(class_name)
        if configured is None:
            return self._cfg.robot.ready_tcp_position_m
        bx, by, bz = configured
        half = max(0.0, self._cfg.pick.drop_tolerance_m - 0.5 * length_m)
        return (
            min(max(tcp_m[0], bx - half), bx + half),
            min(max(tcp_m[1], by - half), by + half),
            max(bz, tcp_m[2]),
        )

    def _closing_width_m(self) -> float:
        """The opening the gripper is commanded to when it closes on the target."""
        width = self._target.width_m if self._target is not None else 0.0
        opening = self._cfg.robot.gripper_max_opening_m
        return float(np.clip(width - self._cfg.pick.grip_squeeze_m, 0.0, opening))

    def _gripper_width_m(self) -> float:
        closed = self._phase == Phase.CLOSE or (
            self._carrying and self._phase in (Phase.LIFT, Phase.CARRY)
        )
        return self._closing_width_m() if closed else self._cfg.robot.gripper_max_opening_m

    def _sync_cartesian(self, q: FloatArray, dq: FloatArray) -> None:
        oMtool = self._kin.fk(q)  # noqa: N806
        p = oMtool.translation
        v = self._kin.tcp_velocity(q, dq)
        self._planner.reset(
            CartesianState(
                position=(float(p[0]), float(p[1]), float(p[2]), yaw_of(oMtool)),
                velocity=(float(v[0]), float(v[1]), float(v[2]), float(v[3])),
            )
        )

    def _step_joint(self, goal: JointGoal) -> None:
        if not self._joint_mode:
            q = self._commander.q
            velocity = np.asarray(self._planner.state.velocity, dtype=np.float64)
            self._joint_planner.reset(q, self._kin.joint_velocity(q, velocity))
            self._joint_mode = True
        try:
            step = (
                self._joint_planner.step(goal.q)
                if goal.dq is None
                else self._joint_planner.follow()  # a move planned at its start; cannot fail
            )
        except PlanningError as exc:
            self._errors["ruckig_error"] += 1
            self.last_error = f"{self._phase}: {exc}"
            return
        self._joint_remaining_s = step.remaining_s
        self._commander.reset(step.q)
        self._sync_cartesian(step.q, step.dq)

    def _step_cartesian(
        self, target: CartesianTarget, t_s: float, belt: tuple[float, float]
    ) -> None:
        try:
            step = self._planner.step(target)
            self._yaw_remaining_s = step.yaw_remaining_s
            if self._phase == Phase.APPROACH and not self._approach_waiting:
                period_s = self._cfg.motion.control_period_s
                self._approach_lead_s = max(
                    0.0, min(self._approach_lead_s - period_s, step.position_remaining_s)
                )
        except PlanningError as exc:
            self._errors["ruckig_error"] += 1
            self.last_error = f"{self._phase}: {exc}"
            if self._target is not None and not self._carrying:
                self._abort("ruckig_error", t_s)
                goal, _ = self._plan(t_s, (), belt)
                if isinstance(goal, JointGoal):
                    self._step_joint(goal)
                else:
                    with contextlib.suppress(PlanningError):
                        self._planner.step(goal)

    def update(
        self,
        t_s: float,
        measured_tcp: TcpMeasurement,
        tracks: Sequence[Track],
        belt_velocity_mps: tuple[float, float],
    ) -> Command:
        """Advance one control tick at ``t_s`` and return the command for the arm and gripper.

        ``tracks`` are the tracker's confirmed tracks (any stamp; they are extrapolated to the
        time the command takes effect), ``belt_velocity_mps`` the measured ``(vx, vy)``.
        """
        self._measured = measured_tcp
        goal, aim = self._plan(t_s, tracks, belt_velocity_mps)
        if isinstance(goal, JointGoal):
            self._step_joint(goal)
            self._feedback.reset()
            position = self._planner.state.position_m
        else:
            if self._joint_mode:
                self._joint_mode = False
            self._step_cartesian(goal, t_s, belt_velocity_mps)
            position = self._command_cartesian(t_s, measured_tcp)
        setpoint = self._planner.state
        q = self._commander.q
        return Command(
            t_s=t_s,
            phase=self._phase,
            target_id=self._target.track_id if self._target is not None else None,
            setpoint=setpoint,
            commanded_position_m=position,
            joint_positions_rad=tuple(float(v) for v in q),
            gripper_width_m=self._gripper_width_m(),
            grasp_point_m=aim,
        )

    def _command_cartesian(self, t_s: float, measured_tcp: TcpMeasurement) -> Vec3:
        setpoint = self._planner.state
        position = setpoint.position_m
        if self._phase in FOLLOWING_PHASES:
            dt_s = self._cfg.motion.control_period_s
            correction = self._feedback.correction(position, measured_tcp.position_m, dt_s)
            position = (
                position[0] + correction[0],
                position[1] + correction[1],
                position[2] + correction[2],
            )
        else:
            self._feedback.reset()
        try:
            self._commander.command(position, setpoint.position[3], ticks=self._ticks_since_command)
            self._ticks_since_command = 1
        except IkError as exc:
            self._errors["ik_failure"] += 1
            self.last_error = f"{self._phase}: {exc}"
            self._ticks_since_command += 1
            limit = self._cfg.pick.ik_failures_to_abort
            if (
                self._target is not None
                and not self._carrying
                and self._ticks_since_command > limit
            ):
                self._abort("ik_failure", t_s)
        return position
