"""The joint command of a Cartesian setpoint: the feedback correction and the joint commander.

:class:`FeedbackTerm` adds a clipped PI correction on the measured tracking error to the
Cartesian setpoint (:mod:`control.planner`'s), and :class:`JointCommander` turns the corrected
setpoint into joint positions with the warm-started IK, refusing anything outside the joint
limits and keeping the commands within the joints' velocity and acceleration limits.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from numpy.typing import NDArray

from control.config_sections import MotionConfig
from control.errors import IkError
from control.ik import IkResult, Kinematics, tool_pose

FloatArray = NDArray[np.float64]


class FeedbackTerm:
    """Clipped PI correction of the position setpoint from the measured tracking error.

    The measured TCP is compared with the setpoint of ``command_latency_s`` ago (the time the arm
    takes to reach a command and report it), so a pure measurement delay is not mistaken for a
    tracking error. Only x and y are corrected (the belt carries the object along them): the
    object's height does not change while it is followed, and a z error is the arm's lag in the
    descent or the tool resting on the object's top; integrating it would drive the tool into
    the object, then lift it off (a suction cup loses its seal).
    """

    def __init__(self, motion: MotionConfig) -> None:
        """Start with zero integral and no setpoint history."""
        self._kp = motion.feedback_kp
        self._ki = motion.feedback_ki_per_s
        self._limit = motion.feedback_max_m
        self._delay_ticks = max(round(motion.command_latency_s / motion.control_period_s), 0)
        self._history: deque[FloatArray] = deque(maxlen=self._delay_ticks + 1)
        self._integral = np.zeros(3)

    def reset(self) -> None:
        """Forget the integral and the history (call when a new target is tracked)."""
        self._integral = np.zeros(3)
        self._history.clear()

    def shift_last(self, offset_m: tuple[float, float, float]) -> None:
        """Move the latest setpoint of the history by ``offset_m`` (where the arm was actually
        commanded to go when the joint command could not reach the setpoint)."""
        if self._history:
            self._history[-1] = self._history[-1] + np.asarray(offset_m, dtype=np.float64)

    def correction(
        self,
        setpoint_m: tuple[float, float, float],
        measured_m: tuple[float, float, float],
        dt_s: float,
    ) -> tuple[float, float, float]:
        """The ``(3,)`` offset (m) to add to ``setpoint_m`` given the measured TCP position (its
        z is 0).

        ``setpoint_m`` is the corrected command of the previous ticks' series (the history is
        kept here). Non-finite measurements give no correction; the integral is clamped.
        """
        self._history.append(np.asarray(setpoint_m, dtype=np.float64))
        if len(self._history) <= self._delay_ticks:
            return (0.0, 0.0, 0.0)
        error = self._history[0] - np.asarray(measured_m, dtype=np.float64)
        if not np.all(np.isfinite(error)):
            return (0.0, 0.0, 0.0)
        error[2] = 0.0  # along the belt's plane only (see the class docstring)
        if self._ki > 0.0:
            self._integral = np.clip(
                self._integral + error * dt_s, -self._limit / self._ki, self._limit / self._ki
            )
        out = np.clip(self._kp * error + self._ki * self._integral, -self._limit, self._limit)
        return (float(out[0]), float(out[1]), float(out[2]))


ON_GOAL_RAD = 2e-3
"""A joint command this close to its IK solution (every joint) has landed on it."""


class JointCommander:
    """Cartesian setpoint to joint positions with the IK warm-started from the last command.

    The joint commands form a trajectory within the robot's joint velocity limits (times
    ``motion.joint_velocity_margin``) and datasheet acceleration limits, sampled every control
    period: between two commands no joint's velocity changes by more than its acceleration
    limit times the period. An arm that follows commands only within those limits (the real
    one, and the twin) then follows these exactly, with no lag of its own. Each IK solution is
    a moving goal: while the goal is reachable within the limits the command lands on it;
    otherwise each joint heads for it as fast as its limits allow, braking in time not to
    overshoot it (the tool lags and catches up).
    """

    def __init__(self, kinematics: Kinematics, motion: MotionConfig, q_init: FloatArray) -> None:
        """Start at rest at ``q_init`` ``(n_arm,) float`` (clipped into the limits)."""
        self._kin = kinematics
        self._dt_s = motion.control_period_s
        self._vmax = np.asarray(kinematics.velocity_limit_rps * motion.joint_velocity_margin)
        self._amax = np.asarray(kinematics.acceleration_limit_rps2, dtype=np.float64)
        self._dv = self._amax * self._dt_s
        self._q = np.clip(
            np.asarray(q_init, dtype=np.float64), kinematics.lower_rad, kinematics.upper_rad
        )
        self._dq = np.zeros_like(self._q)
        self._goal = self._q.copy()
        self._goal_dq = np.zeros_like(self._q)
        self.rate_limited = 0
        """Commands that could not land on the IK solution within the joint limits."""
        self.on_goal = True
        """Whether the last command landed on its IK solution (False while catching up)."""
        self.version = 0
        """Counts the changes of the command (every :meth:`reset` and period moved)."""

    @property
    def q(self) -> FloatArray:
        """The last joint command ``(n_arm,) float``."""
        return self._q.copy()

    @property
    def dq(self) -> FloatArray:
        """The joint velocity of the last command ``(n_arm,) float`` (rad/s)."""
        return self._dq.copy()

    def reset(self, q: FloatArray, dq: FloatArray | None = None) -> None:
        """Continue from ``q`` moving at ``dq`` (None: at rest), e.g. a joint-space move's
        latest step."""
        self._q = np.clip(np.asarray(q, dtype=np.float64), self._kin.lower_rad, self._kin.upper_rad)
        velocity = np.zeros_like(self._q) if dq is None else np.asarray(dq, dtype=np.float64)
        self._dq = np.clip(np.nan_to_num(velocity), -self._vmax, self._vmax)
        self._goal = self._q.copy()
        self._goal_dq = self._dq.copy()
        self.on_goal = True
        self.version += 1

    def command(
        self, position_m: tuple[float, float, float], yaw_rad: float, *, ticks: int = 1
    ) -> IkResult:
        """Solve the IK for the setpoint and move the command towards it.

        ``ticks`` is the number of control periods since the last solved setpoint (the goal's
        velocity is estimated over them). Raises ``IkError`` when the setpoint is not finite,
        the IK does not converge or the solution is outside the joint limits; the command is
        then unchanged (call :meth:`brake` to go on within the limits).
        """
        if not all(math.isfinite(v) for v in (*position_m, yaw_rad)):
            msg = f"non-finite Cartesian setpoint {position_m}, yaw {yaw_rad}"
            raise IkError(msg)
        result = self._kin.solve(tool_pose(position_m, yaw_rad), self._goal)  # its branch
        if not result.success:
            msg = (
                f"IK did not converge for position {position_m} yaw {yaw_rad:.3f} "
                f"(error {result.error_norm:.2e} after {result.iterations} iterations)"
            )
            raise IkError(msg)
        if not self._kin.within_limits(result.q):
            msg = f"IK solution {result.q} is outside the joint limits"
            raise IkError(msg)
        goal = np.asarray(result.q, dtype=np.float64)
        goal_dq = np.clip(
            (goal - self._goal) / (self._dt_s * max(ticks, 1)), -self._vmax, self._vmax
        )
        self._goal, self._goal_dq = goal, goal_dq
        self._advance(goal, goal_dq)
        return result

    def brake(self) -> None:
        """One control period on without a goal (the IK failed): every joint slows down at its
        acceleration limit, and stops at its position limits."""
        dq = np.sign(self._dq) * np.maximum(np.abs(self._dq) - self._dv, 0.0)
        self._move(dq)
        self.on_goal = False
        self._goal, self._goal_dq = self._q.copy(), self._dq.copy()

    def _advance(self, goal: FloatArray, goal_dq: FloatArray) -> None:
        """One control period towards ``goal`` moving at ``goal_dq``: land on it when the
        limits allow, otherwise close in as fast as they allow without overshooting."""
        dt, dv = self._dt_s, self._dv
        # the error relative to the goal as it was a period ago (where the command is now)
        ahead = goal - goal_dq * dt - self._q
        # closing speed relative to the goal from which the joint can still stop on it
        brake = np.sqrt(dv * dv + 2.0 * self._amax * np.abs(ahead)) - dv
        relative = np.clip(ahead / dt, -brake, brake)
        dq = np.clip(goal_dq + relative, self._dq - dv, self._dq + dv)
        dq = np.clip(dq, -self._vmax, self._vmax)
        self._move(dq)
        self.on_goal = float(np.max(np.abs(self._q - goal))) <= ON_GOAL_RAD
        self.rate_limited += not self.on_goal

    def _move(self, dq: FloatArray) -> None:
        """One control period at ``dq``, slowed where a joint could not otherwise stop at its
        position limit within its acceleration limit (an arm cannot stop dead at a limit)."""
        dv, amax = self._dv, self._amax
        room_up = np.maximum(self._kin.upper_rad - self._q, 0.0)
        room_down = np.maximum(self._q - self._kin.lower_rad, 0.0)
        stop_up = np.sqrt(dv * dv + 2.0 * amax * room_up) - dv
        stop_down = np.sqrt(dv * dv + 2.0 * amax * room_down) - dv
        capped = np.clip(dq, -stop_down, stop_up)
        # the cap changes the velocity by at most the acceleration limit's step
        dq = np.clip(capped, np.minimum(dq, self._dq - dv), np.maximum(dq, self._dq + dv))
        q = self._q + dq * self._dt_s
        clipped = np.clip(q, self._kin.lower_rad, self._kin.upper_rad)
        self._dq = np.where(clipped == q, dq, (clipped - self._q) / self._dt_s)
        self._q = clipped
        self.version += 1


__all__ = ["FeedbackTerm", "JointCommander"]
