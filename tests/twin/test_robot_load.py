"""Loading a robot: visual meshes parsed once per client, or left out; the physics unchanged."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pybullet as pb
import pytest

from interfaces.cell import load_cell
from interfaces.urdf import station_urdf
from twin.robot import Robot

STATION = load_cell("line").stations[0]
"""The line's first station: a UR10 with a suction cup (visual meshes: COLLADA files)."""


@pytest.fixture
def clients() -> Iterator[tuple[int, int]]:
    """Two PyBullet clients (DIRECT), disconnected afterwards."""
    first, second = pb.connect(pb.DIRECT), pb.connect(pb.DIRECT)
    try:
        yield first, second
    finally:
        pb.disconnect(physicsClientId=first)
        pb.disconnect(physicsClientId=second)


def _robot(client: int, *, visual_shapes: bool = True, x_m: float = 0.0) -> Robot:
    return Robot(
        client,
        STATION.robot,
        base_position_m=(x_m, 0.0, 0.0),
        urdf=station_urdf(STATION.robot, STATION.tool),
        visual_shapes=visual_shapes,
    )


def _visuals(robot: Robot) -> list[tuple[object, ...]]:
    """Per visual shape: link, geometry type, dimensions, mesh file and colour."""
    shapes = pb.getVisualShapeData(robot.body, physicsClientId=robot.client)
    return [(s[1], s[2], s[3], s[4], s[7]) for s in shapes]


def _joint_trace(robot: Robot, steps: int) -> np.ndarray:
    """``(steps, 2 n)`` joint positions and velocities while the arm follows one command."""
    pb.setGravity(0.0, 0.0, -9.81, physicsClientId=robot.client)
    robot.reset_state()
    robot.apply_commands()
    target = np.asarray(STATION.robot.home_joint_positions, dtype=float) + 0.3
    robot.command(target)
    rows = []
    for _ in range(steps):
        robot.drive()
        pb.stepSimulation(physicsClientId=robot.client)
        q, qd = robot.joint_state()
        rows.append(np.concatenate([q, qd]))
    return np.array(rows)


def test_a_second_arm_shares_the_first_ones_visual_meshes(clients: tuple[int, int]) -> None:
    first, _ = clients
    a, b = _robot(first), _robot(first, x_m=1.1)
    assert _visuals(a)
    assert _visuals(a) == _visuals(b)


def test_an_arm_without_visual_shapes_moves_exactly_as_one_with_them(
    clients: tuple[int, int],
) -> None:
    """Without its visual meshes (PyBullet shows the collision shapes instead): the same joints
    and limits, and the same joint states bit for bit over 240 steps of a commanded move:
    visuals do not take part in the physics."""
    first, second = clients
    seen, unseen = _robot(first), _robot(second, visual_shapes=False)
    assert any(str(v[3]).endswith(".dae'") for v in _visuals(seen))
    assert not any(str(v[3]).endswith(".dae'") for v in _visuals(unseen))
    assert seen.joints == unseen.joints
    assert np.array_equal(seen.limits.upper, unseen.limits.upper)
    moved = _joint_trace(seen, 240)
    assert np.ptp(moved[:, 0]) > 0.1  # the arm did move
    assert np.array_equal(moved, _joint_trace(unseen, 240))
