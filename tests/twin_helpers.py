"""Small helpers for the twin tests (polygons in pixels of a 1000x1000 px image = 0.6 m)."""

from __future__ import annotations

import math

import pybullet as pb

from twin.sim import ArmCommand, Twin

M_PER_PX = 0.6 / 1000.0


def box_px(cx: float, cy: float, length_px: float, width_px: float) -> list[tuple[float, float]]:
    """An axis-aligned rectangle: ``length_px`` along image rows (belt x), ``width_px`` across."""
    hl, hw = 0.5 * length_px, 0.5 * width_px
    return [(cx - hw, cy - hl), (cx + hw, cy - hl), (cx + hw, cy + hl), (cx - hw, cy + hl)]


def tcp_ik(
    twin: Twin,
    position: tuple[float, float, float],
    *,
    station: int = 0,
    tilt_rad: float = 0.0,
    yaw_rad: float = 0.0,
) -> tuple[float, ...]:
    """Arm joint targets (PyBullet's IK) putting a station's TCP at ``position``, pointing down,
    tilted by ``tilt_rad`` about x and turned by ``yaw_rad``."""
    robot, tool = twin.stations[station].robot, twin.stations[station].tool
    movable = [j for j, info in enumerate(robot.infos) if info[2] != pb.JOINT_FIXED]
    q = pb.calculateInverseKinematics(
        robot.body,
        tool.tcp_link,
        position,
        pb.getQuaternionFromEuler([math.pi + tilt_rad, 0.0, yaw_rad]),
        maxNumIterations=300,
        residualThreshold=1e-7,
        physicsClientId=twin.client,
    )
    by_joint = dict(zip(movable, q, strict=True))
    return tuple(by_joint[j] for j in robot.arm_joints)


def hold(twin: Twin, command: ArmCommand, seconds: float) -> None:
    """Command ``command``, then step the twin ``seconds``."""
    end = twin.time_s + seconds
    twin.command(command)
    while twin.time_s < end - 1e-9:
        twin.advance()
