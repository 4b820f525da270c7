"""The pick state machine as pure logic: one :meth:`PickController.update` per control tick.

Sequence per object: ``approach`` (Ruckig to a point above the predicted grasp point, arriving
with the object's velocity), ``descend`` (to the grasp point, still moving with it), ``dwell``
(track it for the tool's dwell; a tool without one skips it), ``close`` (the tool grasps while
tracking), ``lift``, ``carry`` (to the drop point above the class bin), ``release``, ``return``
(towards the ready pose; a new target may be taken from there). The waits come from the tool
(:meth:`control.tools.ControllerTool.timing`). With ``pick.approach_space: joint`` the next
target is chosen as soon as the release ends, and the approach begins as one joint-space move,
planned once, that arrives above the object with its velocity; the Cartesian approach then
takes over. Errors (lost target, Ruckig error, IK failure) abort the pick, are counted, and
never produce a joint command outside the limits: the last valid joint command is held.

Each tick runs the handler of the current phase, from a table with one handler per
:class:`Phase`. A handler returns the tick's :class:`Goal`, or a :class:`Transition` when it
switched the phase: the new phase's handler then runs in the same tick. Before the handler of a
phase that pursues a target, the target checks run (lost for too long, past the pick window),
and an abort they cause is a transition as well. The tool (:mod:`control.tools`) says what to
command to grasp and release and whether the grasp holds anything.

On a line of several stations the controller claims its target (:mod:`control.allocation`):
each :class:`Command` carries the claims of its tick (``claimed`` when a pick starts,
``released`` when it ends without the object, ``picked`` when the tool holds it), the boards
the cell relays come in through :meth:`PickController.apply_claims`, the scheduler leaves what
the allocation gives to other stations, and a target that a station further upstream claims as
well is given up before the tool acts on it.
"""

from __future__ import annotations

import contextlib
import math
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from enum import StrEnum

import numpy as np
from numpy.typing import NDArray

from control.allocation import Allocator, Claim, ClaimState, claim_of
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
from control.poses import (
    JointApproach,
    JointGoal,
    best_grasp_yaw,
    drop_point,
    drop_pose,
    meeting_lead_s,
    solve_meeting,
)
from control.scheduler import (
    Schedule,
    approach_rise_m,
    base_lift_m,
    clearance_rise_m,
    grasp_height_m,
    nearest_grasp_yaw,
    schedule,
    unsettled,
)
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


FOLLOWING_PHASES = frozenset({Phase.DESCEND, Phase.DWELL, Phase.CLOSE})
"""Phases in which the TCP moves with the object and the feedback term is active."""

PURSUIT_PHASES = frozenset({Phase.APPROACH, *FOLLOWING_PHASES})
"""Phases that pursue a target: its predicted grasp point leads by ``command_latency_s``."""


@dataclass(frozen=True, kw_only=True)
class TcpMeasurement:
    """Measured tool: TCP ``position_m`` ``(x, y, z)`` in the world frame, ``yaw_rad``, and the
    tool's measured command value ``tool_measured`` (a gripper's opening in m, a suction cup's
    vacuum fraction, from its joints; NaN when not measured, which turns off the grip check)."""

    position_m: Vec3
    yaw_rad: float
    tool_measured: float = math.nan


@dataclass(frozen=True, kw_only=True)
class Command:
    """Everything the arm and tool are told in one control tick.

    ``setpoint`` is the Ruckig state, ``commanded_position_m`` the setpoint plus feedback that
    went into the IK, ``joint_positions_rad`` ``(n_arm,)`` is always within the joint limits,
    ``tool_command`` the tool's command (a gripper's opening in m, a cup's vacuum 1 or 0),
    ``grasp_point_m`` is the predicted grasp point of the target (None without a target),
    ``claims`` the station's claims made in this tick (:mod:`control.allocation`).
    """

    t_s: float
    phase: Phase
    target_id: int | None
    setpoint: CartesianState
    commanded_position_m: Vec3
    joint_positions_rad: tuple[float, ...]
    tool_command: float
    grasp_point_m: Vec3 | None
    claims: tuple[Claim, ...] = ()


@dataclass(frozen=True, kw_only=True)
class PickStats:
    """Counters since construction.

    ``untargeted`` counts objects that were never targeted, by the last reason the scheduler gave;
    ``aborted`` counts aborted picks by reason (``target_lost``, ``too_late``, ``ruckig_error``,
    ``ik_failure``, ``grip_missed``: the tool closed on nothing); ``errors`` counts every
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


@dataclass(frozen=True, kw_only=True)
class TickInput:
    """What one pass of the phase machine sees: the time, the tracks and the belt velocity."""

    t_s: float
    tracks: Sequence[Track]
    belt_velocity_mps: tuple[float, float]


@dataclass(frozen=True, kw_only=True)
class Goal:
    """A handler's result: this tick's Ruckig goal, and the target's grasp point (if any)."""

    target: CartesianTarget | JointGoal
    aim_m: Vec3 | None = None
    min_duration_s: float | None = None
    """Reach the Cartesian target no sooner than this (s) from now (None: time-optimal)."""


@dataclass(frozen=True, kw_only=True)
class Transition:
    """A handler switched to ``phase``: its handler runs next, in the same tick.

    It sees ``tracks`` (none after an abort: no new target is chosen in the tick of an abort).
    ``checked``: the target checks already ran in this pass (the approach hands over to the
    descent), so they do not run again before the new handler.
    """

    phase: Phase
    tracks: Sequence[Track]
    checked: bool = False


Handler = Callable[[TickInput], Goal | Transition]

MIN_POSTURE_SCALE = 0.05
"""The least :meth:`PickController._posture_scale` (near a singularity the joints' needs grow
without bound; the Cartesian moves still finish)."""

OVERLAP_MARGIN_M = 0.003
"""How far into the grasp box's reach the measured TCP must be before :meth:`PickController.
_note_overlap` counts the overlap as begun (the box's edge against the top's, measured)."""

JOINT_REPLAN_UNTIL_S = 0.1
"""The joint-space approach is re-planned to the target's latest prediction until this long
(s) before it arrives; later corrections are left to the Cartesian approach that follows."""


