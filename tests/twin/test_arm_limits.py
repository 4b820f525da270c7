"""The arm moves within its datasheet limits, whatever it is commanded (PyBullet, the twin's
own joint motors), and the twin knows the datasheet's position limits."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from twin_helpers import box_px

from twin.commands import Rejected, validate_joint_command
from twin.scenario import Scenario, SystemLevel
from twin.sim import ArmCommand, Twin

ONE_BOX = {"img": [(1, box_px(500, 500, 100, 50))]}


def _still() -> Scenario:
    return Scenario(
        duration_s=30.0,
        system=SystemLevel(belt_speed_mps=0.0, prefill_m=1.7, repeat_images=False),
    )


def test_a_position_step_moves_joint_1_within_its_datasheet_limits(
    mesh_polygons: Callable[..., Path],
) -> None:
    """A 1 rad step of the Panda's joint 1 (datasheet: 2.175 rad/s, 15 rad/s^2) used to move it
    at over 12 rad/s and 290 rad/s^2. The joint, as PyBullet moves it, now stays near its limits
    (its motor tracks the limited targets with a small lag, so a few percent over them) and
    still gets there."""
    with Twin(_still(), dataset_dir=mesh_polygons(ONE_BOX)) as twin:
        twin.reset(seed=0)
        robot = twin.stations[0].robot
        vmax = robot.limits.velocity[0]
        amax = robot.spec.joint_max_acceleration_rps2[0]
        assert (vmax, amax) == (2.175, 15.0)
        for _ in range(100):
            twin.advance()
        q = np.array(robot.spec.home_joint_positions)
        q[0] += 1.0
        twin.command(ArmCommand(tuple(q)))
        velocities = []
        for _ in range(round(2.0 / twin.dt_s)):
            twin.advance()
            velocities.append(robot.joint_state()[1][0])
        reached = robot.joint_state()[0][0]
    v = np.array(velocities)
    a = np.diff(v) / twin.dt_s
    assert np.abs(v).max() <= 1.1 * vmax
    assert np.abs(v).max() >= 0.95 * vmax  # at full speed in the middle of the move
    assert np.abs(a).max() <= 1.25 * amax
    assert reached == pytest.approx(q[0], abs=2e-3)


def test_the_twin_has_the_datasheet_position_limits_and_rejects_commands_beyond_them(
    mesh_polygons: Callable[..., Path],
) -> None:
    """The Panda's joint 4 is [-3.0718, -0.0698] (its URDF says [-3.1416, 0]): the station
    URDF carries the datasheet's limits, and a command beyond them is rejected naming them."""
    with Twin(_still(), dataset_dir=mesh_polygons(ONE_BOX)) as twin:
        twin.reset(seed=0)
        robot = twin.stations[0].robot
        lower, upper = robot.limits.lower[3], robot.limits.upper[3]
        names = list(robot.spec.arm_joints)
        q = list(robot.spec.home_joint_positions)
    assert (lower, upper) == pytest.approx((-3.0718, -0.0698), abs=1e-9)
    q[3] = -0.05  # within the URDF's [-3.1416, 0], beyond the datasheet's
    result = validate_joint_command(
        names,
        q,
        [],
        arm_joints=names,
        lower=robot.limits.lower,
        upper=robot.limits.upper,
        velocity_limit=robot.limits.velocity,
    )
    assert isinstance(result, Rejected)
    assert result.reason == "beyond_limits"
    assert "panda_joint4 position -0.0500 rad outside its limits [-3.0718, -0.0698]" in (
        result.detail
    )
