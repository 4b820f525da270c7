"""IK and FK against PyBullet's forward kinematics on the same URDF (real PyBullet, DIRECT)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pybullet
import pytest

from control.config import IkConfig, RobotConfig, resolve_urdf_path
from control.errors import RobotModelError
from control.ik import Kinematics, tool_pose

IIWA = RobotConfig(
    urdf_path="kuka_iiwa/model.urdf",
    tcp_link="lbr_iiwa_link_7",
    tcp_offset_m=(0.0, 0.0, 0.1),
    arm_joint_names=tuple(f"lbr_iiwa_joint_{i}" for i in range(1, 8)),
    finger_joint_names=(),
    ready_joint_positions_rad=(0.0, 0.5, 0.0, -1.2, 0.0, 1.0, 0.0),
)
PANDA_ON_PEDESTAL = RobotConfig(
    base_position_m=(0.1, -0.05, 0.2), base_orientation_xyzw=(0.0, 0.0, 0.38268343, 0.92387953)
)


@pytest.fixture
def client() -> Iterator[int]:
    cid = pybullet.connect(pybullet.DIRECT)
    yield cid
    pybullet.disconnect(physicsClientId=cid)


def _pybullet_tcp(client: int, robot: RobotConfig, q: np.ndarray) -> np.ndarray:
    """World TCP position from PyBullet's FK for arm configuration ``q``."""
    body = pybullet.loadURDF(
        str(resolve_urdf_path(robot.urdf_path)),
        basePosition=robot.base_position_m,
        baseOrientation=robot.base_orientation_xyzw,
        useFixedBase=True,
        physicsClientId=client,
    )
    joints = {}
    links = {}
    for j in range(pybullet.getNumJoints(body, physicsClientId=client)):
        info = pybullet.getJointInfo(body, j, physicsClientId=client)
        joints[info[1].decode()] = j
        links[info[12].decode()] = j
    for name, value in zip(robot.arm_joint_names, q, strict=True):
        pybullet.resetJointState(body, joints[name], float(value), physicsClientId=client)
    state = pybullet.getLinkState(
        body, links[robot.tcp_link], computeForwardKinematics=True, physicsClientId=client
    )
    position = np.asarray(state[4])
    rotation = np.asarray(pybullet.getMatrixFromQuaternion(state[5])).reshape(3, 3)
    pybullet.removeBody(body, physicsClientId=client)
    return np.asarray(position + rotation @ np.asarray(robot.tcp_offset_m))


@pytest.mark.parametrize(
    "robot", [RobotConfig(), PANDA_ON_PEDESTAL, IIWA], ids=["panda", "pedestal", "iiwa"]
)
def test_fk_and_ik_match_pybullet(client: int, robot: RobotConfig) -> None:
    kin = Kinematics(robot, IkConfig())
    rng = np.random.default_rng(11)
    solved = 0
    for _ in range(20):
        q_true = rng.uniform(kin.lower_rad * 0.9, kin.upper_rad * 0.9)
        reference = _pybullet_tcp(client, robot, q_true)
        assert np.allclose(kin.fk(q_true).translation, reference, atol=1e-9)
        # Warm start near the true configuration, as in the control loop.
        q_init = np.clip(q_true + rng.normal(0.0, 0.1, kin.nq), kin.lower_rad, kin.upper_rad)
        result = kin.solve(kin.fk(q_true), q_init)
        assert kin.within_limits(result.q)
        if result.success:
            solved += 1
            reached = _pybullet_tcp(client, robot, np.asarray(result.q))
            assert np.linalg.norm(reached - reference) < 1e-6
            assert result.error_norm < 1e-6
    assert solved >= 18


def test_ik_failure_is_flagged_and_stays_in_limits() -> None:
    kin = Kinematics(RobotConfig(), IkConfig(max_iterations=50))
    q0 = np.asarray(RobotConfig().ready_joint_positions_rad)
    result = kin.solve(tool_pose((2.0, 0.0, 0.3), 0.0), q0)
    assert not result.success
    assert result.iterations == 50
    assert result.error_norm > 0.1
    assert kin.within_limits(result.q)
    nan_result = kin.solve(tool_pose((np.nan, 0.0, 0.3), 0.0), q0)
    assert not nan_result.success
    assert kin.within_limits(nan_result.q)


def test_warm_start_converges_in_few_iterations() -> None:
    robot = RobotConfig()
    kin = Kinematics(robot)
    q = kin.solve(tool_pose((0.0, 0.45, 0.30), 1.5), np.asarray(robot.ready_joint_positions_rad)).q
    for k in range(50):
        result = kin.solve(tool_pose((0.002 * k, 0.45, 0.30 - 0.002 * k), 1.5), q)
        assert result.success
        assert result.iterations <= 4
        q = result.q


def test_bad_robot_description_is_reported() -> None:
    with pytest.raises(RobotModelError, match="no joint 'panda_joint8'"):
        Kinematics(
            RobotConfig(
                arm_joint_names=tuple(f"panda_joint{i}" for i in range(3, 10)),
            )
        )
    with pytest.raises(RobotModelError, match=r"robot\.tcp_link: no link or frame 'gripper'"):
        Kinematics(RobotConfig(tcp_link="gripper"))