@dataclass(kw_only=True)
class _Pursuit:
    """The current target and what the pick knows about it."""

    target: Track | None = None
    seen_s: float = -math.inf
    grasp_yaw_rad: float
    intercept_estimate_s: float = math.nan
    tracking_start_s: float = math.nan
    carrying: bool = False
    lift_target: CartesianTarget | None = None
    counted: bool = False
    """Whether this pick counted its target as a new one (a grip retry does not)."""
    seal_depth_m: float = 0.0
    """How far below the grasp point the seal search has taken the setpoint."""
    seal_wait_s: float = 0.0
    """How long the close has waited for a seal to start (its deadlines move on by it)."""
    clear_rise_m: float = 0.0
    """How much higher the approach ends to pass over the neighbours (at the pick's start)."""
    overlap_s: float = math.nan
    """When the measured TCP's grasp box came down onto the target (``pick.dwell_from_overlap``;
    NaN: not yet)."""


@dataclass(kw_only=True, eq=False)
class _Motion:
    """State of the motion between ticks: joint-space or Cartesian, and what is left of it."""

    drop_q: FloatArray
    joint_mode: bool = False
    joint_remaining_s: float = 0.0
    yaw_remaining_s: float = 0.0
    meet_s: float = -math.inf
    """When the Cartesian approach plans to be above the target (the scheduler's estimate)."""
    joint_approach: JointApproach | None = None
    ticks_since_command: int = 1


