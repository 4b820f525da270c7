"""Online Cartesian trajectories of the TCP with Ruckig, feedback, and the joint-space command.

The planned degrees of freedom are ``(x, y, z, yaw)`` of a downward-pointing tool. Each control
period :meth:`CartesianPlanner.step` advances one Ruckig cycle towards a target position **and**
velocity (the object's, feed-forward) within the velocity, acceleration and jerk limits of
``MotionConfig``. :class:`JointPlanner` plans the joint-space transfer moves (carry to a bin,
return to ready). The feedback term and the joint commander are :mod:`control.commander`'s
(re-exported here).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from ruckig import InputParameter, Result, Ruckig, RuckigError, Synchronization, Trajectory

from control.commander import FeedbackTerm, JointCommander
from control.config_sections import MotionConfig
from control.errors import PlanningError
from control.ik import Kinematics

Vec4 = tuple[float, float, float, float]
FloatArray = NDArray[np.float64]

_ZERO4: Vec4 = (0.0, 0.0, 0.0, 0.0)
_SOLVED = (Result.Working, Result.Finished)


def calculate_synchronised(
    otg: Ruckig, inp: InputParameter, trajectory: Trajectory, fallback: Synchronization
) -> tuple[Result, bool]:
    """Ruckig with time synchronisation, retried once with ``fallback`` if that fails.

    Ruckig's synchronisation step fails numerically for rare states, and fails the same way on
    every retry from the same state, while the same input solves without it. Returns the result
    and whether the fallback was used; a ``RuckigError`` of the fallback propagates.
    ``inp.synchronization`` is left at ``Time``.
    """
    inp.synchronization = Synchronization.Time
    try:
        result = otg.calculate(inp, trajectory)
    except RuckigError:
        result = Result.Error
    if result in _SOLVED:
        return result, False
    inp.synchronization = fallback
    try:
        return otg.calculate(inp, trajectory), True
    finally:
        inp.synchronization = Synchronization.Time


def _vec4(values: object) -> Vec4:
    x, y, z, w = (float(v) for v in values)  # type: ignore[attr-defined]
    return (x, y, z, w)


@dataclass(frozen=True, kw_only=True)
class CartesianState:
    """Kinematic state of the TCP: ``(x, y, z, yaw)`` position, velocity and acceleration.

    Units: m, m/s, m/s^2 for x, y, z; rad, rad/s, rad/s^2 for yaw.
    """

    position: Vec4
    velocity: Vec4 = _ZERO4
    acceleration: Vec4 = _ZERO4

    @property
    def position_m(self) -> tuple[float, float, float]:
        """The ``(x, y, z)`` part of :attr:`position`."""
        return (self.position[0], self.position[1], self.position[2])


@dataclass(frozen=True, kw_only=True)
class CartesianTarget:
    """Where (``(x, y, z, yaw)``) and how fast (``(vx, vy, vz, yaw rate)``) to arrive."""

    position: Vec4
    velocity: Vec4 = _ZERO4


@dataclass(frozen=True, kw_only=True)
class PlannerStep:
    """One control period of the planner.

    ``state`` is the new setpoint, ``remaining_s`` the time left of the current trajectory,
    ``position_remaining_s`` the time left until x, y and z reach their target (the degrees of
    freedom are not synchronised, so yaw may take longer), ``yaw_remaining_s`` the same for
    the yaw, and ``finished`` is True when the target state has been reached.
    """

    state: CartesianState
    remaining_s: float
    position_remaining_s: float
    finished: bool
    yaw_remaining_s: float


class _AxisGroup:
    """One Ruckig instance over a group of axes, planned in a frame moving with the target."""

    def __init__(self, dofs: int, period_s: float) -> None:
        self.otg = Ruckig(dofs, period_s)
        self.input = InputParameter(dofs)
        self.trajectory = Trajectory(dofs)
        self.dofs = dofs
        self.fallbacks = 0

    def solve(
        self,
        relative_position: list[float],
        relative_velocity: list[float],
        acceleration: list[float],
        limits: tuple[list[float], list[float], list[float], list[float]],
        period_s: float,
        min_duration_s: float | None = None,
    ) -> tuple[list[float], list[float], list[float], float]:
        """New relative (position, velocity, acceleration) after ``period_s`` and time left;
        the goal is reached no sooner than ``min_duration_s`` from now (when given)."""
        inp = self.input
        inp.minimum_duration = min_duration_s
        inp.current_position = relative_position
        inp.current_velocity = relative_velocity
        inp.current_acceleration = acceleration
        inp.target_position = [0.0] * self.dofs
        inp.target_velocity = [0.0] * self.dofs
        inp.target_acceleration = [0.0] * self.dofs
        inp.min_velocity, inp.max_velocity, inp.max_acceleration, inp.max_jerk = limits
        try:
            result, fell_back = calculate_synchronised(
                self.otg, inp, self.trajectory, Synchronization.No
            )
        except RuckigError as exc:
            self.fallbacks += 1
            msg = f"Ruckig rejected the input: {str(exc).strip()}"
            raise PlanningError(msg) from exc
        self.fallbacks += fell_back
        if result not in _SOLVED:
            msg = f"Ruckig returned {result}"
            raise PlanningError(msg)
        duration_s = float(self.trajectory.duration)
        dt_s = min(period_s, duration_s)
        position, velocity, accel = self.trajectory.at_time(dt_s)
        return list(position), list(velocity), list(accel), max(duration_s - dt_s, 0.0)


class CartesianPlanner:
    """Ruckig (free edition: no intermediate waypoints) over ``(x, y, z, yaw)``.

    x, y and z form one time-synchronised group (a straight-ish path); yaw is planned by its own
    Ruckig instance, so a slow turn does not delay the position intercept. When Ruckig's
    synchronisation fails numerically the step is retried with the axes planned alone.
    """

    def __init__(self, motion: MotionConfig, initial: CartesianState) -> None:
        """Create the generators at ``initial`` with the limits of ``motion``."""
        self._motion = motion
        self._xyz = _AxisGroup(3, motion.control_period_s)
        self._yaw = _AxisGroup(1, motion.control_period_s)
        self._state = initial
        self.reset(initial)

    @property
    def sync_fallbacks(self) -> int:
        """Steps where time synchronisation failed and each axis was planned alone."""
        return self._xyz.fallbacks

    @property
    def state(self) -> CartesianState:
        """The current setpoint."""
        return self._state

    def reset(self, state: CartesianState) -> None:
        """Restart from ``state`` (e.g. the measured TCP after an abort)."""
        values = (*state.position, *state.velocity, *state.acceleration)
        if not all(math.isfinite(v) for v in values):
            msg = f"planner reset to a non-finite state {state}"
            raise PlanningError(msg)
        self._state = state

    def _relative(
        self, target: CartesianTarget, speed_scale: float, acceleration_scale: float = 1.0
    ) -> tuple[list[float], list[float], tuple[list[float], list[float], list[float], list[float]]]:
        """The state relative to the moving target, and the limits in its frame (see
        :meth:`step`)."""
        values = (*target.position, *target.velocity)
        if not all(math.isfinite(v) for v in values):
            msg = f"non-finite Ruckig target {target}"
            raise PlanningError(msg)
        if not 0.0 < speed_scale <= 1.0:
            msg = f"speed_scale {speed_scale} is not in (0, 1]"
            raise PlanningError(msg)
        if not 0.0 < acceleration_scale <= 1.0:
            msg = f"acceleration_scale {acceleration_scale} is not in (0, 1]"
            raise PlanningError(msg)
        motion = self._motion
        vmax = [v * speed_scale for v in motion.max_velocity]
        if any(abs(v) >= limit for v, limit in zip(target.velocity, vmax, strict=True)):
            msg = f"target velocity {target.velocity} is not below the velocity limits {vmax}"
            raise PlanningError(msg)
        state = self._state
        period_s = motion.control_period_s
        relative = [
            c - (g - v * period_s)
            for c, g, v in zip(state.position, target.position, target.velocity, strict=True)
        ]
        relative_velocity = [c - v for c, v in zip(state.velocity, target.velocity, strict=True)]
        v_hi = [limit - v for v, limit in zip(target.velocity, vmax, strict=True)]
        v_lo = [-limit - v for v, limit in zip(target.velocity, vmax, strict=True)]
        amax = [a * speed_scale * acceleration_scale for a in motion.max_acceleration]
        return relative, relative_velocity, (v_lo, v_hi, amax, list(motion.max_jerk))

    def step(
        self,
        target: CartesianTarget,
        *,
        speed_scale: float = 1.0,
        acceleration_scale: float = 1.0,
        min_duration_s: float | None = None,
    ) -> PlannerStep:
        """Advance one control period towards a target moving at constant velocity.

        ``target.position`` is where the target is when the new setpoint takes effect and
        ``target.velocity`` how it moves (the object's velocity, or zero for a fixed point).
        Ruckig plans in the frame moving with the target (relative goal: zero offset, zero
        relative velocity, velocity limits shifted by the target velocity), so the world
        trajectory intercepts the moving target exactly and then moves with it (feed-forward of
        the target velocity). ``speed_scale`` in (0, 1] scales the velocity and acceleration
        limits; ``acceleration_scale`` in (0, 1] scales the acceleration limits once more (what
        the joints can follow in the current posture). With ``min_duration_s`` x, y and z meet
        the target no sooner than that (s) from now (Ruckig's minimum duration; a longer
        time-optimal trajectory is not shortened).
        Raises ``PlanningError`` for non-finite targets, a target velocity at or above
        the limits or any other Ruckig error; the state is then unchanged.
        """
        relative, relative_velocity, (v_lo, v_hi, amax, jmax) = self._relative(
            target, speed_scale, acceleration_scale
        )
        state = self._state
        period_s = self._motion.control_period_s
        try:
            p3, v3, a3, left_xyz = self._xyz.solve(
                relative[:3],
                relative_velocity[:3],
                list(state.acceleration[:3]),
                (v_lo[:3], v_hi[:3], amax[:3], jmax[:3]),
                period_s,
                min_duration_s,
            )
            p1, v1, a1, left_yaw = self._yaw.solve(
                relative[3:],
                relative_velocity[3:],
                list(state.acceleration[3:]),
                (v_lo[3:], v_hi[3:], amax[3:], jmax[3:]),
                period_s,
            )
        except PlanningError as exc:
            msg = f"Ruckig failed for target {target}: {exc}"
            raise PlanningError(msg) from exc
        self._state = CartesianState(
            position=_vec4(r + g for r, g in zip(p3 + p1, target.position, strict=True)),
            velocity=_vec4(r + v for r, v in zip(v3 + v1, target.velocity, strict=True)),
            acceleration=_vec4(a3 + a1),
        )
        return PlannerStep(
            state=self._state,
            remaining_s=max(left_xyz, left_yaw),
            position_remaining_s=left_xyz,
            finished=max(left_xyz, left_yaw) == 0.0,
            yaw_remaining_s=left_yaw,
        )


@dataclass(frozen=True, kw_only=True, eq=False)
class JointStep:
    """One control period of a joint-space move: ``q`` and ``dq`` are ``(n_arm,) float``."""

    q: FloatArray
    dq: FloatArray
    remaining_s: float


SNAP_RAD = 2e-3
"""A joint move this close to its target (every joint) that Ruckig cannot finish ends there."""


class JointPlanner:
    """Ruckig in joint space for transfer moves (carry to a bin, return to ready).

    Joint velocity limits are the URDF's scaled by ``transfer_speed_scale``, acceleration and jerk
    limits the robot's datasheet values (:class:`~control.ik.Kinematics`); positions are kept
    inside the joint limits by Ruckig and by a final check.
    """

    def __init__(self, kinematics: Kinematics, motion: MotionConfig) -> None:
        """Create the generator with the joint limits of ``kinematics``."""
        self._kin = kinematics
        n = kinematics.nq
        self._period_s = motion.control_period_s
        self._otg = Ruckig(n, motion.control_period_s)
        self._input = InputParameter(n)
        self._trajectory = Trajectory(n)
        self._move = Trajectory(n)
        self._move_elapsed_s = 0.0
        self._input.max_velocity = list(kinematics.velocity_limit_rps * motion.transfer_speed_scale)
        self._input.max_acceleration = [float(v) for v in kinematics.acceleration_limit_rps2]
        self._input.max_jerk = [float(v) for v in kinematics.jerk_limit_rps3]
        self._q = np.zeros(n)
        self._dq = np.zeros(n)
        self._ddq = np.zeros(n)
        self._rest: JointStep | None = None  # a step that left the state unchanged
        self._rest_key = b""  # the state and target it was computed from
        self.sync_fallbacks = 0
        """Plans where time synchronisation failed and the fallback solved the move."""

    def reset(self, q: FloatArray, dq: FloatArray | None = None) -> None:
        """Continue from ``q`` (and ``dq``, clipped to the joint velocity limits), zero
        acceleration. A ``dq`` above the transfer speed (``transfer_speed_scale``) is kept: the
        move brakes down to it within the acceleration limits rather than jump to it."""
        vmax = np.asarray(self._kin.velocity_limit_rps)
        self._q = np.clip(np.asarray(q, dtype=np.float64), self._kin.lower_rad, self._kin.upper_rad)
        velocity = np.zeros_like(self._q) if dq is None else np.asarray(dq, dtype=np.float64)
        self._dq = np.clip(np.nan_to_num(velocity), -vmax, vmax)
        self._ddq = np.zeros_like(self._q)

    def _calculate(
        self,
        q_target: FloatArray,
        dq_target: FloatArray | None,
        min_duration_s: float,
        trajectory: Trajectory,
    ) -> Result:
        """Ruckig from the current state to ``q_target`` (at ``dq_target``) into ``trajectory``.

        Raises ``PlanningError`` for a target outside the position or velocity limits.
        """
        if not self._kin.within_limits(q_target):
            msg = f"joint target {q_target} is outside the joint limits"
            raise PlanningError(msg)
        inp = self._input
        velocity = np.zeros_like(q_target) if dq_target is None else np.asarray(dq_target)
        if not np.all(np.isfinite(velocity)) or np.any(
            np.abs(velocity) > np.asarray(inp.max_velocity)
        ):
            msg = f"joint target velocity {velocity} is outside the velocity limits"
            raise PlanningError(msg)
        inp.current_position = list(self._q)
        inp.current_velocity = list(self._dq)
        inp.current_acceleration = list(self._ddq)
        inp.target_position = list(q_target)
        inp.target_velocity = list(velocity)
        inp.minimum_duration = min_duration_s if min_duration_s > 0.0 else None
        # to rest, every joint may arrive on its own; a moving target keeps them together
        fallback = Synchronization.No if not velocity.any() else Synchronization.TimeIfNecessary
        result, fell_back = calculate_synchronised(self._otg, inp, trajectory, fallback)
        self.sync_fallbacks += fell_back
        return result

    def _checked(
        self,
        q_target: FloatArray,
        dq_target: FloatArray | None,
        min_duration_s: float,
        trajectory: Trajectory,
    ) -> None:
        try:
            result = self._calculate(q_target, dq_target, min_duration_s, trajectory)
        except RuckigError as exc:
            msg = f"Ruckig rejected joint target {q_target}: {str(exc).strip()}"
            raise PlanningError(msg) from exc
        if result not in (Result.Working, Result.Finished):
            msg = f"Ruckig returned {result} for joint target {q_target}"
            raise PlanningError(msg)

    def duration_s(self, q_target: FloatArray, dq_target: FloatArray | None = None) -> float:
        """Time-optimal duration (s) of a move from the current state, without moving.

        Raises ``PlanningError`` when the target is outside the limits or Ruckig fails.
        """
        self._checked(np.asarray(q_target, dtype=np.float64), dq_target, 0.0, self._trajectory)
        return float(self._trajectory.duration)

    def start_move(
        self, q_target: FloatArray, dq_target: FloatArray, *, min_duration_s: float = 0.0
    ) -> float:
        """Plan one whole move from the current state to ``q_target`` at ``dq_target``.

        The move takes at least ``min_duration_s``; :meth:`follow` then steps along it (a move
        that ends in motion is planned once and followed, not re-planned every period, so it
        arrives at the planned time in the planned state). Returns its duration (s). Raises
        ``PlanningError`` when the target is outside the limits or Ruckig fails.
        """
        q_target = np.asarray(q_target, dtype=np.float64)
        self._checked(q_target, dq_target, min_duration_s, self._move)
        self._move_elapsed_s = 0.0
        return float(self._move.duration)

    def follow(self) -> JointStep:
        """Advance one control period along the move of :meth:`start_move`."""
        duration_s = float(self._move.duration)
        self._move_elapsed_s = min(self._move_elapsed_s + self._period_s, duration_s)
        return self._sample(self._move, self._move_elapsed_s)

    def _sample(self, trajectory: Trajectory, t_s: float) -> JointStep:
        """Make ``trajectory``'s state at ``t_s`` (clipped to the joint limits) the current one."""
        q, dq, ddq = trajectory.at_time(t_s)
        self._q = np.clip(np.asarray(q), self._kin.lower_rad, self._kin.upper_rad)
        self._dq = np.asarray(dq)
        self._ddq = np.asarray(ddq)
        remaining_s = max(float(trajectory.duration) - t_s, 0.0)
        return JointStep(q=self._q.copy(), dq=self._dq.copy(), remaining_s=remaining_s)

    def step(self, q_target: FloatArray) -> JointStep:
        """Advance one control period towards ``q_target`` ``(n_arm,)`` (at rest).

        A step that leaves the state as it found it (at rest on the target, or a hair from it
        where Ruckig's move is a fixed point: a waiting arm) is returned again, the same
        :class:`JointStep` object, while the state and target are unchanged: the same call
        would compute the same step, and a caller may skip what it did with it last time.
        Raises ``PlanningError`` when the target is outside the limits or Ruckig fails.
        """
        q_target = np.asarray(q_target, dtype=np.float64)
        key = self._state_key(q_target)
        if self._rest is not None and key == self._rest_key:
            return self._rest
        step = self._step(q_target)
        if key == self._state_key(q_target):
            step.q.flags.writeable = step.dq.flags.writeable = False  # handed out again
            self._rest, self._rest_key = step, key
        return step

    def _state_key(self, q_target: FloatArray) -> bytes:
        return b"".join(a.tobytes() for a in (self._q, self._dq, self._ddq, q_target))

    def _step(self, q_target: FloatArray) -> JointStep:
        if not self._dq.any() and not self._ddq.any() and np.array_equal(self._q, q_target):
            # at rest on the target: Ruckig would plan a zero-length move
            return JointStep(q=self._q.copy(), dq=self._dq.copy(), remaining_s=0.0)
        try:
            self._checked(q_target, None, 0.0, self._trajectory)
        except PlanningError as exc:
            # Ruckig's time synchronisation can fail numerically a hair from the target while
            # still moving; there the move is over: hold the target at rest.
            near = float(np.max(np.abs(q_target - self._q))) < SNAP_RAD
            if not (near and isinstance(exc.__cause__, RuckigError)):
                raise
            self._q, self._dq, self._ddq = (q_target.copy(), np.zeros_like(q_target), 0 * q_target)
            return JointStep(q=self._q.copy(), dq=self._dq.copy(), remaining_s=0.0)
        return self._sample(self._trajectory, min(self._period_s, float(self._trajectory.duration)))


__all__ = [
    "CartesianPlanner",
    "CartesianState",
    "CartesianTarget",
    "FeedbackTerm",
    "JointCommander",
    "JointPlanner",
    "JointStep",
    "PlannerStep",
    "calculate_synchronised",
]
