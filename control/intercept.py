"""Where and when the pick meets its moving target: prediction, the joint-space meeting and the
Cartesian approach's timing.

Pure logic, one part of :class:`control.pick.PickController`. The target's grasp point is
predicted to the time a command takes effect (:meth:`Intercept.object_state`, extrapolated with
the measured belt velocity while the target is unseen); the Cartesian phases follow it
(:meth:`Intercept.following_target`, a Ruckig goal of position *and* velocity). With
``pick.approach_space: joint`` the approach starts as one time-optimal joint move that arrives
above the object with its velocity (:func:`control.poses.solve_meeting`, cached per track for
the tick: the scheduler's estimate and the chosen move are the same computation), re-planned
while the young track's prediction moves (:meth:`Intercept.correct_joint_approach`) and handed
over to the Cartesian approach when it arrives; the Cartesian approach meets the object no
sooner than the scheduler planned nor before a run-up past the window's entry
(:meth:`Intercept.meeting_in_s`).
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence

import numpy as np

from control.config import ControllerConfig
from control.errors import ControlError, PlanningError
from control.ik import Kinematics, tool_pose
from control.motion import PickMotion
from control.pick_state import FloatArray, Pursuit, TickInput, Vec3
from control.planner import CartesianTarget
from control.poses import JointApproach, JointGoal, meeting_lead_s, solve_meeting
from control.scheduler import (
    approach_rise_m,
    clearance_rise_m,
    grasp_height_m,
    held_x_m,
    nearest_grasp_yaw,
)
from control.tracking import Track

JOINT_REPLAN_UNTIL_S = 0.1
"""The joint-space approach is re-planned to the target's latest prediction until this long
(s) before it arrives; later corrections are left to the Cartesian approach that follows."""

EARLY_RECHECK_S = 0.1
"""While the arm rests, a track whose meeting had the arm above it before it enters the pick
window (``upstream``) is not solved again until, at that meeting's duration, it would be less
than this long (at its speed) from the window's entry (:meth:`Intercept.approach_estimate`)."""


