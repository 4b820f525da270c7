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

The phase machine is :mod:`control.phases` (one handler per :class:`Phase`, run until one
returns the tick's :class:`Goal`); it plans where to meet the target with
:mod:`control.intercept`, moves with :mod:`control.motion` and commands the tool with
:mod:`control.grasp`; the values they share are :mod:`control.pick_state`'s. This module adds
the tick (:meth:`PickController.update`) and the public view.

On a line of several stations the controller claims its target (:mod:`control.allocation`):
each :class:`Command` carries the claims of its tick (``claimed`` when a pick starts,
``released`` when it ends without the object, ``picked`` when the tool holds it), the boards
the cell relays come in through :meth:`PickController.apply_claims`, the scheduler leaves what
the allocation gives to other stations, and a target that a station further upstream claims as
well is given up before the tool acts on it.
"""

from __future__ import annotations

import contextlib
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import replace

from control import grasp
from control.allocation import Claim
from control.errors import PlanningError
from control.grasp import OVERLAP_MARGIN_M
from control.ik import Kinematics
from control.intercept import JOINT_REPLAN_UNTIL_S
from control.motion import MIN_POSTURE_SCALE
from control.phases import PhaseMachine
from control.pick_state import (
    Command,
    Goal,
    PickStats,
    TcpMeasurement,
    TickInput,
    Transition,
    Vec3,
)
from control.planner import CartesianTarget
from control.poses import JointGoal
from control.tracking import Track
from interfaces.phases import FOLLOWING_PHASES, PURSUIT_PHASES, Phase


class PickController(PhaseMachine):
    """Pick state machine; pure logic, driven by :meth:`update` at the control rate."""

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
        self._move.cfg = self._intercept.cfg = self._cfg

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
            rate_limited=self._move.commander.rate_limited,
            sync_fallbacks=self._move.planner.sync_fallbacks
            + self._move.joint_planner.sync_fallbacks,
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
            self._move.step_joint(plan.target, self._phase)
            self._move.feedback.reset()
            position = self._move.planner.state.position_m
        else:
            self._move.state.joint_mode = False
            self._step_cartesian(plan.target, now, min_duration_s=plan.min_duration_s)
            position = self._command_cartesian(t_s, measured_tcp)
        target = self._pursuit.target
        return Command(
            t_s=t_s,
            phase=self._phase,
            target_id=target.track_id if target is not None else None,
            setpoint=self._move.planner.state,
            commanded_position_m=position,
            joint_positions_rad=tuple(float(v) for v in self._move.commander.q),
            tool_command=grasp.tool_command(self._cfg, self._phase, self._pursuit),
            grasp_point_m=plan.aim_m,
            claims=self._take_claims(),
        )

    def _take_claims(self) -> tuple[Claim, ...]:
        claims = tuple(self._claims_out)
        self._claims_out.clear()
        return claims

    # -- motion -------------------------------------------------------------------------------
    def _step_cartesian(
        self, target: CartesianTarget, now: TickInput, *, min_duration_s: float | None = None
    ) -> None:
        """One Cartesian step; after a Ruckig error a pursuit is aborted and the phase it
        switches to plans the tick's step instead."""
        if self._move.step_cartesian(target, self._phase, min_duration_s=min_duration_s):
            return
        if self._pursuit.target is not None and not self._pursuit.carrying:
            self._abort("ruckig_error", now.t_s)
            goal = self._plan(replace(now, tracks=())).target
            if isinstance(goal, JointGoal):
                self._move.step_joint(goal, self._phase)
            else:
                with contextlib.suppress(PlanningError):
                    self._move.planner.step(goal)

    def _command_cartesian(self, t_s: float, measured_tcp: TcpMeasurement) -> Vec3:
        """The tick's joint command from the Cartesian setpoint; a pursuit is aborted once the
        IK has failed for too many ticks in a row."""
        position, failing = self._move.command_cartesian(self._phase, measured_tcp)
        if failing and self._pursuit.target is not None and not self._pursuit.carrying:
            self._abort("ik_failure", t_s)
        return position


__all__ = [
    "FOLLOWING_PHASES",
    "JOINT_REPLAN_UNTIL_S",
    "MIN_POSTURE_SCALE",
    "OVERLAP_MARGIN_M",
    "PURSUIT_PHASES",
    "Command",
    "Goal",
    "Phase",
    "PickController",
    "PickStats",
    "TcpMeasurement",
    "TickInput",
    "Transition",
]
