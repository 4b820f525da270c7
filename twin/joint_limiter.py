"""Joint velocity and acceleration limits on the targets the twin hands its joint motors.

A real arm's joint controller never moves a joint faster than the datasheet allows, whatever it
is commanded: a position step is followed along a ramp. PyBullet's position-controlled motors
have no such limit (a 1 rad step moves a Panda joint at over 12 rad/s), so the twin puts a
limiter between the commands and the motors, one per arm, stepped at the physics rate.

Each new command (positions ``q_k``, velocities ``qd_k``, stamped ``dt_k`` after the previous
one) is checked against the previous one at their stamps, per joint: it continues a trajectory
within the limits when ``|qd_k - qd_{k-1}| <= a dt_k`` and
``|q_k - (q_{k-1} + qd_{k-1} dt_k)| <= a dt_k^2`` (``a`` the acceleration limit; ``dt_k`` counted
at most ``hold_s``, as long as a command's velocity moves its target on). Every trajectory within
the limits passes this check whether it is sampled with its exact velocities (deviation
``a dt^2 / 2``) or with backward differences (``a dt^2``), at any command rate of ``1 / hold_s``
or more, however late each command arrives; a jump, or a velocity change beyond the limit,
fails it.

A joint whose command passes keeps its commanded targets unchanged (the limiter only follows
them). A joint whose command fails is *limited*: its motor gets the limiter's reference instead,
a position ``p`` and velocity ``v`` with ``|v| <= velocity`` and ``|dv/dt| <= acceleration``.
Towards a resting target (a position step) the limited joints move on the time-optimal,
jerk-limited trajectory that brings them to rest there together (Ruckig, replanned every step,
as a robot's joint interpolator would); towards a moving one (a command with velocities) each
joint follows the time-optimal path of a double integrator that matches the target's position
and velocity, braking in time. Once the reference has caught up (within
:data:`CATCH_UP_STEPS` of ``a dt^2`` in position and ``a dt`` in velocity) with a resting
target, or with a moving one whose latest command passed the check, the joint follows its
commands again. No simulator.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from ruckig import InputParameter, OutputParameter, Result, Ruckig

FloatArray = npt.NDArray[np.float64]

CATCH_UP_STEPS = 1.0
"""A limited joint whose reference is within this many ``a dt^2`` of the desired target (and
within ``a dt`` of its velocity) has caught up and follows its commands again."""

_LONG_AGO = 1 << 30
"""Steps since the last command at the start: a first command is checked against a start pose
held for long (as after ``hold_s``)."""

_SLACK = 1e-9
"""Relative slack of the command check (rounding of a trajectory planned exactly at the
limits)."""


class JointLimiter:
    """Velocity and acceleration limiter of an arm's ``(n,)`` joint targets (see the module
    docstring).

    Call :meth:`command` with every new command, and :meth:`step` once per physics step with
    the desired targets; :meth:`step` returns the targets the motors get.
    """

    def __init__(
        self,
        *,
        velocity_rps: FloatArray,
        acceleration_rps2: FloatArray,
        jerk_rps3: FloatArray,
        dt_s: float,
        hold_s: float,
        start_rad: FloatArray,
    ) -> None:
        self.vmax = np.array(velocity_rps, dtype=float)
        self.amax = np.array(acceleration_rps2, dtype=float)
        if self.vmax.shape != self.amax.shape or not (
            np.all(self.vmax > 0) and np.all(self.amax > 0) and dt_s > 0 and hold_s > 0
        ):
            msg = (
                f"joint limiter: velocity limits {self.vmax.tolist()} and acceleration limits "
                f"{self.amax.tolist()} must be positive, one per joint; dt {dt_s}, hold {hold_s}"
            )
            raise ValueError(msg)
        self.dt_s = dt_s
        self.hold_s = hold_s
        self.dv = self.amax * dt_s
        self.catch_up_rad = CATCH_UP_STEPS * self.amax * dt_s * dt_s
        n = self.vmax.size
        self.position = np.array(start_rad, dtype=float)
        self.velocity = np.zeros(n)
        self.acceleration = np.zeros(n)
        self.limited = np.zeros(n, dtype=bool)
        self._otg = Ruckig(n, dt_s)
        self._input = InputParameter(n)
        self._input.max_velocity = self.vmax.tolist()
        self._input.max_acceleration = self.amax.tolist()
        self._input.max_jerk = np.array(jerk_rps3, dtype=float).tolist()
        self._input.target_velocity = [0.0] * n
        self._input.target_acceleration = [0.0] * n
        self._output = OutputParameter(n)
        self._any = False
        self._zero = np.zeros(n)
        self._last_q = self.position.copy()
        self._last_qd = np.zeros(n)
        self._continues = np.ones(n, dtype=bool)
        self._steps = _LONG_AGO
        self._last_age_steps = 0

    def reset(self, position_rad: FloatArray) -> None:
        """At rest at ``position_rad``, as if commanded there long ago."""
        self.position = np.array(position_rad, dtype=float)
        self.velocity = np.zeros_like(self.position)
        self.acceleration = np.zeros_like(self.position)
        self.limited[:] = False
        self._any = False
        self._last_q = self.position.copy()
        self._last_qd = np.zeros_like(self.position)
        self._continues[:] = True
        self._steps = _LONG_AGO
        self._last_age_steps = 0

    @property
    def any_limited(self) -> bool:
        """Whether some joint's motor gets the limiter's reference."""
        return self._any

    def command(
        self, positions_rad: FloatArray, velocities_rps: FloatArray | None, *, age_s: float = 0.0
    ) -> None:
        """A new command, stamped ``age_s`` before now: the joints whose command does not
        continue a trajectory within the limits become limited. Commands are compared at their
        stamps (the steps since the previous one's arrival, corrected by both ages), so a
        command that arrives a step late, or two that arrive in one step, continue the
        trajectory they sample. Ages count in whole steps (stamps are step times), so the
        interval is as exact as the steps' own."""
        qd = self._zero if velocities_rps is None else velocities_rps
        age_steps = round(age_s / self.dt_s)
        since_steps = self._steps + self._last_age_steps - age_steps
        if since_steps <= 0:  # stamped no later than the previous one: compare by arrival
            since_steps = self._steps
        since_s = min(since_steps * self.dt_s, self.hold_s)
        self._last_age_steps = age_steps
        predicted = self._last_q + self._last_qd * since_s
        slack = 1.0 + _SLACK
        jump = np.abs(positions_rad - predicted) > self.amax * since_s * since_s * slack + 1e-12
        kink = np.abs(qd - self._last_qd) > self.amax * since_s * slack + 1e-12
        self._last_q = np.array(positions_rad, dtype=float)
        self._last_qd = np.array(qd, dtype=float)
        self._steps = 0
        bad = jump | kink
        self._continues = ~bad
        if bad.any():
            self.limited |= bad
            self._any = True

    def step(
        self, target_rad: FloatArray, target_velocity_rps: FloatArray | None
    ) -> tuple[FloatArray, FloatArray]:
        """One physics step towards the desired target ``target_rad`` (moving at
        ``target_velocity_rps``; None: resting): the position and velocity targets the motors
        get."""
        self._steps += 1
        v_d = self._zero if target_velocity_rps is None else target_velocity_rps
        if not self._any:
            self.position, self.velocity = target_rad, v_d
            return target_rad, v_d
        v_before = self.velocity
        if v_d[self.limited].any():
            p, v = self._follow(target_rad, v_d)
        else:
            p, v = self._plan(target_rad)
        lim = self.limited
        caught = (
            (np.abs(target_rad - p) <= self.catch_up_rad)
            & (np.abs(v - v_d) <= self.dv)
            & (np.abs(v_before - v_d) <= self.dv)  # handing over keeps within the limit
        )
        lim &= ~(caught & (self._continues | (v_d == 0.0)))
        self._any = bool(lim.any())
        self.position = np.where(lim, p, target_rad)
        self.velocity = np.where(lim, v, v_d)
        self.acceleration = np.where(lim, self.acceleration, 0.0)
        return self.position, self.velocity

    def _plan(self, target_rad: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The limited joints' reference one step along Ruckig's trajectory to the resting
        target, synchronised to arrive together."""
        inp, out = self._input, self._output
        inp.current_position = self.position.tolist()
        inp.current_velocity = self.velocity.tolist()
        inp.current_acceleration = self.acceleration.tolist()
        inp.target_position = target_rad.tolist()
        inp.enabled = self.limited.tolist()
        if self._otg.update(inp, out) in (Result.Working, Result.Finished):
            self.acceleration = np.array(out.new_acceleration)
            return np.array(out.new_position), np.array(out.new_velocity)
        return self._follow(target_rad, self._zero)

    def _follow(self, target_rad: FloatArray, v_d: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The reference one step on, heading for the target as fast as the limits allow,
        each joint on its own (the fallback)."""
        dt, p, v = self.dt_s, self.position, self.velocity
        ahead = target_rad - v_d * dt - p  # relative error once the target has moved on
        # closing speed relative to the target from which the reference can still stop on it
        brake = np.sqrt(self.dv * self.dv + 2.0 * self.amax * np.abs(ahead)) - self.dv
        relative = np.clip(ahead / dt, -brake, brake)  # land on it when that is within reach
        v_new = np.clip(v_d + relative, v - self.dv, v + self.dv)
        v_new = np.clip(v_new, -self.vmax, self.vmax)
        self.acceleration = (v_new - v) / dt
        return p + v_new * dt, v_new
