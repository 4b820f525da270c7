"""A robot arm in PyBullet: load it from its URDF at a station's base pose, command its joints.

The robot is data (:class:`interfaces.robots.RobotSpec`): URDF, arm joints, home pose, motor
gains, acceleration limits (position and velocity limits come from the URDF, which for a station
carries the datasheet's, :func:`interfaces.urdf.station_urdf`). The joint motors get the
commanded targets through a :class:`twin.joint_limiter.JointLimiter`, so the arm never moves
faster or accelerates harder than its limits, whatever it is commanded. Only the arm lives
here; the tool the robot carries (fingers, TCP) is a :mod:`twin.tools` object built on the same
body. Loading checks every named joint and raises
:class:`twin.errors.SceneError` naming the URDF and the missing name before anything runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as pb

from interfaces.errors import ConfigError
from interfaces.robots import RobotSpec, resolve_urdf
from twin.errors import SceneError
from twin.joint_limiter import JointLimiter
from twin.scene import Pose

HOLD_S = 0.05
"""How long a commanded velocity moves the position target on after the command."""

_DEFAULT_VELOCITY_RPS = 2.0
_DEFAULT_EFFORT_NM = 100.0


def load_flags(spec: RobotSpec, *, visual_shapes: bool = True) -> int:
    """PyBullet's ``loadURDF`` flags for ``spec``'s robot: its inertias from the file when the
    spec says so; graphics shapes cached and shared by every later load of the same meshes in
    the client (a line of eight arms parses each arm's visual meshes once, not eight times:
    half of a repeated load's time); with ``visual_shapes=False`` no visual shapes at all
    (a load then takes about 6 ms instead of 0.3 s for a UR10). Neither changes the physics:
    Bullet simulates the collision shapes and the inertias only."""
    flags = int(pb.URDF_ENABLE_CACHED_GRAPHICS_SHAPES)
    if spec.inertia_from_file:
        flags |= pb.URDF_USE_INERTIA_FROM_FILE
    if not visual_shapes:
        flags |= pb.URDF_IGNORE_VISUAL_SHAPES
    return flags


@dataclass(frozen=True)
class JointLimits:
    """Per arm joint: position limits (rad or m), velocity limit and effort limit."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


class Robot:
    """One robot arm in one PyBullet client (``client`` is passed to every call).

    ``joints`` and ``links`` map the URDF's joint and link names to PyBullet indices; a tool on
    the same body looks its own up with :meth:`joint_index` and :meth:`link_index`. ``dt_s`` is
    the physics step: :meth:`drive` is called once per step.
    """

    def __init__(
        self,
        client: int,
        spec: RobotSpec,
        *,
        base_position_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
        base_yaw_rad: float = 0.0,
        urdf: Path | None = None,
        dt_s: float = 1.0 / 240.0,
        visual_shapes: bool = True,
    ) -> None:
        """Load the robot's URDF (``urdf``, else the spec's) at ``base_position_m`` turned by
        ``base_yaw_rad``, at its home pose. ``visual_shapes=False`` leaves the URDF's visual
        meshes out (:func:`load_flags`): nothing but a camera or PyBullet's window looks at
        them, and parsing them is nearly all of a load. Raises :class:`SceneError` naming the
        URDF when PyBullet cannot load it or a named joint is missing."""
        self.client = client
        self.spec = spec
        try:
            self.urdf = urdf if urdf is not None else resolve_urdf(spec.urdf)
        except ConfigError as exc:
            raise SceneError(str(exc)) from None
        quat = pb.getQuaternionFromEuler([0.0, 0.0, base_yaw_rad])
        try:
            self.body = pb.loadURDF(
                str(self.urdf),
                basePosition=base_position_m,
                baseOrientation=quat,
                useFixedBase=True,
                flags=load_flags(spec, visual_shapes=visual_shapes),
                physicsClientId=client,
            )
        except pb.error as exc:
            msg = f"{self.urdf}: PyBullet cannot load this URDF: {exc}"
            raise SceneError(msg) from None
        self.infos = [
            pb.getJointInfo(self.body, j, physicsClientId=client)
            for j in range(pb.getNumJoints(self.body, physicsClientId=client))
        ]
        self.joints = {info[1].decode(): info[0] for info in self.infos}
        self.links = {info[12].decode(): info[0] for info in self.infos}
        self.arm_joints = [self.joint_index(name, "arm joint") for name in spec.arm_joints]
        self.limits = self._limits()
        self._q_target = np.array(spec.home_joint_positions, dtype=float)
        self._q_command = self._q_target.copy()
        self._qd_target = np.zeros(len(self.arm_joints))
        self._since_command_s = 0.0
        self._changed = True
        self.limiter = JointLimiter(
            velocity_rps=self.limits.velocity,
            acceleration_rps2=np.array(spec.joint_max_acceleration_rps2, dtype=float),
            jerk_rps3=np.array(spec.joint_max_jerk_rps3, dtype=float),
            dt_s=dt_s,
            hold_s=HOLD_S,
            start_rad=self._q_target,
        )
        n = len(self.arm_joints)
        self._gains = ([spec.position_gain] * n, [spec.velocity_gain] * n)

    def _limits(self) -> JointLimits:
        lower, upper, velocity, effort = [], [], [], []
        for j in self.arm_joints:
            info = self.infos[j]
            lo, hi = float(info[8]), float(info[9])
            if hi <= lo:
                lo, hi = -math.pi, math.pi
            lower.append(lo)
            upper.append(hi)
            velocity.append(float(info[11]) if info[11] > 0 else _DEFAULT_VELOCITY_RPS)
            effort.append(float(info[10]) if info[10] > 0 else _DEFAULT_EFFORT_NM)
        return JointLimits(np.array(lower), np.array(upper), np.array(velocity), np.array(effort))

    def joint_index(self, name: str, what: str) -> int:
        """PyBullet index of the joint ``name`` (:class:`SceneError` naming the URDF if none)."""
        return self._lookup(self.joints, name, what)

    def link_index(self, name: str, what: str) -> int:
        """PyBullet index of the link ``name`` (:class:`SceneError` naming the URDF if none)."""
        return self._lookup(self.links, name, what)

    def _lookup(self, table: dict[str, int], name: str, what: str) -> int:
        if name not in table:
            known = ", ".join(sorted(table))
            msg = f"{self.urdf}: no {what} named {name!r} (the URDF has: {known})"
            raise SceneError(msg)
        return table[name]

    def link_name(self, link: int) -> str:
        """The URDF name of link ``link`` (``base`` for -1)."""
        return "base" if link < 0 else str(self.infos[link][12].decode())

    def reset_state(self) -> None:
        """Put the arm at its home pose, at rest, with no velocity to follow (the motors are
        set by the next :meth:`apply_commands`)."""
        for j, q in zip(self.arm_joints, self.spec.home_joint_positions, strict=True):
            pb.resetJointState(self.body, j, q, 0.0, physicsClientId=self.client)
        self._q_target = np.array(self.spec.home_joint_positions, dtype=float)
        self._q_command = self._q_target.copy()
        self._qd_target = np.zeros(len(self.arm_joints))
        self._since_command_s = 0.0
        self.limiter.reset(self._q_target)
        self._changed = True

    def command(self, q: np.ndarray, qd: np.ndarray | None = None, *, age_s: float = 0.0) -> None:
        """Set arm joint position targets (and feed-forward velocities); clipped to the limits.

        With velocities, the position target moves on with them between commands (as a
        trajectory controller interpolates a point with velocity), for up to ``HOLD_S`` after
        the command's stamp, ``age_s`` (>= 0) before now: a command that arrives late starts
        where it meant the arm to be by now. The motors follow from the next :meth:`drive`,
        through the joint limiter.
        """
        self._q_command = np.clip(np.asarray(q, dtype=float), self.limits.lower, self.limits.upper)
        self._qd_target = (
            np.zeros(len(self.arm_joints))
            if qd is None
            else np.clip(np.asarray(qd, dtype=float), -self.limits.velocity, self.limits.velocity)
        )
        age_s = max(age_s, 0.0)
        self._since_command_s = min(age_s, HOLD_S)
        self._q_target = self._q_command.copy()
        if self._since_command_s > 0.0 and self._qd_target.any():
            q_now = self._q_command + self._qd_target * self._since_command_s
            self._q_target = np.clip(q_now, self.limits.lower, self.limits.upper)
        self.limiter.command(self._q_command, self._qd_target, age_s=age_s)
        self._changed = True

    @property
    def position_target_rad(self) -> np.ndarray:
        """The arm's joint position targets now ``(n,)``: the last command, moved on along its
        velocities (what the limiter is handed next)."""
        return self._q_target.copy()

    def extrapolate(self, dt_s: float) -> None:
        """Advance the position target along the commanded velocity by one step."""
        if not self._qd_target.any() or self._since_command_s >= HOLD_S:
            return
        self._since_command_s += dt_s
        q = self._q_command + self._qd_target * min(self._since_command_s, HOLD_S)
        self._q_target = np.clip(q, self.limits.lower, self.limits.upper)
        self._changed = True

    def drive(self) -> None:
        """Once per physics step, after this step's command or extrapolation: hand the targets
        to the motors through the joint limiter (nothing to do while they rest unchanged).

        A joint the limiter passes gets its targets exactly as commanded (position, and the
        commanded velocity as the feed-forward); a limited one the limiter's reference.
        """
        limiter = self.limiter
        was_limited = limiter.any_limited
        if not self._changed and not was_limited:
            limiter.step(self._q_target, None)
            return
        self._changed = False
        moving = self._since_command_s < HOLD_S and self._qd_target.any()
        q, qd = limiter.step(self._q_target, self._qd_target if moving else None)
        if was_limited or limiter.any_limited:
            self._set_motors(q, np.where(limiter.limited, qd, self._qd_target))
        else:
            self._set_motors(self._q_target, self._qd_target)

    def apply_commands(self) -> None:
        """Hand the current arm targets to PyBullet's joint motors as they are (the start pose
        of an episode; :meth:`drive` limits every later command)."""
        self._set_motors(self._q_target, self._qd_target)

    def _set_motors(self, q: np.ndarray, qd: np.ndarray) -> None:
        pb.setJointMotorControlArray(
            self.body,
            self.arm_joints,
            pb.POSITION_CONTROL,
            targetPositions=q.tolist(),
            targetVelocities=qd.tolist(),
            forces=self.limits.effort.tolist(),
            positionGains=self._gains[0],
            velocityGains=self._gains[1],
            physicsClientId=self.client,
        )

    @property
    def root_link(self) -> str:
        """The URDF name of the body's root link (PyBullet's base)."""
        return str(pb.getBodyInfo(self.body, physicsClientId=self.client)[0].decode())

    def root_pose(self) -> Pose:
        """The world pose of the root link's URDF frame (PyBullet reports the base's inertial
        frame; this takes its offset off)."""
        c = self.client
        com_pos, com_orn = pb.getBasePositionAndOrientation(self.body, physicsClientId=c)
        info = pb.getDynamicsInfo(self.body, -1, physicsClientId=c)
        inv_pos, inv_orn = pb.invertTransform(info[3], info[4])
        pos, orn = pb.multiplyTransforms(com_pos, com_orn, inv_pos, inv_orn)
        return (pos[0], pos[1], pos[2]), (orn[0], orn[1], orn[2], orn[3])

    def link_poses(self) -> dict[str, Pose]:
        """The world pose of every non-root link's URDF frame, by link name, in PyBullet's
        link order (forward kinematics of the current joint positions)."""
        indices = list(range(len(self.infos)))
        if not indices:
            return {}
        states = pb.getLinkStates(
            self.body, indices, computeForwardKinematics=1, physicsClientId=self.client
        )
        return {
            self.link_name(i): (
                (state[4][0], state[4][1], state[4][2]),
                (state[5][0], state[5][1], state[5][2], state[5][3]),
            )
            for i, state in zip(indices, states, strict=True)
        }

    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Arm joint positions and velocities, ``(n,)`` each."""
        states = pb.getJointStates(self.body, self.arm_joints, physicsClientId=self.client)
        return (np.array([s[0] for s in states]), np.array([s[1] for s in states]))
