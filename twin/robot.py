"""A robot arm in PyBullet: load from URDF, command joints and gripper, read its state.

The robot is configuration (:class:`twin.config.RobotConfig`): URDF, base pose, TCP link, arm and
finger joints. Loading checks every named link and joint and raises
:class:`twin.errors.SceneError` naming the URDF and the missing name before anything runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as pb

from twin.config import RobotConfig
from twin.errors import SceneError

HOLD_S = 0.05


@dataclass(frozen=True)
class JointLimits:
    """Per arm joint: position limits (rad or m), velocity limit and effort limit."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


class Robot:
    """One robot in one PyBullet client (``client`` is passed to every call)."""

    def __init__(self, client: int, config: RobotConfig) -> None:
        self.client = client
        self.config = config
        urdf = config.resolve_urdf()
        quat = pb.getQuaternionFromEuler([0.0, 0.0, config.base_yaw_rad])
        try:
            self.body = pb.loadURDF(
                str(urdf),
                basePosition=config.base_position_m,
                baseOrientation=quat,
                useFixedBase=True,
                flags=pb.URDF_USE_INERTIA_FROM_FILE if config.inertia_from_file else 0,
                physicsClientId=client,
            )
        except pb.error as exc:
            msg = f"{urdf}: PyBullet cannot load this URDF: {exc}"
            raise SceneError(msg) from None
        joints: dict[str, int] = {}
        links: dict[str, int] = {}
        lower, upper, velocity, effort = [], [], [], []
        infos = [
            pb.getJointInfo(self.body, j, physicsClientId=client)
            for j in range(pb.getNumJoints(self.body, physicsClientId=client))
        ]
        for info in infos:
            joints[info[1].decode()] = info[0]
            links[info[12].decode()] = info[0]
        self.arm_joints = [
            self._lookup(joints, name, "arm joint", urdf) for name in config.arm_joints
        ]
        self.finger_joints = [
            self._lookup(joints, name, "finger joint", urdf) for name in config.finger_joints
        ]
        self.finger_links = [
            self._lookup(links, name, "finger link", urdf) for name in config.finger_links
        ]
        self.tcp_link = self._lookup(links, config.tcp_link, "TCP link", urdf)
        for j in self.arm_joints:
            info = infos[j]
            lo, hi = float(info[8]), float(info[9])
            if hi <= lo:
                lo, hi = -math.pi, math.pi
            lower.append(lo)
            upper.append(hi)
            velocity.append(float(info[11]) if info[11] > 0 else 2.0)
            effort.append(float(info[10]) if info[10] > 0 else 100.0)
        self.limits = JointLimits(
            np.array(lower), np.array(upper), np.array(velocity), np.array(effort)
        )
        self._finger_effort = [max(float(infos[j][10]), 20.0) for j in self.finger_joints]
        self.robot_links = frozenset(links.values()) | {-1}
        self._q_target = np.array(config.home_joint_positions, dtype=float)
        self._q_command = self._q_target.copy()
        self._qd_target = np.zeros(len(self.arm_joints))
        self._since_command_s = 0.0
        self._gripper_width_m = config.max_opening_m
        self._applied_gripper_width_m = math.nan
        self.reset()

    @staticmethod
    def _lookup(table: dict[str, int], name: str, what: str, urdf: object) -> int:
        if name not in table:
            known = ", ".join(sorted(table))
            msg = f"{urdf}: no {what} named {name!r} (the URDF has: {known})"
            raise SceneError(msg)
        return table[name]

    def reset(self) -> None:
        """Put the arm at its home pose with the gripper open, at rest."""
        for j, q in zip(self.arm_joints, self.config.home_joint_positions, strict=True):
            pb.resetJointState(self.body, j, q, 0.0, physicsClientId=self.client)
        for j, q in zip(self.finger_joints, self.config.finger_open, strict=True):
            pb.resetJointState(self.body, j, q, 0.0, physicsClientId=self.client)
        self._q_target = np.array(self.config.home_joint_positions, dtype=float)
        self._q_command = self._q_target.copy()
        self._qd_target = np.zeros(len(self.arm_joints))
        self._since_command_s = 0.0
        self._gripper_width_m = self.config.max_opening_m
        self._applied_gripper_width_m = math.nan  # finger motors are set when the target changes
        self.apply_commands()

    def command(self, q: np.ndarray, qd: np.ndarray | None = None) -> None:
        """Set arm joint position targets (and feed-forward velocities); clipped to the limits.

        With velocities, the position target moves on with them between commands (as a
        trajectory controller interpolates a point with velocity), for up to ``HOLD_S``.
        """
        self._q_command = np.clip(np.asarray(q, dtype=float), self.limits.lower, self.limits.upper)
        self._q_target = self._q_command.copy()
        self._qd_target = (
            np.zeros(len(self.arm_joints))
            if qd is None
            else np.clip(np.asarray(qd, dtype=float), -self.limits.velocity, self.limits.velocity)
        )
        self._since_command_s = 0.0

    def extrapolate(self, dt_s: float) -> None:
        """Advance the position target along the commanded velocity by one step."""
        if not self._qd_target.any() or self._since_command_s >= HOLD_S:
            return
        self._since_command_s += dt_s
        q = self._q_command + self._qd_target * min(self._since_command_s, HOLD_S)
        self._q_target = np.clip(q, self.limits.lower, self.limits.upper)
        self.apply_commands()

    def command_gripper(self, width_m: float) -> None:
        """Set the gripper opening in metres (0 = closed, ``max_opening_m`` = open)."""
        self._gripper_width_m = float(np.clip(width_m, 0.0, self.config.max_opening_m))

    def apply_commands(self) -> None:
        """Hand the current targets to PyBullet's joint motors."""
        n = len(self.arm_joints)
        pb.setJointMotorControlArray(
            self.body,
            self.arm_joints,
            pb.POSITION_CONTROL,
            targetPositions=self._q_target.tolist(),
            targetVelocities=self._qd_target.tolist(),
            forces=self.limits.effort.tolist(),
            positionGains=[self.config.position_gain] * n,
            velocityGains=[self.config.velocity_gain] * n,
            physicsClientId=self.client,
        )
        if self.finger_joints and self._gripper_width_m != self._applied_gripper_width_m:
            self._applied_gripper_width_m = self._gripper_width_m
            frac = self._gripper_width_m / self.config.max_opening_m
            targets = [
                c + frac * (o - c)
                for o, c in zip(self.config.finger_open, self.config.finger_closed, strict=True)
            ]
            pb.setJointMotorControlArray(
                self.body,
                self.finger_joints,
                pb.POSITION_CONTROL,
                targetPositions=targets,
                forces=self._finger_effort,
                physicsClientId=self.client,
            )

    @property
    def q_target(self) -> np.ndarray:
        """The current arm joint targets."""
        return self._q_target.copy()

    @property
    def gripper_width_target_m(self) -> float:
        """The current gripper opening target."""
        return self._gripper_width_m

    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Arm joint positions and velocities, ``(n,)`` each."""
        states = pb.getJointStates(self.body, self.arm_joints, physicsClientId=self.client)
        return (np.array([s[0] for s in states]), np.array([s[1] for s in states]))

    def gripper_width_m(self) -> float:
        """Measured gripper opening, from the finger joints."""
        if not self.finger_joints:
            return 0.0
        states = pb.getJointStates(self.body, self.finger_joints, physicsClientId=self.client)
        fracs = [
            (s[0] - c) / (o - c) if o != c else 0.0
            for s, o, c in zip(
                states, self.config.finger_open, self.config.finger_closed, strict=True
            )
        ]
        return float(np.clip(np.mean(fracs), 0.0, 1.0) * self.config.max_opening_m)

    def tcp_pose(self) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """Position and xyzw orientation of the TCP link in the world frame."""
        state = pb.getLinkState(
            self.body, self.tcp_link, computeForwardKinematics=True, physicsClientId=self.client
        )
        return state[4], state[5]

    def tcp_velocity(self) -> tuple[float, float, float]:
        """Linear velocity of the TCP link in the world frame."""
        state = pb.getLinkState(
            self.body,
            self.tcp_link,
            computeLinkVelocity=True,
            computeForwardKinematics=True,
            physicsClientId=self.client,
        )
        vx, vy, vz = state[6]
        return (float(vx), float(vy), float(vz))