class Intercept:
    """The meeting planning of one controller: its target (``pursuit``), its motion
    (``move``), the ready pose ``q_ready`` ``(n_arm,)``."""

    def __init__(
        self,
        config: ControllerConfig,
        kinematics: Kinematics,
        *,
        move: PickMotion,
        pursuit: Pursuit,
        q_ready: FloatArray,
    ) -> None:
        self.cfg = config
        self.kin = kinematics
        self.move = move
        self.pursuit = pursuit
        self.q_ready = q_ready
        self._meetings: dict[int, JointApproach | None] = {}
        self._meetings_t_s = math.nan
        self._early: dict[int, float] = {}  # track id: the duration (s) of its early meeting
        self._late: set[int] = set()  # track ids met too late
        self._rest_version = -1  # the joint command's version while those were found

    def object_state(
        self, t_s: float, belt_velocity_mps: tuple[float, float], *, now_s: float | None = None
    ) -> tuple[Vec3, Vec3] | None:
        """Predicted grasp point and velocity of the target at ``t_s``.

        While the target is not in the current tracks (``now_s`` after the last sighting), it is
        extrapolated with the measured belt velocity.
        """
        track = self.pursuit.target
        if track is None:
            return None
        velocity = track.velocity_mps
        unseen = (t_s if now_s is None else now_s) > self.pursuit.seen_s
        if unseen and all(math.isfinite(v) for v in belt_velocity_mps):
            velocity = belt_velocity_mps
        dt_s = t_s - track.stamp_s
        dx_m, dy_m = self.cfg.tool.grasp_offset_m(track)
        x = track.position_m[0] + dx_m + velocity[0] * dt_s
        y = track.position_m[1] + dy_m + velocity[1] * dt_s
        return (x, y, grasp_height_m(track, self.cfg)), (velocity[0], velocity[1], 0.0)

    def track_target(self, t_s: float, tracks: Sequence[Track]) -> bool:
        """Refresh the target snapshot; False when it has been lost for too long."""
        pursuit = self.pursuit
        if pursuit.target is None:
            return False
        for track in tracks:
            if track.track_id == pursuit.target.track_id:
                pursuit.target = track
                pursuit.seen_s = t_s
                pursuit.grasp_yaw_rad = nearest_grasp_yaw(
                    track.yaw_rad, pursuit.grasp_yaw_rad, self.cfg.tool.grasp_yaw_period_rad
                )
                return True
        return t_s - pursuit.seen_s <= self.cfg.pick.lost_timeout_s

    def following_target(
        self, t_s: float, belt_velocity_mps: tuple[float, float], height_m: float
    ) -> tuple[CartesianTarget, Vec3]:
        """Ruckig goal ``height_m`` above the target's grasp point, and the grasp point itself.

        The goal is the target's predicted state (position and velocity) when the command takes
        effect: the planner meets the moving object itself (:meth:`CartesianPlanner.step`).
        """
        t_cmd = t_s + self.cfg.motion.command_latency_s
        obj = self.object_state(t_cmd, belt_velocity_mps, now_s=t_s)
        if obj is None:
            msg = "following without a target"
            raise ControlError(msg)
        (x, y, z), (vx, vy, _) = obj
        target = CartesianTarget(
            position=(x, y, z + height_m, self.pursuit.grasp_yaw_rad),
            velocity=(vx, vy, 0.0, 0.0),
        )
        return target, (x, y, z)

    def meeting_in_s(self, target: CartesianTarget, t_s: float) -> float | None:
        """Time (s) from now at which the approach meets the moving target: no sooner than the
        scheduler planned (:attr:`control.pick_state.MotionState.meet_s`), nor than the target
        is a run-up past the pick window's entry (the distance in which the arm, from rest, gets
        to the belt's speed). None: as soon as the planner can.

        The planner meets the object itself, moving with it, at that time: where the scheduler
        found the arm can reach it, in the window (the arm does not chase it upstream, to the
        edge of the workspace), and never waiting at rest at the window's entry while the
        object comes (the arm would then have to catch up with it).
        """
        x, vx = target.position[0], target.velocity[0]
        until_s = self.move.state.meet_s - t_s
        if vx > 0.0:
            # a run-up past the entry, and a control period (the setpoints are samples of it)
            run_up_m = self.move.run_up(vx)[1] + vx * self.cfg.motion.control_period_s
            x_entry = self.cfg.pick_window_x_m[0] + run_up_m
            until_s = max(until_s, (x_entry - x) / vx)
        return until_s if until_s > self.cfg.motion.control_period_s else None

    def joint_meeting(
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
                kinematics=self.kin,
                joint_planner=self.move.joint_planner,
                config=self.cfg,
                q_now=np.array(self.move.commander.q),
                q_ready=self.q_ready,
                tcp_yaw_rad=self.move.planner.state.position[3],
                clear_rise_m=clearance_rise_m(track, tracks, self.cfg),
            )
        return self._meetings[track.track_id]

    def approach_estimate(self, track: Track, t_s: float, tracks: Sequence[Track]) -> float:
        """The scheduler's time (s) until the arm can be above ``track`` with a joint-space move
        (:meth:`joint_meeting`; ``inf`` when there is none).

        An idle station asks about every track it may take, every ``scheduler.replan_period_s``
        (on the reference cell every tick), and most answers do not change while the arm rests:
        a track the arm would meet before it enters the window (``upstream``) stays so while it
        is more than :data:`EARLY_RECHECK_S` from the entry at that meeting's duration, which
        is then returned again (the scheduler finds it ``upstream`` again); a track moving
        downstream that the arm would hold only past the window's exit (``too_late``) cannot
        become reachable while the arm rests (it only moves on), and is ``inf``. Neither is
        solved again until the joint command changes (:attr:`JointCommander.version`). Not
        bit for bit the answers of solving every time (a track's estimate moves a little with
        each frame); ``docs/benchmarks.md`` (issue 37) measures what it changes.
        """
        version = self.move.commander.version
        if version != self._rest_version or len(self._early) + len(self._late) > 4 * len(tracks):
            self._early.clear()
            self._late.clear()
            self._rest_version = version
        track_id, downstream = track.track_id, track.velocity_mps[0] > 0.0
        if downstream:
            if track_id in self._late:
                return math.inf
            early_s = self._early.get(track_id)
            if early_s is not None and self._well_upstream(track, t_s, early_s):
                return early_s
        meeting = self.joint_meeting(track, t_s, tracks)
        if meeting is None:
            return math.inf
        approach_s = meeting.goal.arrive_s - t_s
        if downstream:
            if held_x_m(track, t_s, approach_s, self.cfg) > self.cfg.pick_window_x_m[1]:
                self._late.add(track_id)
            elif self._well_upstream(track, t_s, approach_s):
                self._early[track_id] = approach_s
        return approach_s

    def _well_upstream(self, track: Track, t_s: float, approach_s: float) -> bool:
        """Whether ``track`` (moving downstream) is still more than :data:`EARLY_RECHECK_S` at
        its speed from the window's entry when an approach of ``approach_s`` would be over."""
        x_above, _ = track.position_at(t_s + approach_s)
        x_min = self.cfg.pick_window_x_m[0]
        return x_above < x_min - track.velocity_mps[0] * EARLY_RECHECK_S

    def plan_joint_approach(
        self, track: Track, t_s: float, tracks: Sequence[Track]
    ) -> JointApproach | None:
        """Start the joint-space move of :meth:`joint_meeting`; None when there is none."""
        meeting = self.joint_meeting(track, t_s, tracks)
        if meeting is None:
            return None
        goal = meeting.goal
        assert goal.dq is not None
        try:
            self.move.joint_planner.start_move(goal.q, goal.dq, min_duration_s=goal.arrive_s - t_s)
        except PlanningError:
            return None
        return meeting

    def correct_joint_approach(self, now: TickInput) -> None:
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
        motion, cfg = self.move.state, self.cfg
        approach = motion.joint_approach
        if approach is None or not motion.joint_mode:
            return
        goal = approach.goal
        remaining_s = goal.arrive_s - now.t_s
        arrive_cmd_s = goal.arrive_s + meeting_lead_s(cfg)  # where the hand-over checks it
        obj = self.object_state(arrive_cmd_s, now.belt_velocity_mps, now_s=now.t_s)
        if obj is None or remaining_s <= JOINT_REPLAN_UNTIL_S or goal.dq is None:
            return
        (x, y, z), (vx, vy, _) = obj
        assert self.pursuit.target is not None
        z += approach_rise_m(self.pursuit.target, cfg, self.pursuit.clear_rise_m)
        planned = self.kin.fk(goal.q).translation
        if math.dist((x, y, z), planned) <= 0.5 * cfg.pick.arrive_tolerance_m:
            return
        result = self.kin.solve(tool_pose((x, y, z), approach.yaw_rad), goal.q)
        if not result.success:
            return
        q = np.array(result.q)
        dq = self.kin.joint_velocity(q, np.array([vx, vy, 0.0, 0.0]))
        joint_planner = self.move.joint_planner
        try:
            joint_planner.start_move(q, dq, min_duration_s=remaining_s)
        except PlanningError:
            with contextlib.suppress(PlanningError):  # keep to the move as planned
                joint_planner.start_move(goal.q, goal.dq, min_duration_s=remaining_s)
            return
        motion.joint_approach = JointApproach(
            goal=JointGoal(q=q, dq=dq, arrive_s=goal.arrive_s), yaw_rad=approach.yaw_rad
        )


__all__ = ["EARLY_RECHECK_S", "JOINT_REPLAN_UNTIL_S", "Intercept"]