@dataclass(kw_only=True)
class _Book:
    """Counters of targets and errors, and the tracks that must not be chosen again."""

    targeted: int = 0
    completed: int = 0
    completed_by_class: Counter[str] = field(default_factory=Counter)
    aborted: Counter[str] = field(default_factory=Counter)
    errors: Counter[str] = field(default_factory=Counter)
    untargeted: dict[int, str] = field(default_factory=dict)
    targeted_ids: set[int] = field(default_factory=set)
    excluded: set[int] = field(default_factory=set)
    grip_misses: Counter[int] = field(default_factory=Counter)
    last_error: str = ""

    def error(self, kind: str, message: str) -> None:
        """Count an error of ``kind`` and keep its message."""
        self.errors[kind] += 1
        self.last_error = message


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
        self._kin = (
            kinematics
            if kinematics is not None
            else Kinematics.of_station(config.station, config.ik)
        )
        self.q_ready: FloatArray = self._solve_ready()
        """Joint positions ``(n_arm,)`` of the ready pose."""
        q0 = self.q_ready if q_init is None else np.asarray(q_init, dtype=np.float64)
        oMtool = self._kin.fk(q0)  # noqa: N806
        p = oMtool.translation
        start = CartesianState(position=(float(p[0]), float(p[1]), float(p[2]), yaw_of(oMtool)))
        self._planner = CartesianPlanner(config.motion, start)
        self._joint_planner = JointPlanner(self._kin, config.motion)
        self._commander = JointCommander(self._kin, config.motion, q0)
        self._feedback = FeedbackTerm(config.motion)
        self._motion = _Motion(drop_q=np.array(self.q_ready))
        self._pursuit = _Pursuit(grasp_yaw_rad=config.ready_yaw_rad)
        self._book = _Book()
        self._allocator = Allocator(config)
        self._claims_out: list[Claim] = []
        self._meetings: dict[int, JointApproach | None] = {}
        self._meetings_t_s = math.nan
        self._next_schedule_s = -math.inf
        self._phase = Phase.RETURN
        self._phase_start_s = -math.inf
        self._measured = TcpMeasurement(position_m=(math.nan,) * 3, yaw_rad=math.nan)
        self._handlers: dict[Phase, Handler] = {
            Phase.IDLE: self._on_idle,
            Phase.APPROACH: self._on_approach,
            Phase.DESCEND: self._on_descend,
            Phase.DWELL: self._on_dwell,
            Phase.CLOSE: self._on_close,
            Phase.LIFT: self._on_lift,
            Phase.CARRY: self._on_carry,
            Phase.RELEASE: self._on_release,
            Phase.RETURN: self._on_return,
        }

    def _solve_ready(self) -> FloatArray:
        cfg = self._cfg
        ready = self._kin.solve(
            tool_pose(cfg.ready_tcp_position_m, cfg.ready_yaw_rad),
            np.asarray(cfg.robot.ready_joint_positions_rad, dtype=np.float64),
        )
        if not ready.success:
            msg = (
                f"robot.ready_tcp_position_m {cfg.robot.ready_tcp_position_m} with ready_yaw_rad "
                f"{cfg.robot.ready_yaw_rad} has no IK solution near ready_joint_positions_rad"
            )
            raise ControlError(msg)
        return np.array(ready.q)

    # -- public view --------------------------------------------------------------------------
    @property
    def phase(self) -> Phase:
        """The current phase."""
        return self._phase

    @property
    def tracking_start_s(self) -> float:
        """Time the current target was chosen (NaN without a target)."""
        return self._pursuit.tracking_start_s

    @property
    def intercept_estimate_s(self) -> float:
        """The scheduler's estimate of the time to intercept the current target (at choice)."""
        return self._pursuit.intercept_estimate_s

    @property
    def kinematics(self) -> Kinematics:
        """The kinematics the controller commands with."""
        return self._kin

    @property
    def last_error(self) -> str:
        """The message of the latest Ruckig/IK error (empty before the first)."""
        return self._book.last_error

    def apply_claims(self, claims: Sequence[Claim]) -> None:
        """Take a board of claims the cell relayed (:meth:`control.allocation.Allocator.
        apply_board`); boards apply in the order they were relayed."""
        self._allocator.apply_board(claims)

    def set_class_priorities(self, priorities: Mapping[str, float]) -> None:
        """Replace the scheduler's class priorities (larger is picked first) from now on."""
        scheduler = replace(self._cfg.scheduler, class_priorities=dict(priorities))
        self._cfg = replace(self._cfg, scheduler=scheduler)

    def stats(self) -> PickStats:
        """Counters of targeted, completed, aborted and untargeted objects."""
        book = self._book
        return PickStats(
            targeted=book.targeted,
            completed=book.completed,
            completed_by_class=dict(book.completed_by_class),
            aborted=dict(book.aborted),
            untargeted=dict(Counter(book.untargeted.values())),
            errors=dict(book.errors),
            rate_limited=self._commander.rate_limited,
            sync_fallbacks=self._planner.sync_fallbacks + self._joint_planner.sync_fallbacks,
        )

    # -- the tick -----------------------------------------------------------------------------
    def update(
        self,
        t_s: float,
        measured_tcp: TcpMeasurement,
        tracks: Sequence[Track],
        belt_velocity_mps: tuple[float, float],
    ) -> Command:
        """Advance one control tick at ``t_s`` and return the command for the arm and tool.

        ``tracks`` are the tracker's confirmed tracks (any stamp; they are extrapolated to the
        time the command takes effect), ``belt_velocity_mps`` the measured ``(vx, vy)``.
        """
        self._measured = measured_tcp
        now = TickInput(t_s=t_s, tracks=tracks, belt_velocity_mps=belt_velocity_mps)
        plan = self._plan(now)
        if isinstance(plan.target, JointGoal):
            self._step_joint(plan.target)
            self._feedback.reset()
            position = self._planner.state.position_m
        else:
            self._motion.joint_mode = False
            self._step_cartesian(plan.target, now, min_duration_s=plan.min_duration_s)
            position = self._command_cartesian(t_s, measured_tcp)
        target = self._pursuit.target
        return Command(
            t_s=t_s,
            phase=self._phase,
            target_id=target.track_id if target is not None else None,
            setpoint=self._planner.state,
            commanded_position_m=position,
            joint_positions_rad=tuple(float(v) for v in self._commander.q),
            tool_command=self._tool_command(),
            grasp_point_m=plan.aim_m,
            claims=self._take_claims(),
        )

    def _take_claims(self) -> tuple[Claim, ...]:
        claims = tuple(self._claims_out)
        self._claims_out.clear()
        return claims

    def _claim(self, state: ClaimState, t_s: float) -> None:
        """Publish (with the tick's command) this station's claim of ``state`` on its target."""
        target = self._pursuit.target
        if target is not None:
            self._claims_out.append(
                claim_of(
                    self._cfg.station.name,
                    target,
                    t_s,
                    state,
                    self._cfg.allocation.min_claim_radius_m,
                )
            )

    def _plan(self, now: TickInput) -> Goal:
        """Run the phase handlers of this tick until one returns the tick's goal."""
        checked = False
        while True:
            if not checked and self._check_target(now):
                now = replace(now, tracks=())  # aborted: the new phase runs without tracks
                continue
            result = self._handlers[self._phase](now)
            if isinstance(result, Goal):
                return result
            assert result.phase == self._phase
            now = replace(now, tracks=result.tracks)
            checked = result.checked

    def _check_target(self, now: TickInput) -> bool:
        """In a phase that pursues a target: refresh it, and abort the pick when it is lost
        (approach) or past the pick window (until the gripper closes; a tool that measures its
        grasp, until that is complete: the grasp of an object outside the window does not
        count); give the target up when a station further upstream claims it too (as long as
        it would abort). A tool that measures its grasp complete while following lifts the
        object and carries it to its bin: a held object is never let go away from a bin. True
        when the pursuit ended."""
        phase = self._phase
        if phase not in PURSUIT_PHASES:
            return False
        if not self._track_target(now.t_s, now.tracks) and phase == Phase.APPROACH:
            self._abort("target_lost", now.t_s)
            return True
        if phase in FOLLOWING_PHASES and self._grasp_complete():
            self._grasped(now.t_s)  # held: carried to its bin, whatever else happens
            return True
        if phase == Phase.CLOSE and self._cfg.timing.close_max_s is None:
            return False
        target = self._pursuit.target
        if target is not None and self._allocator.must_yield(target, now.t_s):
            self._give_up(now.t_s)
            return True
        obj = self._object_state(now.t_s, now.belt_velocity_mps)
        x_now = obj[0][0] if obj is not None else math.inf
        if x_now > self._cfg.pick_window_x_m[1]:
            self._abort("too_late", now.t_s)
            return True
        return False

    # -- phase handlers -----------------------------------------------------------------------
    def _on_idle(self, now: TickInput) -> Goal | Transition:
        """At the ready pose: choose a target."""
        self._schedule(now.t_s, now.tracks, now.belt_velocity_mps)
        if self._phase != Phase.IDLE:
            return Transition(phase=self._phase, tracks=now.tracks)
        return Goal(target=JointGoal(q=self.q_ready))

    def _on_return(self, now: TickInput) -> Goal | Transition:
        """Back to the ready pose; a target may be chosen before it is reached."""
        pick, motion = self._cfg.pick, self._motion
        almost_ready = motion.joint_mode and (
            motion.joint_remaining_s <= pick.schedule_before_ready_s
            or pick.approach_space == "joint"
        )
        if almost_ready:
            self._schedule(now.t_s, now.tracks, now.belt_velocity_mps)
            if self._phase != Phase.RETURN:
                return Transition(phase=self._phase, tracks=now.tracks)
        goal = JointGoal(q=self.q_ready)
        if motion.joint_remaining_s <= self._cfg.motion.control_period_s and self._at_joint_goal(
            goal
        ):
            self._set_phase(Phase.IDLE, now.t_s)
        return Goal(target=goal)

    def _on_approach(self, now: TickInput) -> Goal | Transition:
        """Above the moving target, turned to its grasp yaw; then the descent."""
        pick, motion, pursuit = self._cfg.pick, self._motion, self._pursuit
        period_s = self._cfg.motion.control_period_s
        if motion.joint_approach is not None:
            if not (motion.joint_mode and motion.joint_remaining_s <= period_s):
                self._correct_joint_approach(now)
                assert motion.joint_approach is not None
                obj = self._object_state(now.t_s, now.belt_velocity_mps, now_s=now.t_s)
                aim = obj[0] if obj is not None else None
                return Goal(target=motion.joint_approach.goal, aim_m=aim)
            motion.joint_approach = None  # above the object, moving with it: Cartesian from here
            pursuit.grasp_yaw_rad = nearest_grasp_yaw(
                pursuit.grasp_yaw_rad,
                self._planner.state.position[3],
                self._cfg.tool.grasp_yaw_period_rad,
            )
            handed_over = True
        else:
            handed_over = False
        assert pursuit.target is not None
        rise_m = approach_rise_m(pursuit.target, self._cfg, pursuit.clear_rise_m)
        target, aim = self._following_target(now.t_s, now.belt_velocity_mps, rise_m)
        yaw_error = abs(self._planner.state.position[3] - target.position[3])
        yaw_ready = (
            yaw_error < pick.yaw_tolerance_rad or motion.yaw_remaining_s <= pick.descend_yaw_lead_s
        )
        near = handed_over and self._on_target(target, pick.handover_tolerance_m)
        if yaw_ready and (near or self._arrived(target)):
            self._set_phase(Phase.DESCEND, now.t_s)
            return Transition(phase=Phase.DESCEND, tracks=now.tracks, checked=True)
        return Goal(target=target, aim_m=aim, min_duration_s=self._meeting_in_s(target, now.t_s))

    def _on_descend(self, now: TickInput) -> Goal | Transition:
        """Down to the grasp point, moving with the object; then the dwell (a tool without one
        goes on to its close in the same tick, once the yaw is aligned)."""
        target, aim = self._following_target(now.t_s, now.belt_velocity_mps, 0.0)
        self._note_overlap(now.t_s, aim)
        if self._arrived(target):
            self._set_phase(Phase.DWELL, now.t_s)
            if self._cfg.timing.dwell_s == 0.0:
                return Transition(phase=Phase.DWELL, tracks=now.tracks, checked=True)
        return Goal(target=target, aim_m=aim)

    def _on_dwell(self, now: TickInput) -> Goal | Transition:
        """At the grasp point for the dwell; the tool closes once the yaw is aligned."""
        pick = self._cfg.pick
        target, aim = self._following_target(now.t_s, now.belt_velocity_mps, 0.0)
        self._note_overlap(now.t_s, aim)
        yaw_error = abs(self._planner.state.position[3] - target.position[3])
        timing = self._cfg.timing
        since_s = min(self._phase_start_s, self._pursuit.overlap_s)  # NaN: the phase's start
        since_s = since_s if math.isfinite(since_s) else self._phase_start_s
        dwelt = now.t_s - since_s >= timing.dwell_s - timing.close_overlap_s
        if dwelt and yaw_error < pick.yaw_tolerance_rad and self._commander.on_goal:
            self._set_phase(Phase.CLOSE, now.t_s)
        return Goal(target=target, aim_m=aim)

    def _note_overlap(self, t_s: float, aim_m: Vec3) -> None:
        """With ``pick.dwell_from_overlap``: note when the measured TCP's grasp box (a jaw's
        ``tcp_half_extents_m``) first reaches down onto the target, within the box's half width
        of the grasp point and its half height of the target's top. The twin's grasp rule (the
        reference's) counts the dwell from that overlap, which begins during the descent: the
        dwell then need not wait its whole length again at the bottom."""
        pursuit, pick = self._pursuit, self._cfg.pick
        half = getattr(self._cfg.station.tool, "tcp_half_extents_m", None)
        if not pick.dwell_from_overlap or half is None or math.isfinite(pursuit.overlap_s):
            return
        target = pursuit.target
        if target is None:
            return
        x, y, z = self._measured.position_m
        top_z = self._cfg.belt.surface_z_m + base_lift_m(target, self._cfg) + target.height_m
        near = math.hypot(x - aim_m[0], y - aim_m[1]) <= min(half[0], half[1])
        if near and z <= top_z + half[2] - OVERLAP_MARGIN_M:
            pursuit.overlap_s = t_s

    def _on_close(self, now: TickInput) -> Goal | Transition:
        """The tool grasps while following; then the grip check and the lift.

        After ``close_s`` a tool that holds nothing aborts (``grip_missed``). A tool that
        measures when its grasp is complete (``timing.close_max_s``) lifts once it is (the
        target checks lift it as soon as it is), and keeps following until then, up to
        ``close_max_s``; a grasp still not complete then is missed. Other tools, and a tool
        that is not measured, lift after ``close_s``.
        """
        timing = self._cfg.timing
        elapsed_s = now.t_s - self._phase_start_s - self._seal_search()
        if elapsed_s >= timing.close_s:
            if self._holds_nothing():
                self._abort("grip_missed", now.t_s)
                return Transition(phase=self._phase, tracks=())
            if timing.close_max_s is None or not math.isfinite(self._measured.tool_measured):
                self._grasped(now.t_s)
                return Transition(phase=Phase.LIFT, tracks=now.tracks)
            if elapsed_s >= timing.close_max_s:
                self._abort("grip_missed", now.t_s)
                return Transition(phase=self._phase, tracks=())
        depth_m = self._pursuit.seal_depth_m
        target, aim = self._following_target(now.t_s, now.belt_velocity_mps, -depth_m)
        return Goal(target=target, aim_m=aim)

    def _seal_search(self) -> float:
        """One control period of the seal search (:class:`~control.config.PickConfig`): the
        seconds the close has waited so far for a seal to start. A cup that reads any vacuum
        has sealed (the search stops where it is); one that reads none waits, and goes lower
        once the arm has caught up with the setpoint's height."""
        pick, pursuit = self._cfg.pick, self._pursuit
        measured = self._measured.tool_measured
        if (
            pick.seal_search_m <= 0.0
            or self._cfg.timing.close_max_s is None
            or not math.isfinite(measured)
            or measured > 0.0
        ):
            return pursuit.seal_wait_s
        period_s = self._cfg.motion.control_period_s
        if pursuit.seal_wait_s + period_s > pick.seal_search_max_s:
            return pursuit.seal_wait_s
        pursuit.seal_wait_s += period_s
        lag_m = self._measured.position_m[2] - self._planner.state.position[2]
        if abs(lag_m) <= pick.seal_search_settled_m:
            pursuit.seal_depth_m = min(
                pick.seal_search_m, pursuit.seal_depth_m + pick.seal_search_speed_mps * period_s
            )
        return pursuit.seal_wait_s

    def _on_lift(self, now: TickInput) -> Goal | Transition:
        """Up from the belt; then the carry (holding the object) or the return."""
        pursuit = self._pursuit
        if pursuit.carrying and self._holds_nothing():
            self._abort("grip_missed", now.t_s)  # the tool finished closing on nothing
            self._set_phase(Phase.LIFT, now.t_s)  # the lift goes on, with the tool open
        lift = pursuit.lift_target
        if lift is None or (
            self._planner.state.position[2] >= lift.position[2] - 0.2 * self._cfg.pick.lift_height_m
        ):
            if pursuit.carrying:
                self._start_carry(now.t_s)
            else:
                self._set_phase(Phase.RETURN, now.t_s)
            return Transition(phase=self._phase, tracks=now.tracks)
        return Goal(target=lift)

    def _on_carry(self, now: TickInput) -> Goal | Transition:
        """The joint move to the drop pose; then the release."""
        goal = JointGoal(q=self._motion.drop_q)
        if self._motion.joint_remaining_s <= self._cfg.motion.control_period_s and (
            self._at_joint_goal(goal)
        ):
            self._set_phase(Phase.RELEASE, now.t_s)
        return Goal(target=goal)

    def _on_release(self, now: TickInput) -> Goal | Transition:
        """The tool opens over the bin; then the pick is complete."""
        if now.t_s - self._phase_start_s >= self._cfg.timing.release_s:
            pursuit, book = self._pursuit, self._book
            book.completed += 1
            if pursuit.target is not None:
                book.completed_by_class[pursuit.target.class_name] += 1
            pursuit.target = None
            pursuit.carrying = False
            pursuit.tracking_start_s = math.nan
            self._set_phase(Phase.RETURN, now.t_s)
            return Transition(phase=Phase.RETURN, tracks=now.tracks)
        return Goal(target=JointGoal(q=self._motion.drop_q))

    # -- transitions --------------------------------------------------------------------------
    def _set_phase(self, phase: Phase, t_s: float) -> None:
        self._phase = phase
        self._phase_start_s = t_s
        if phase == Phase.CLOSE:
            self._pursuit.seal_depth_m = 0.0
            self._pursuit.seal_wait_s = 0.0
        if phase in (Phase.CARRY, Phase.RETURN):
            self._motion.joint_remaining_s = math.inf  # until the new joint move's first step

    def _abort(self, reason: str, t_s: float) -> None:
        book, pursuit = self._book, self._pursuit
        book.aborted[reason] += 1
        book.last_error = f"{reason} in {self._phase.name.lower()} at t={t_s:.2f} s"
        if pursuit.target is not None:
            track_id = pursuit.target.track_id
            book.last_error += f", track {track_id} ({pursuit.target.class_name})"
            if reason == "grip_missed":
                book.grip_misses[track_id] += 1
            if reason != "grip_missed" or book.grip_misses[track_id] > self._cfg.pick.grip_retries:
                book.excluded.add(track_id)
            else:
                book.targeted_ids.discard(track_id)  # may be scheduled again
        self._end_pursuit(t_s)

    def _give_up(self, t_s: float) -> None:
        """Leave the target to a station further upstream that claims it too: not a target of
        this station after all (``claimed_by_other``), and never chosen again."""
        book, pursuit = self._book, self._pursuit
        if pursuit.target is not None:
            track_id = pursuit.target.track_id
            book.targeted -= pursuit.counted
            book.targeted_ids.discard(track_id)
            book.excluded.add(track_id)
            book.untargeted[track_id] = "claimed_by_other"
        self._end_pursuit(t_s)

    def _end_pursuit(self, t_s: float) -> None:
        """Release the target (a ``released`` claim) and lift, or return."""
        pursuit = self._pursuit
        self._claim("released", t_s)
        following = self._phase in FOLLOWING_PHASES
        pursuit.target = None
        pursuit.tracking_start_s = math.nan
        pursuit.carrying = False
        if following:
            self._start_lift(t_s)
        else:
            self._set_phase(Phase.RETURN, t_s)

    def _grasped(self, t_s: float) -> None:
        """The tool holds the target: claim it ``picked`` and lift it (then carry it)."""
        self._pursuit.carrying = True
        self._claim("picked", t_s)
        self._start_lift(t_s)

    def _start_lift(self, t_s: float) -> None:
        state = self._planner.state
        x, y, z, yaw = state.position
        vx, vy = state.velocity[0], state.velocity[1]
        stop_s = 0.1
        self._pursuit.lift_target = CartesianTarget(
            position=(x + vx * stop_s, y + vy * stop_s, z + self._cfg.pick.lift_height_m, yaw)
        )
        self._set_phase(Phase.LIFT, t_s)

    def _start_pick(
        self, track: Track, decision: Schedule, t_s: float, tracks: Sequence[Track]
    ) -> None:
        pursuit, motion, book = self._pursuit, self._motion, self._book
        pursuit.clear_rise_m = clearance_rise_m(track, tracks, self._cfg)
        intercept_s = decision.intercept_s
        pursuit.target = track
        pursuit.seen_s = t_s
        pursuit.overlap_s = math.nan
        pursuit.counted = track.track_id not in book.grip_misses  # a retry is not a new target
        book.targeted += pursuit.counted
        self._claim("claimed", t_s)
        book.targeted_ids.add(track.track_id)
        book.untargeted.pop(track.track_id, None)
        pursuit.tracking_start_s = t_s
        pursuit.intercept_estimate_s = intercept_s
        self._feedback.reset()
        motion.joint_approach = None
        if self._cfg.pick.approach_space == "joint" and motion.joint_mode:
            # the joint planner continues from the current joint move
            motion.joint_approach = self._plan_joint_approach(track, t_s, tracks)
        motion.joint_mode = motion.joint_approach is not None
        pursuit.grasp_yaw_rad = (
            motion.joint_approach.yaw_rad
            if motion.joint_approach is not None
            else best_grasp_yaw(
                track,
                intercept_s,
                kinematics=self._kin,
                config=self._cfg,
                q_now=self._commander.q,
                tcp_yaw_rad=self._planner.state.position[3],
            )
        )
        motion.yaw_remaining_s = math.inf  # until the first Cartesian step of this pick
        motion.meet_s = (
            t_s + decision.approach_s + self._cfg.scheduler.time_margin_s
            if motion.joint_approach is None
            else -math.inf
        )
        self._set_phase(Phase.APPROACH, t_s)
        motion.joint_remaining_s = math.inf  # until the new joint move's first step

    def _start_carry(self, t_s: float) -> None:
        """Solve the drop pose once (:func:`~control.poses.drop_pose`) and start the carry."""
        target = self._pursuit.target
        class_name, length_m = ("", 0.0) if target is None else (target.class_name, target.length_m)
        q_now = np.array(self._commander.q)
        x, y, z, yaw_now = self._planner.state.position
        drop = drop_point(self._cfg, class_name, (x, y, z), length_m)
        best = drop_pose(self._kin, self._cfg, drop, q_now, (x, y, yaw_now))
        if best is not None:
            self._motion.drop_q = best
        else:
            self._book.error(
                "ik_failure", f"{self._phase}: no IK solution for the drop point {drop}"
            )
            self._book.aborted["drop_unreachable"] += 1
            self._motion.drop_q = self._commander.q
        self._set_phase(Phase.CARRY, t_s)

    # -- targets ------------------------------------------------------------------------------
    def _schedule(
        self, t_s: float, tracks: Sequence[Track], belt_velocity_mps: tuple[float, float]
    ) -> None:
        if t_s < self._next_schedule_s:
            return  # found nothing a moment ago (``scheduler.replan_period_s``)
        estimate = None
        if self._cfg.pick.approach_space == "joint" and self._motion.joint_mode:

            def estimate(track: Track) -> float:
                meeting = self._joint_meeting(track, t_s, tracks)
                return math.inf if meeting is None else meeting.goal.arrive_s - t_s

        book = self._book
        result = schedule(
            tracks,
            now_s=t_s,
            tcp_position_m=self._planner.state.position_m,
            config=self._cfg,
            excluded_ids=book.excluded | book.targeted_ids,
            tcp_yaw_rad=self._planner.state.position[3],
            approach_estimate=estimate,
            allow=self._chooser(t_s, belt_velocity_mps),
        )
        for item in result.untargeted:
            if item.track_id not in book.targeted_ids:
                book.untargeted[item.track_id] = item.reason
        if result.target is not None:
            self._start_pick(result.target, result, t_s, tracks)
        else:
            self._next_schedule_s = t_s + self._cfg.scheduler.replan_period_s - 1e-9

    def _chooser(
        self, t_s: float, belt_velocity_mps: tuple[float, float]
    ) -> Callable[[Track], str | None]:
        """The scheduler's ``allow``: ``unsettled`` (:func:`~control.scheduler.unsettled`),
        else the line's allocation."""
        allocation = self._allocator.chooser(t_s)

        def allow(track: Track) -> str | None:
            if unsettled(track, belt_velocity_mps, self._cfg):
                return "unsettled"
            return allocation(track)

        return allow

    def _joint_meeting(
        self, track: Track, t_s: float, tracks: Sequence[Track]
    ) -> JointApproach | None:
        """:func:`~control.poses.solve_meeting` from the current joint state, cached per track
        for the tick ``t_s`` (the scheduler's estimate and the chosen move are the same
        computation)."""
        if t_s != self._meetings_t_s:
            self._meetings.clear()
            self._meetings_t_s = t_s
        if track.track_id not in self._meetings:
            self._meetings[track.track_id] = solve_meeting(
                track,
                t_s,
                kinematics=self._kin,
                joint_planner=self._joint_planner,
                config=self._cfg,
                q_now=np.array(self._commander.q),
                q_ready=self.q_ready,
                tcp_yaw_rad=self._planner.state.position[3],
                clear_rise_m=clearance_rise_m(track, tracks, self._cfg),
            )
        return self._meetings[track.track_id]

    def _plan_joint_approach(
        self, track: Track, t_s: float, tracks: Sequence[Track]
    ) -> JointApproach | None:
        """Start the joint-space move of :meth:`_joint_meeting`; None when there is none."""
        meeting = self._joint_meeting(track, t_s, tracks)
        if meeting is None:
            return None
        goal = meeting.goal
        assert goal.dq is not None
        try:
            self._joint_planner.start_move(goal.q, goal.dq, min_duration_s=goal.arrive_s - t_s)
        except PlanningError:
            return None
        return meeting

    def _correct_joint_approach(self, now: TickInput) -> None:
        """Re-plan the joint-space approach when the target's latest prediction moved its
        meeting point by more than half ``pick.arrive_tolerance_m``: the same arrival time, the
        grasp yaw of the plan, from the joint planner's current state. The meeting point is
        the object's :func:`~control.poses.meeting_lead_s` after the arrival, where the
        hand-over to the Cartesian approach looks for it.

        The move is planned on a young track, whose velocity is still a few percent off: at
        0.6 m/s the meeting point moves by 1-2 cm while the arm travels, and the arm would reach
        the pick window's exit catching up with the object. Not in the last
        :data:`JOINT_REPLAN_UNTIL_S` (the Cartesian approach corrects the rest), nor when the
        arm is still in the move of the previous pick (its state is not the move's).
        """
        motion, cfg = self._motion, self._cfg
        approach = motion.joint_approach
        if approach is None or not motion.joint_mode:
            return
        goal = approach.goal
        remaining_s = goal.arrive_s - now.t_s
        arrive_cmd_s = goal.arrive_s + meeting_lead_s(cfg)  # where the hand-over checks it
        obj = self._object_state(arrive_cmd_s, now.belt_velocity_mps, now_s=now.t_s)
        if obj is None or remaining_s <= JOINT_REPLAN_UNTIL_S or goal.dq is None:
            return
        (x, y, z), (vx, vy, _) = obj
        assert self._pursuit.target is not None
        z += approach_rise_m(self._pursuit.target, cfg, self._pursuit.clear_rise_m)
        planned = self._kin.fk(goal.q).translation
        if math.dist((x, y, z), planned) <= 0.5 * cfg.pick.arrive_tolerance_m:
            return
        result = self._kin.solve(tool_pose((x, y, z), approach.yaw_rad), goal.q)
        if not result.success:
            return
        q = np.array(result.q)
        dq = self._kin.joint_velocity(q, np.array([vx, vy, 0.0, 0.0]))
        try:
            self._joint_planner.start_move(q, dq, min_duration_s=remaining_s)
        except PlanningError:
            with contextlib.suppress(PlanningError):  # keep to the move as planned
                self._joint_planner.start_move(goal.q, goal.dq, min_duration_s=remaining_s)
            return
        motion.joint_approach = JointApproach(
            goal=JointGoal(q=q, dq=dq, arrive_s=goal.arrive_s), yaw_rad=approach.yaw_rad
        )

    def _object_state(
        self, t_s: float, belt_velocity_mps: tuple[float, float], *, now_s: float | None = None
    ) -> tuple[Vec3, Vec3] | None:
        """Predicted grasp point and velocity of the target at ``t_s``.

        While the target is not in the current tracks (``now_s`` after the last sighting), it is
        extrapolated with the measured belt velocity.
        """
        track = self._pursuit.target
        if track is None:
            return None
        velocity = track.velocity_mps
        unseen = (t_s if now_s is None else now_s) > self._pursuit.seen_s
        if unseen and all(math.isfinite(v) for v in belt_velocity_mps):
            velocity = belt_velocity_mps
        dt_s = t_s - track.stamp_s
        dx_m, dy_m = self._cfg.tool.grasp_offset_m(track)
        x = track.position_m[0] + dx_m + velocity[0] * dt_s
        y = track.position_m[1] + dy_m + velocity[1] * dt_s
        return (x, y, grasp_height_m(track, self._cfg)), (velocity[0], velocity[1], 0.0)

    def _track_target(self, t_s: float, tracks: Sequence[Track]) -> bool:
        """Refresh the target snapshot; False when it has been lost for too long."""
        pursuit = self._pursuit
        if pursuit.target is None:
            return False
        for track in tracks:
            if track.track_id == pursuit.target.track_id:
                pursuit.target = track
                pursuit.seen_s = t_s
                pursuit.grasp_yaw_rad = nearest_grasp_yaw(
                    track.yaw_rad, pursuit.grasp_yaw_rad, self._cfg.tool.grasp_yaw_period_rad
                )
                return True
        return t_s - pursuit.seen_s <= self._cfg.pick.lost_timeout_s

    def _following_target(
        self, t_s: float, belt_velocity_mps: tuple[float, float], height_m: float
    ) -> tuple[CartesianTarget, Vec3]:
        """Ruckig goal ``height_m`` above the target's grasp point, and the grasp point itself.

        The goal is the target's predicted state (position and velocity) when the command takes
        effect: the planner meets the moving object itself (:meth:`CartesianPlanner.step`).
        """
        t_cmd = t_s + self._cfg.motion.command_latency_s
        obj = self._object_state(t_cmd, belt_velocity_mps, now_s=t_s)
        if obj is None:
            msg = "following without a target"
            raise ControlError(msg)
        (x, y, z), (vx, vy, _) = obj
        target = CartesianTarget(
            position=(x, y, z + height_m, self._pursuit.grasp_yaw_rad),
            velocity=(vx, vy, 0.0, 0.0),
        )
        return target, (x, y, z)

    def _meeting_in_s(self, target: CartesianTarget, t_s: float) -> float | None:
        """Time (s) from now at which the approach meets the moving target: no sooner than the
        scheduler planned (:attr:`_Motion.meet_s`), nor than the target is a run-up past the
        pick window's entry (the distance in which the arm, from rest, gets to the belt's
        speed). None: as soon as the planner can.

        The planner meets the object itself, moving with it, at that time: where the scheduler
        found the arm can reach it, in the window (the arm does not chase it upstream, to the
        edge of the workspace), and never waiting at rest at the window's entry while the
        object comes (the arm would then have to catch up with it).
        """
        x, vx = target.position[0], target.velocity[0]
        until_s = self._motion.meet_s - t_s
        if vx > 0.0:
            # a run-up past the entry, and a control period (the setpoints are samples of it)
            run_up_m = self._run_up(vx)[1] + vx * self._cfg.motion.control_period_s
            x_entry = self._cfg.pick_window_x_m[0] + run_up_m
            until_s = max(until_s, (x_entry - x) / vx)
        return until_s if until_s > self._cfg.motion.control_period_s else None

    def _run_up(self, speed_mps: float) -> tuple[float, float]:
        """Time (s) and distance (m) along x in which the TCP gets from rest to ``speed_mps``
        (a jerk-limited ramp at the x limits)."""
        motion = self._cfg.motion
        a, j = motion.max_acceleration[0], motion.max_jerk[0]
        time_s = speed_mps / a + a / j
        return time_s, 0.5 * speed_mps * time_s

    def _arrived(self, target: CartesianTarget) -> bool:
        """True when the setpoint is on the moving target (position and velocity) and the joint
        command on the setpoint (not still catching up within the joint limits)."""
        if not self._commander.on_goal:
            return False
        return self._on_target(target, self._cfg.pick.arrive_tolerance_m)

    def _on_target(self, target: CartesianTarget, tolerance_m: float) -> bool:
        """True when the setpoint is within ``tolerance_m`` of the moving target, as it was a
        control period ago, and moves with it (``pick.arrive_speed_tolerance_mps``)."""
        state = self._planner.state
        period_s = self._cfg.motion.control_period_s
        previous = [
            p - v * period_s for p, v in zip(target.position[:3], target.velocity[:3], strict=True)
        ]
        relative_speed = math.dist(state.velocity[:3], target.velocity[:3])
        return (
            math.dist(state.position_m, previous) <= tolerance_m
            and relative_speed <= self._cfg.pick.arrive_speed_tolerance_mps
        )

    # -- the tool -----------------------------------------------------------------------------
    def _grasp_command(self) -> float:
        """The tool's command when it grasps the target."""
        target = self._pursuit.target
        width = target.width_m if target is not None else 0.0
        return self._cfg.tool.grasp_command(width, self._cfg.pick.grip_squeeze_m)

    def _tool_command(self) -> float:
        phase = self._phase
        grasping = (
            phase == Phase.CLOSE
            or (self._pursuit.carrying and phase in (Phase.LIFT, Phase.CARRY))
            or (self._cfg.timing.grasp_on_descent and phase in (Phase.DESCEND, Phase.DWELL))
        )
        return self._grasp_command() if grasping else self._cfg.tool.open_command

    def _grasp_complete(self) -> bool:
        """The tool, commanded to grasp, measures its grasp complete
        (:meth:`~control.tools.ControllerTool.grasp_complete`)."""
        return self._tool_command() != self._cfg.tool.open_command and (
            self._cfg.tool.grasp_complete(self._measured.tool_measured)
        )

    def _holds_nothing(self) -> bool:
        """The tool, commanded to grasp, measured within ``pick.grip_check_margin_m`` of its
        command: nothing held it back (:meth:`~control.tools.ControllerTool.holds_nothing`)."""
        return self._cfg.tool.holds_nothing(
            self._measured.tool_measured,
            self._grasp_command(),
            self._cfg.pick.grip_check_margin_m,
        )

    # -- motion -------------------------------------------------------------------------------
    def _at_joint_goal(self, goal: JointGoal) -> bool:
        return bool(np.max(np.abs(self._commander.q - goal.q)) < 1e-4)

    def _sync_cartesian(self, q: FloatArray, dq: FloatArray) -> None:
        oMtool = self._kin.fk(q)  # noqa: N806
        p = oMtool.translation
        vmax = self._cfg.motion.max_velocity
        v = np.clip(self._kin.tcp_velocity(q, dq), -np.asarray(vmax), np.asarray(vmax))
        self._planner.reset(
            CartesianState(
                position=(float(p[0]), float(p[1]), float(p[2]), yaw_of(oMtool)),
                velocity=(float(v[0]), float(v[1]), float(v[2]), float(v[3])),
            )
        )

    def _posture_scale(self) -> float:
        """The scale of the Cartesian acceleration limits that the joints can follow in the
        current posture (``motion.posture_acceleration_margin`` of their datasheet limits, with
        every axis at its limit at once, or in the descent and the lift the shares
        ``motion.vertical_posture_axes`` of them; 1 when that is more than the limits, or off)."""
        motion = self._cfg.motion
        margin = motion.posture_acceleration_margin
        if margin <= 0.0:
            return 1.0
        rates = np.abs(self._kin.tilt_held_rates(self._commander.q))
        budget = np.asarray(motion.max_acceleration)
        if self._phase in (Phase.DESCEND, Phase.LIFT):
            budget = budget * np.asarray(motion.vertical_posture_axes)
        needed = rates @ budget
        limits = margin * np.asarray(self._kin.acceleration_limit_rps2)
        scale = float(np.min(limits / np.maximum(needed, 1e-12)))
        return min(1.0, max(scale, MIN_POSTURE_SCALE))

    def _step_joint(self, goal: JointGoal) -> None:
        motion = self._motion
        if not motion.joint_mode:
            # the joint move continues the commands' own velocity (the arm's, within limits)
            self._joint_planner.reset(self._commander.q, self._commander.dq)
            motion.joint_mode = True
        try:
            step = (
                self._joint_planner.step(goal.q)
                if goal.dq is None
                else self._joint_planner.follow()  # a move planned at its start; cannot fail
            )
        except PlanningError as exc:
            self._book.error("ruckig_error", f"{self._phase}: {exc}")
            return
        motion.joint_remaining_s = step.remaining_s
        self._commander.reset(step.q, step.dq)
        self._sync_cartesian(step.q, step.dq)

    def _step_cartesian(
        self, target: CartesianTarget, now: TickInput, *, min_duration_s: float | None = None
    ) -> None:
        motion = self._motion
        try:
            step = self._planner.step(
                target,
                acceleration_scale=self._posture_scale(),
                min_duration_s=min_duration_s,
            )
            motion.yaw_remaining_s = step.yaw_remaining_s
        except PlanningError as exc:
            self._book.error("ruckig_error", f"{self._phase}: {exc}")
            if self._pursuit.target is not None and not self._pursuit.carrying:
                self._abort("ruckig_error", now.t_s)
                goal = self._plan(replace(now, tracks=())).target
                if isinstance(goal, JointGoal):
                    self._step_joint(goal)
                else:
                    with contextlib.suppress(PlanningError):
                        self._planner.step(goal)

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
        motion = self._motion
        try:
            self._commander.command(
                position, setpoint.position[3], ticks=motion.ticks_since_command
            )
            motion.ticks_since_command = 1
            if not self._commander.on_goal and self._phase in FOLLOWING_PHASES:
                # the arm was told to go where the command is, not to the setpoint: the
                # feedback compares it with that, and does not wind up on the command's lag
                lag = np.asarray(position) - self._kin.fk(self._commander.q).translation
                self._feedback.shift_last((-float(lag[0]), -float(lag[1]), -float(lag[2])))
            elif not self._commander.on_goal and self._phase == Phase.APPROACH:
                # the setpoint ran ahead of what the joints can do: plan on from where they are
                self._sync_cartesian(self._commander.q, self._commander.dq)
        except IkError as exc:
            self._book.error("ik_failure", f"{self._phase}: {exc}")
            self._commander.brake()
            motion.ticks_since_command += 1
            limit = self._cfg.pick.ik_failures_to_abort
            if (
                self._pursuit.target is not None
                and not self._pursuit.carrying
                and motion.ticks_since_command > limit
            ):
                self._abort("ik_failure", t_s)
        return position
