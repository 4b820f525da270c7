"""The pick's motion: Cartesian and joint stepping, the joint commander, posture and feedback.

Pure logic, one part of :class:`control.pick.PickController` (its phase machine decides what to
reach; :mod:`control.intercept` where the object will be). Each tick the controller asks for one
step, towards a Cartesian target (Ruckig on the TCP, :class:`control.planner.CartesianPlanner`,
its acceleration scaled to what the joints can follow in the current posture) or a joint goal
(:class:`control.planner.JointPlanner`); the Cartesian setpoint, with the feedback term while the
TCP follows the object, goes through the IK to the joint commander
(:class:`control.planner.JointCommander`), which keeps every joint command within the limits.
Errors are counted in the controller's book; whether they abort the pick is the controller's
call.
"""

from __future__ import annotations

import math

import numpy as np

from control.commander import FeedbackTerm, JointCommander
from control.config import ControllerConfig
from control.errors import IkError, PlanningError
from control.ik import Kinematics, yaw_of
from control.pick_state import FloatArray, MotionState, PickBook, TcpMeasurement, Vec3
from control.planner import (
    CartesianPlanner,
    CartesianState,
    CartesianTarget,
    JointPlanner,
    JointStep,
)
from control.poses import JointGoal
from interfaces.phases import FOLLOWING_PHASES, Phase

MIN_POSTURE_SCALE = 0.05
"""The least :meth:`PickMotion.posture_scale` (near a singularity the joints' needs grow
without bound; the Cartesian moves still finish)."""


