"""IK and FK against PyBullet's forward kinematics on the same URDF (real PyBullet, DIRECT)."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np
import pybullet
import pytest

from control.config import ControllerConfig, IkConfig
from control.errors import RobotModelError
from control.ik import Kinematics, tool_pose
from interfaces.cell import load_cell
from interfaces.robots import RobotSpec, resolve_urdf, robot_from_data


@dataclass(frozen=True)
class Arm:
    """A robot with its TCP and base pose, as a station places it."""

    robot: RobotSpec
    tcp_link: str
    tcp_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    base_position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    base_yaw_rad: float = 0.0

    def kinematics(self, ik: IkConfig | None = None) -> Kinematics:
        return Kinematics(
            self.robot,
            tcp_link=self.tcp_link,
            tcp_offset_m=self.tcp_offset_m,
            base_position_m=self.base_position_m,
            base_yaw_rad=self.base_yaw_rad,
            ik=ik,
        )


PANDA_SPEC = robot_from_data("panda", "robot")
PANDA = Arm(PANDA_SPEC, "panda_grasptarget")
IIWA = Arm(
    replace(
        PANDA_SPEC,
        name="iiwa",
        urdf="kuka_iiwa/model.urdf",
        arm_joints=tuple(f"lbr_iiwa_joint_{i}" for i in range(1, 8)),
        ready_joint_positions_rad=(0.0, 0.5, 0.0, -1.2, 0.0, 1.0, 0.0),
    ),
    "lbr_iiwa_link_7",
    tcp_offset_m=(0.0, 0.0, 0.1),
)
PANDA_ON_PEDESTAL = replace(PANDA, base_position_m=(0.1, -0.05, 0.2), base_yaw_rad=math.pi / 4)


@pytest.fixture
def client() -> Iterator[int]:
    cid = pybullet.connect(pybullet.DIRECT)
    yield cid
    pybullet.disconnect(physicsClientId=cid)


def _pybullet_tcp(client: int, arm: Arm, q: np.ndarray) -> np.ndarray:
    """World TCP position from PyBullet's FK for arm configuration ``q``."""
    body = pybullet.loadURDF(
        str(resolve_urdf(arm.robot.urdf)),
        basePosition=arm.base_position_m,
        baseOrientation=pybullet.getQuaternionFromEuler((0.0, 0.0, arm.base_yaw_rad)),
        useFixedBase=True,
        physicsClientId=client,
    )
    joints = {}
    links = {}
    for j in range(pybullet.getNumJoints(body, physicsClientId=client)):
        info = pybullet.getJointInfo(body, j, physicsClientId=client)
        joints[info[1].decode()] = j
        links[info[12].decode()] = j
    for name, value in zip(arm.robot.arm_joints, q, strict=True):
        pybullet.resetJointState(body, joints[name], float(value), physicsClientId=client)
    state = pybullet.getLinkState(
        body, links[arm.tcp_link], computeForwardKinematics=True, physicsClientId=client
    )
    position = np.asarray(state[4])
    rotation = np.asarray(pybullet.getMatrixFromQuaternion(state[5])).reshape(3, 3)
    pybullet.removeBody(body, physicsClientId=client)
    return np.asarray(position + rotation @ np.asarray(arm.tcp_offset_m))


@pytest.mark.parametrize("arm", [PANDA, PANDA_ON_PEDESTAL, IIWA], ids=["panda", "pedestal", "iiwa"])
def test_fk_and_ik_match_pybullet(client: int, arm: Arm) -> None:
    kin = arm.kinematics(IkConfig())
    rng = np.random.default_rng(11)
    solved = 0
    for _ in range(20):
        q_true = rng.uniform(kin.lower_rad * 0.9, kin.upper_rad * 0.9)
        reference = _pybullet_tcp(client, arm, q_true)
        assert np.allclose(kin.fk(q_true).translation, reference, atol=1e-9)
        # Warm start near the true configuration, as in the control loop.
        q_init = np.clip(q_true + rng.normal(0.0, 0.1, kin.nq), kin.lower_rad, kin.upper_rad)
        result = kin.solve(kin.fk(q_true), q_init)
        assert kin.within_limits(result.q)
        if result.success:
            solved += 1
            reached = _pybullet_tcp(client, arm, np.asarray(result.q))
            assert np.linalg.norm(reached - reference) < 1e-6
            assert result.error_norm < 1e-6
    assert solved >= 18


def test_ik_failure_is_flagged_and_stays_in_limits() -> None:
    kin = PANDA.kinematics(IkConfig(max_iterations=50))
    q0 = np.asarray(PANDA_SPEC.ready_joint_positions_rad)
    result = kin.solve(tool_pose((0.1, 0.0, 0.1), 0.0), q0)  # in reach, into the arm itself
    assert not result.success
    assert result.iterations == 50
    assert result.error_norm > 0.1
    assert kin.within_limits(result.q)
    wide = kin.solve(tool_pose((1.0, 0.0, 0.333), 0.0), q0)  # the wrist cannot be that far
    assert not wide.success
    assert wide.iterations == 0
    assert kin.within_limits(wide.q)
    far = kin.solve(tool_pose((2.0, 0.0, 0.3), 0.0), q0)  # beyond the reach bound
    assert not far.success
    assert far.iterations == 0
    assert kin.within_limits(far.q)
    nan_result = kin.solve(tool_pose((np.nan, 0.0, 0.3), 0.0), q0)
    assert not nan_result.success
    assert kin.within_limits(nan_result.q)


