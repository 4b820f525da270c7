"""The pick's phase machine: one handler per :class:`interfaces.phases.Phase`, and the
transitions between them.

Each tick runs the handler of the current phase, from a table with one handler per phase. A
handler returns the tick's :class:`control.pick_state.Goal`, or a
:class:`control.pick_state.Transition` when it switched the phase: the new phase's handler then
runs in the same tick. Before the handler of a phase that pursues a target, the target checks
run (lost for too long, past the pick window, claimed upstream), and an abort they cause is a
transition as well. Where the target will be is :mod:`control.intercept`'s, how the arm gets
there :mod:`control.motion`'s, what the tool does :mod:`control.grasp`'s;
:class:`control.pick.PickController` adds the tick and the public view.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from control import grasp
from control.allocation import Allocator, Claim, ClaimState, claim_of
from control.config import ControllerConfig
from control.errors import ControlError
from control.ik import Kinematics, tool_pose, yaw_of
from control.intercept import Intercept
from control.motion import PickMotion
from control.pick_state import (
    FloatArray,
    Goal,
    Handler,
    PickBook,
    Pursuit,
    TcpMeasurement,
    TickInput,
    Transition,
)
from control.planner import CartesianState, CartesianTarget
from control.poses import JointGoal, best_grasp_yaw, drop_point, drop_pose
from control.scheduler import (
    Schedule,
    approach_rise_m,
    clearance_rise_m,
    nearest_grasp_yaw,
    schedule,
    unsettled,
)
from control.tracking import Track
from interfaces.phases import FOLLOWING_PHASES, PURSUIT_PHASES, Phase


class PhaseMachine:
    """The pick's state and its phase handlers; pure logic (:class:`control.pick.
    PickController` drives it at the control rate)."""

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
        self._pursuit = Pursuit(grasp_yaw_rad=config.ready_yaw_rad)
        self._book = PickBook()
        self._move = PickMotion(
            config, self._kin, q0=q0, start=start, drop_q=np.array(self.q_ready), book=self._book
        )
        self._intercept = Intercept(
            config, self._kin, move=self._move, pursuit=self._pursuit, q_ready=self.q_ready
        )
        self._allocator = Allocator(config)
        self._claims_out: list[Claim] = []
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
        if not self._intercept.track_target(now.t_s, now.tracks) and phase == Phase.APPROACH:
            self._abort("target_lost", now.t_s)
            return True
        if phase in FOLLOWING_PHASES and grasp.grasp_complete(
            self._cfg, phase, self._pursuit, self._measured
        ):
            self._grasped(now.t_s)  # held: carried to its bin, whatever else happens
            return True
        if phase == Phase.CLOSE and self._cfg.timing.close_max_s is None:
            return False
        target = self._pursuit.target
        if target is not None and self._allocator.must_yield(target, now.t_s):
            self._give_up(now.t_s)
            return True
        obj = self._intercept.object_state(now.t_s, now.belt_velocity_mps)
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
        pick, motion = self._cfg.pick, self._move.state
        almost_ready = motion.joint_mode and (
            motion.joint_remaining_s <= pick.schedule_before_ready_s
            or pick.approach_space == "joint"
        )
        if almost_ready:
            self._schedule(now.t_s, now.tracks, now.belt_velocity_mps)
            if self._phase != Phase.RETURN:
                return Transition(phase=self._phase, tracks=now.tracks)
        goal = JointGoal(q=self.q_ready)
        if (
            motion.joint_remaining_s <= self._cfg.motion.control_period_s
            and self._move.at_joint_goal(goal)
        ):
            self._set_phase(Phase.IDLE, now.t_s)
        return Goal(target=goal)

    def _on_approach(self, now: TickInput) -> Goal | Transition:
        """Above the moving target, turned to its grasp yaw; then the descent."""
        pick, motion, pursuit = self._cfg.pick, self._move.state, self._pursuit
        period_s = self._cfg.motion.control_period_s
        if motion.joint_approach is not None:
            if not (motion.joint_mode and motion.joint_remaining_s <= period_s):
                self._intercept.correct_joint_approach(now)
                assert motion.joint_approach is not None
                obj = self._intercept.object_state(now.t_s, now.belt_velocity_mps, now_s=now.t_s)
                aim = obj[0] if obj is not None else None
                return Goal(target=motion.joint_approach.goal, aim_m=aim)
            motion.joint_approach = None  # above the object, moving with it: Cartesian from here
            pursuit.grasp_yaw_rad = nearest_grasp_yaw(
                pursuit.grasp_yaw_rad,
                self._move.planner.state.position[3],
                self._cfg.tool.grasp_yaw_period_rad,
            )
            handed_over = True
        else:
            handed_over = False
        assert pursuit.target is not None
        rise_m = approach_rise_m(pursuit.target, self._cfg, pursuit.clear_rise_m)
        target, aim = self._intercept.following_target(now.t_s, now.belt_velocity_mps, rise_m)
        yaw_error = abs(self._move.planner.state.position[3] - target.position[3])
        yaw_ready = (
            yaw_error < pick.yaw_tolerance_rad or motion.yaw_remaining_s <= pick.descend_yaw_lead_s
        )
        near = handed_over and self._move.on_target(target, pick.handover_tolerance_m)
        if yaw_ready and (near or self._move.arrived(target)):
            self._set_phase(Phase.DESCEND, now.t_s)
            return Transition(phase=Phase.DESCEND, tracks=now.tracks, checked=True)
        return Goal(
            target=target, aim_m=aim, min_duration_s=self._intercept.meeting_in_s(target, now.t_s)
        )

    def _on_descend(self, now: TickInput) -> Goal | Transition:
        """Down to the grasp point, moving with the object; then the dwell (a tool without one
        goes on to its close in the same tick, once the yaw is aligned)."""
        target, aim = self._intercept.following_target(now.t_s, now.belt_velocity_mps, 0.0)
        grasp.note_overlap(self._cfg, self._pursuit, self._measured, now.t_s, aim)
        if self._move.arrived(target):
            self._set_phase(Phase.DWELL, now.t_s)
            if self._cfg.timing.dwell_s == 0.0:
                return Transition(phase=Phase.DWELL, tracks=now.tracks, checked=True)
        return Goal(target=target, aim_m=aim)

    def _on_dwell(self, now: TickInput) -> Goal | Transition:
        """At the grasp point for the dwell; the tool closes once the yaw is aligned."""
        pick = self._cfg.pick
        target, aim = self._intercept.following_target(now.t_s, now.belt_velocity_mps, 0.0)
        grasp.note_overlap(self._cfg, self._pursuit, self._measured, now.t_s, aim)
        yaw_error = abs(self._move.planner.state.position[3] - target.position[3])
        timing = self._cfg.timing
        since_s = min(self._phase_start_s, self._pursuit.overlap_s)  # NaN: the phase's start
        since_s = since_s if math.isfinite(since_s) else self._phase_start_s
        dwelt = now.t_s - since_s >= timing.dwell_s - timing.close_overlap_s
        if dwelt and yaw_error < pick.yaw_tolerance_rad and self._move.commander.on_goal:
            self._set_phase(Phase.CLOSE, now.t_s)
        return Goal(target=target, aim_m=aim)

    def _on_close(self, now: TickInput) -> Goal | Transition:
        """The tool grasps while following; then the grip check and the lift.

        After ``close_s`` a tool that holds nothing aborts (``grip_missed``). A tool that
        measures when its grasp is complete (``timing.close_max_s``) lifts once it is (the
        target checks lift it as soon as it is), and keeps following until then, up to
        ``close_max_s``; a grasp still not complete then is missed. Other tools, and a tool
        that is not measured, lift after ``close_s``.
        """
        timing = self._cfg.timing
        elapsed_s = (
            now.t_s
            - self._phase_start_s
            - grasp.seal_search(
                self._cfg, self._pursuit, self._measured, self._move.planner.state.position[2]
            )
        )
        if elapsed_s >= timing.close_s:
            if grasp.holds_nothing(self._cfg, self._pursuit, self._measured):
                self._abort("grip_missed", now.t_s)
                return Transition(phase=self._phase, tracks=())
            if timing.close_max_s is None or not math.isfinite(self._measured.tool_measured):
                self._grasped(now.t_s)
                return Transition(phase=Phase.LIFT, tracks=now.tracks)
            if elapsed_s >= timing.close_max_s:
                self._abort("grip_missed", now.t_s)
                return Transition(phase=self._phase, tracks=())
        depth_m = self._pursuit.seal_depth_m
        target, aim = self._intercept.following_target(now.t_s, now.belt_velocity_mps, -depth_m)
        return Goal(target=target, aim_m=aim)

    def _on_lift(self, now: TickInput) -> Goal | Transition:
        """Up from the belt; then the carry (holding the object) or the return."""
        pursuit = self._pursuit
        if pursuit.carrying and grasp.holds_nothing(self._cfg, self._pursuit, self._measured):
            self._abort("grip_missed", now.t_s)  # the tool finished closing on nothing
            self._set_phase(Phase.LIFT, now.t_s)  # the lift goes on, with the tool open
        lift = pursuit.lift_target
        if lift is None or (
            self._move.planner.state.position[2]
            >= lift.position[2] - 0.2 * self._cfg.pick.lift_height_m
        ):
            if pursuit.carrying:
                self._start_carry(now.t_s)
            else:
                self._set_phase(Phase.RETURN, now.t_s)
            return Transition(phase=self._phase, tracks=now.tracks)
        return Goal(target=lift)

    def _on_carry(self, now: TickInput) -> Goal | Transition:
        """The joint move to the drop pose; then the release."""
        goal = JointGoal(q=self._move.state.drop_q)
        if self._move.state.joint_remaining_s <= self._cfg.motion.control_period_s and (
            self._move.at_joint_goal(goal)
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
        return Goal(target=JointGoal(q=self._move.state.drop_q))

    # -- transitions --------------------------------------------------------------------------
    def _set_phase(self, phase: Phase, t_s: float) -> None:
        self._phase = phase
        self._phase_start_s = t_s
        if phase == Phase.CLOSE:
            self._pursuit.seal_depth_m = 0.0
            self._pursuit.seal_wait_s = 0.0
        if phase in (Phase.CARRY, Phase.RETURN):
            self._move.state.joint_remaining_s = math.inf  # until the new joint move's first step

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
        state = self._move.planner.state
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
        pursuit, motion, book = self._pursuit, self._move.state, self._book
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
        self._move.feedback.reset()
        motion.joint_approach = None
        if self._cfg.pick.approach_space == "joint" and motion.joint_mode:
            # the joint planner continues from the current joint move
            motion.joint_approach = self._intercept.plan_joint_approach(track, t_s, tracks)
        motion.joint_mode = motion.joint_approach is not None
        pursuit.grasp_yaw_rad = (
            motion.joint_approach.yaw_rad
            if motion.joint_approach is not None
            else best_grasp_yaw(
                track,
                intercept_s,
                kinematics=self._kin,
                config=self._cfg,
                q_now=self._move.commander.q,
                tcp_yaw_rad=self._move.planner.state.position[3],
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
        q_now = np.array(self._move.commander.q)
        x, y, z, yaw_now = self._move.planner.state.position
        drop = drop_point(self._cfg, class_name, (x, y, z), length_m)
        best = drop_pose(self._kin, self._cfg, drop, q_now, (x, y, yaw_now))
        if best is not None:
            self._move.state.drop_q = best
        else:
            self._book.error(
                "ik_failure", f"{self._phase}: no IK solution for the drop point {drop}"
            )
            self._book.aborted["drop_unreachable"] += 1
            self._move.state.drop_q = self._move.commander.q
        self._set_phase(Phase.CARRY, t_s)

    # -- targets ------------------------------------------------------------------------------
    def _schedule(
        self, t_s: float, tracks: Sequence[Track], belt_velocity_mps: tuple[float, float]
    ) -> None:
        if t_s < self._next_schedule_s:
            return  # found nothing a moment ago (``scheduler.replan_period_s``)
        estimate = None
        if self._cfg.pick.approach_space == "joint" and self._move.state.joint_mode:

            def estimate(track: Track) -> float:
                return self._intercept.approach_estimate(track, t_s, tracks)

        book = self._book
        result = schedule(
            tracks,
            now_s=t_s,
            tcp_position_m=self._move.planner.state.position_m,
            config=self._cfg,
            excluded_ids=book.excluded | book.targeted_ids,
            tcp_yaw_rad=self._move.planner.state.position[3],
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


__all__ = ["PhaseMachine"]