class PickMotion:
    """The planners, the commander and the feedback term of one controller, starting at joint
    positions ``q0`` ``(n_arm,)`` whose TCP state is ``start``; errors go to ``book``."""

    def __init__(
        self,
        config: ControllerConfig,
        kinematics: Kinematics,
        *,
        q0: FloatArray,
        start: CartesianState,
        drop_q: FloatArray,
        book: PickBook,
    ) -> None:
        self.cfg = config
        self.kin = kinematics
        self.planner = CartesianPlanner(config.motion, start)
        self.joint_planner = JointPlanner(kinematics, config.motion)
        self.commander = JointCommander(kinematics, config.motion, q0)
        self.feedback = FeedbackTerm(config.motion)
        self.state = MotionState(drop_q=drop_q)
        self.book = book
        self._held: tuple[JointStep, int, CartesianState] | None = None
        """The joint step, command version and setpoint of the last :meth:`step_joint`: a
        waiting arm's next step is the same object (:meth:`JointPlanner.step`), and when the
        command and setpoint have not changed since, resetting them again would not either."""

    def at_joint_goal(self, goal: JointGoal) -> bool:
        """The joint command is at ``goal`` (within 1e-4 rad)."""
        return bool(np.max(np.abs(self.commander.q - goal.q)) < 1e-4)

    def sync_cartesian(self, q: FloatArray, dq: FloatArray) -> None:
        """Restart the Cartesian planner from the TCP state of joints ``q``, ``dq`` ``(n_arm,)``
        (its velocity clipped to the Cartesian limits)."""
        oMtool = self.kin.fk(q)  # noqa: N806
        p = oMtool.translation
        vmax = self.cfg.motion.max_velocity
        v = np.clip(self.kin.tcp_velocity(q, dq), -np.asarray(vmax), np.asarray(vmax))
        self.planner.reset(
            CartesianState(
                position=(float(p[0]), float(p[1]), float(p[2]), yaw_of(oMtool)),
                velocity=(float(v[0]), float(v[1]), float(v[2]), float(v[3])),
            )
        )

    def posture_scale(self, phase: Phase) -> float:
        """The scale of the Cartesian acceleration limits that the joints can follow in the
        current posture (``motion.posture_acceleration_margin`` of their datasheet limits, with
        every axis at its limit at once, or in the descent and the lift the shares
        ``motion.vertical_posture_axes`` of them; 1 when that is more than the limits, or off)."""
        motion = self.cfg.motion
        margin = motion.posture_acceleration_margin
        if margin <= 0.0:
            return 1.0
        rates = np.abs(self.kin.tilt_held_rates(self.commander.q))
        budget = np.asarray(motion.max_acceleration)
        if phase in (Phase.DESCEND, Phase.LIFT):
            budget = budget * np.asarray(motion.vertical_posture_axes)
        needed = rates @ budget
        limits = margin * np.asarray(self.kin.acceleration_limit_rps2)
        scale = float(np.min(limits / np.maximum(needed, 1e-12)))
        return min(1.0, max(scale, MIN_POSTURE_SCALE))

    def step_joint(self, goal: JointGoal, phase: Phase) -> None:
        """One joint-space step towards ``goal`` (a move planned at its start when the goal has
        a velocity); a Ruckig error is counted and the command held."""
        motion = self.state
        if not motion.joint_mode:
            # the joint move continues the commands' own velocity (the arm's, within limits)
            self.joint_planner.reset(self.commander.q, self.commander.dq)
            motion.joint_mode = True
        try:
            step = (
                self.joint_planner.step(goal.q)
                if goal.dq is None
                else self.joint_planner.follow()  # a move planned at its start; cannot fail
            )
        except PlanningError as exc:
            self.book.error("ruckig_error", f"{phase}: {exc}")
            return
        motion.joint_remaining_s = step.remaining_s
        held = (step, self.commander.version, self.planner.state)
        if self._held is not None and all(a is b for a, b in zip(held, self._held, strict=True)):
            return  # at rest on the goal as last tick: the command and setpoint are as set then
        self.commander.reset(step.q, step.dq)
        self.sync_cartesian(step.q, step.dq)
        self._held = (step, self.commander.version, self.planner.state)

    def step_cartesian(
        self, target: CartesianTarget, phase: Phase, *, min_duration_s: float | None = None
    ) -> bool:
        """One Cartesian step towards ``target``; False after a Ruckig error (counted)."""
        try:
            step = self.planner.step(
                target,
                acceleration_scale=self.posture_scale(phase),
                min_duration_s=min_duration_s,
            )
            self.state.yaw_remaining_s = step.yaw_remaining_s
        except PlanningError as exc:
            self.book.error("ruckig_error", f"{phase}: {exc}")
            return False
        return True

    def command_cartesian(self, phase: Phase, measured_tcp: TcpMeasurement) -> tuple[Vec3, bool]:
        """The Cartesian setpoint (plus the feedback term while following) through the IK to
        the joint commander. Returns the commanded position and whether the IK has now failed
        for more than ``pick.ik_failures_to_abort`` ticks in a row (the command brakes)."""
        setpoint = self.planner.state
        position = setpoint.position_m
        if phase in FOLLOWING_PHASES:
            dt_s = self.cfg.motion.control_period_s
            correction = self.feedback.correction(position, measured_tcp.position_m, dt_s)
            position = (
                position[0] + correction[0],
                position[1] + correction[1],
                position[2] + correction[2],
            )
        else:
            self.feedback.reset()
        motion = self.state
        try:
            self.commander.command(position, setpoint.position[3], ticks=motion.ticks_since_command)
            motion.ticks_since_command = 1
            if not self.commander.on_goal and phase in FOLLOWING_PHASES:
                # the arm was told to go where the command is, not to the setpoint: the
                # feedback compares it with that, and does not wind up on the command's lag
                lag = np.asarray(position) - self.kin.fk(self.commander.q).translation
                self.feedback.shift_last((-float(lag[0]), -float(lag[1]), -float(lag[2])))
            elif not self.commander.on_goal and phase == Phase.APPROACH:
                # the setpoint ran ahead of what the joints can do: plan on from where they are
                self.sync_cartesian(self.commander.q, self.commander.dq)
        except IkError as exc:
            self.book.error("ik_failure", f"{phase}: {exc}")
            self.commander.brake()
            motion.ticks_since_command += 1
            return position, motion.ticks_since_command > self.cfg.pick.ik_failures_to_abort
        return position, False

    def run_up(self, speed_mps: float) -> tuple[float, float]:
        """Time (s) and distance (m) along x in which the TCP gets from rest to ``speed_mps``
        (a jerk-limited ramp at the x limits)."""
        motion = self.cfg.motion
        a, j = motion.max_acceleration[0], motion.max_jerk[0]
        time_s = speed_mps / a + a / j
        return time_s, 0.5 * speed_mps * time_s

    def arrived(self, target: CartesianTarget) -> bool:
        """True when the setpoint is on the moving target (position and velocity) and the joint
        command on the setpoint (not still catching up within the joint limits)."""
        if not self.commander.on_goal:
            return False
        return self.on_target(target, self.cfg.pick.arrive_tolerance_m)

    def on_target(self, target: CartesianTarget, tolerance_m: float) -> bool:
        """True when the setpoint is within ``tolerance_m`` of the moving target, as it was a
        control period ago, and moves with it (``pick.arrive_speed_tolerance_mps``)."""
        state = self.planner.state
        period_s = self.cfg.motion.control_period_s
        previous = [
            p - v * period_s for p, v in zip(target.position[:3], target.velocity[:3], strict=True)
        ]
        relative_speed = math.dist(state.velocity[:3], target.velocity[:3])
        return (
            math.dist(state.position_m, previous) <= tolerance_m
            and relative_speed <= self.cfg.pick.arrive_speed_tolerance_mps
        )


__all__ = ["MIN_POSTURE_SCALE", "PickMotion"]