@pytest.mark.parametrize("name", ["panda", "iiwa", "line_ur10_cup", "line_ur10_gripper"])
def test_reach_bound_holds_in_every_configuration(name: str) -> None:
    """No configuration puts the TCP beyond ``reach_m`` from the first joint, and the bound is
    not far above the farthest sampled TCP: a pose beyond it is rightly refused unsolved."""
    if name.startswith("line"):
        stations = load_cell("line").stations
        station = stations[0] if name.endswith("cup") else stations[-1]
        kin = Kinematics.of_station(station)
    else:
        kin = {"panda": PANDA, "iiwa": IIWA}[name].kinematics()
    rng = np.random.default_rng(7)
    base = kin.oMbase.translation + kin.oMbase.rotation @ np.asarray(kin.reach_origin_m)
    farthest = 0.0
    for _ in range(2000):
        q = rng.uniform(kin.lower_rad, kin.upper_rad)
        farthest = max(farthest, float(np.linalg.norm(kin.fk(q).translation - base)))
    assert farthest <= kin.reach_m
    assert kin.reach_m < 1.6 * farthest


def test_warm_start_converges_in_few_iterations() -> None:
    kin = PANDA.kinematics()
    q0 = np.asarray(PANDA_SPEC.ready_joint_positions_rad)
    q = kin.solve(tool_pose((0.0, 0.45, 0.30), 1.5), q0).q
    for k in range(50):
        result = kin.solve(tool_pose((0.002 * k, 0.45, 0.30 - 0.002 * k), 1.5), q)
        assert result.success
        assert result.iterations <= 4
        q = result.q


def test_bad_robot_description_is_reported() -> None:
    shifted = replace(PANDA_SPEC, arm_joints=tuple(f"panda_joint{i}" for i in range(3, 10)))
    with pytest.raises(RobotModelError, match="no joint 'panda_joint8'"):
        Kinematics(shifted, tcp_link="panda_grasptarget")
    with pytest.raises(RobotModelError, match=r"tool\.tcp_link: no link or frame 'gripper'"):
        Kinematics(PANDA_SPEC, tcp_link="gripper")
    with pytest.raises(RobotModelError, match=r"robot\.urdf = 'no/such\.urdf'"):
        Kinematics(replace(PANDA_SPEC, urdf="no/such.urdf"), tcp_link="panda_grasptarget")


def test_the_ik_converges_along_a_joint_limit() -> None:
    """A pose over the belt's far edge, low, from a seed that runs the arm into a joint limit
    on the way: the solve goes on with the other joints (before, the steps clipped at the limit
    left 5.5e-4 of error after the iteration limit, over the accept tolerance)."""
    config = ControllerConfig(cell=load_cell("suction"))
    kin = Kinematics.of_station(config.station, config.ik)
    seed = np.array([1.2151, -1.0195, 0.1539, -2.2893, -0.1590, 1.8292, 1.3303])
    target = tool_pose((-0.3359, 0.7189, 0.0178), -0.7154)
    result = kin.solve(target, seed)
    assert result.success
    assert result.error_norm < config.ik.accept_tolerance
    assert kin.within_limits(result.q)
    reached = kin.fk(result.q)
    assert np.allclose(reached.translation, target.translation, atol=1e-4)


def test_tilt_held_rates_move_the_tcp_as_asked_and_keep_the_tool_vertical() -> None:
    """The joint rates of :meth:`Kinematics.tilt_held_rates` give the requested world
    ``(vx, vy, vz, yaw rate)`` of the TCP with no roll or pitch: a small step along them moves
    a downward-pointing tool to the pose that far away, pointing down still."""
    config = ControllerConfig(cell=load_cell("suction"))
    kin = Kinematics.of_station(config.station, config.ik)
    seed = np.asarray(config.robot.ready_joint_positions_rad)
    start = kin.solve(tool_pose((0.1, 0.5, 0.1), 1.2), seed)
    assert start.success
    rates = kin.tilt_held_rates(np.asarray(start.q))
    assert rates.shape == (kin.nq, 4)
    for axis, twist in enumerate(np.eye(4)):
        dt = 1e-4
        q = np.asarray(start.q) + rates @ twist * dt
        moved = kin.fk(q)
        want = tool_pose(
            (0.1 + twist[0] * dt, 0.5 + twist[1] * dt, 0.1 + twist[2] * dt), 1.2 + twist[3] * dt
        )
        error = np.linalg.norm((want.inverse() * moved).homogeneous - np.eye(4))
        assert error < 1e-6, axis
