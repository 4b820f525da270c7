"""Arm command validation: the whole command is rejected, and the reason names what and why."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pybullet as pb
import pytest

from interfaces.cell import default_cell
from twin.commands import JointTarget, Rejected, command_age_s, validate_joint_command
from twin.robot import JointLimits, Robot

PANDA = default_cell().stations[0].robot
ARM = PANDA.arm_joints
HOME = PANDA.home_joint_positions


@pytest.fixture(scope="module")
def limits() -> Iterator[JointLimits]:
    """The Panda's joint limits as the twin loads them from the URDF."""
    client = pb.connect(pb.DIRECT)
    try:
        yield Robot(client, PANDA).limits
    finally:
        pb.disconnect(physicsClientId=client)


def _check(
    limits: JointLimits,
    names: list[str],
    positions: list[float],
    velocities: list[float] | None = None,
) -> JointTarget | Rejected:
    return validate_joint_command(
        names,
        positions,
        velocities or [],
        arm_joints=ARM,
        lower=limits.lower,
        upper=limits.upper,
        velocity_limit=limits.velocity,
    )


def test_a_velocity_beyond_its_joint_limit_rejects_the_command_and_states_the_limit(
    limits: JointLimits,
) -> None:
    velocities = [0.0] * 7
    velocities[1] = -2.5  # panda_joint2: 2.175 rad/s
    result = _check(limits, list(ARM), list(HOME), velocities)
    assert isinstance(result, Rejected)
    assert result.reason == "beyond_limits"
    assert result.detail == (
        "panda_joint2 velocity -2.5000 rad/s outside its limit [-2.1750, 2.1750]"
    )


def test_velocities_at_their_limits_are_accepted_in_the_arms_order(limits: JointLimits) -> None:
    names = list(reversed(ARM))
    velocities = list(reversed(limits.velocity.tolist()))
    result = _check(limits, names, list(reversed(HOME)), velocities)
    assert isinstance(result, JointTarget)
    assert result.positions == pytest.approx(HOME)
    assert result.velocities == pytest.approx(limits.velocity.tolist())


def test_a_position_beyond_its_joint_limit_states_the_limits(limits: JointLimits) -> None:
    positions = list(HOME)
    positions[3] = 0.1  # panda_joint4 ends at 0
    result = _check(limits, list(ARM), positions)
    assert isinstance(result, Rejected)
    assert result.reason == "beyond_limits"
    assert result.detail == "panda_joint4 position 0.1000 rad outside its limits [-3.1416, 0.0000]"


def test_a_duplicate_joint_name_is_named_as_a_duplicate(limits: JointLimits) -> None:
    names = list(ARM)
    names[6] = "panda_joint3"  # seven names, one twice, one missing
    result = _check(limits, names, list(HOME))
    assert result == Rejected("duplicate_joint", "duplicate joint name 'panda_joint3'")


def test_an_unknown_joint_name_is_named_with_the_arms_joints(limits: JointLimits) -> None:
    names = [*ARM[:6], "panda_finger_joint1"]
    result = _check(limits, names, list(HOME))
    assert isinstance(result, Rejected)
    assert result.reason == "unknown_joint"
    assert result.detail.startswith("joint names ['panda_finger_joint1'] are not the arm's")
    assert "panda_joint7" in result.detail


def test_the_velocity_limits_are_the_urdfs(limits: JointLimits) -> None:
    """2.175 rad/s on the four shoulder joints, 2.61 rad/s on the wrist (Panda URDF)."""
    assert np.allclose(limits.velocity, [2.175] * 4 + [2.61] * 3)


def test_a_command_is_applied_as_of_its_stamp() -> None:
    """A command stamped one step before it arrives is one step old; an unset stamp (0) or one
    ahead of the twin's clock counts as now."""
    dt_s = 1.0 / 240.0
    assert command_age_s(100 * dt_s, 101 * dt_s) == pytest.approx(dt_s, abs=1e-9)
    assert command_age_s(101 * dt_s, 101 * dt_s) == 0.0
    assert command_age_s(0.0, 101 * dt_s) == 0.0
    assert command_age_s(102 * dt_s, 101 * dt_s) == 0.0


def test_a_late_command_starts_where_it_meant_the_arm_to_be_now() -> None:
    """Its feed-forward velocity has moved the position target on by its age."""
    client = pb.connect(pb.DIRECT)
    try:
        on_time, late = Robot(client, PANDA), Robot(client, PANDA)
        q = np.array(HOME, dtype=float)
        qd = np.full(len(ARM), 0.2)
        on_time.command(q, qd)
        late.command(q, qd, age_s=0.01)
        assert np.allclose(on_time.position_target_rad, q)
        assert np.allclose(late.position_target_rad, q + 0.2 * 0.01)
        late.extrapolate(0.005)
        assert np.allclose(late.position_target_rad, q + 0.2 * 0.015)
    finally:
        pb.disconnect(physicsClientId=client)
