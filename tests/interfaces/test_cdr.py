"""The direct CDR encoders give what rclpy's serializer gives (compared as deserialized)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("cdw_interfaces")

from builtin_interfaces.msg import Time
from cdw_interfaces.msg import (
    Detection,
    DetectionArray,
    LockstepTick,
    ObjectState,
    ObjectStateArray,
)
from geometry_msgs.msg import PoseStamped
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from interfaces import cdr


def _same(encoded: bytes, msg: Any) -> None:
    """``encoded`` deserializes to ``msg`` in rclpy, and rosbags (a strict reader of
    recordings: the size must match exactly) reads it and writes it back byte for byte."""
    assert encoded[:4] == cdr.CDR_HEADER
    assert deserialize_message(encoded, type(msg)) == msg
    typename = msg.__class__.__module__.split(".")[0] + "/msg/" + type(msg).__name__
    store = _typestore()
    assert store.serialize_cdr(store.deserialize_cdr(encoded, typename), typename) == encoded


def _typestore() -> Any:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    msg_dir = Path(__file__).resolve().parents[2] / "interfaces" / "cdw_interfaces" / "msg"
    types = {}
    for path in sorted(msg_dir.glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"cdw_interfaces/msg/{path.stem}"))
    store.register(types)
    return store


def test_clock() -> None:
    _same(cdr.clock_cdr(12, 345), Clock(clock=Time(sec=12, nanosec=345)))


@pytest.mark.parametrize("frame_id", ["world", "", "s1/panda_link0"])
def test_pose_stamped(frame_id: str) -> None:
    msg = PoseStamped()
    msg.header.stamp = Time(sec=3, nanosec=999_999_999)
    msg.header.frame_id = frame_id
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z = 0.1, -2.5, math.pi
    o.x, o.y, o.z, o.w = 0.0, 0.6, 0.0, 0.8
    _same(
        cdr.pose_stamped_cdr(3, 999_999_999, frame_id, (0.1, -2.5, math.pi), (0, 0.6, 0, 0.8)), msg
    )


@pytest.mark.parametrize("n", [0, 1, 7, 9])
def test_joint_state(n: int) -> None:
    names = [f"panda_joint{i}" for i in range(n)]
    q = [0.1 * i - 0.3 for i in range(n)]
    qd = [-0.01 * i for i in range(n)]
    msg = JointState(name=names, position=q, velocity=qd)
    msg.header.stamp = Time(sec=1, nanosec=4_166_667)
    _same(cdr.joint_state_cdr(1, 4_166_667, names, q, qd), msg)


def test_lockstep_tick() -> None:
    values = cdr.TickValues(
        tick=2**40 + 3,
        sec=5,
        nanosec=7,
        n_joint_states=2,
        n_belt_states=1,
        n_detections=0,
        last_joint_state_ns=5_000_000_007,
        last_belt_state_ns=-1,
        last_detections_ns=4_966_666_667,
        n_claims=1,
        last_claims_ns=-1,
    )
    msg = LockstepTick(
        tick=values.tick,
        stamp=Time(sec=5, nanosec=7),
        n_joint_states=2,
        n_belt_states=1,
        n_detections=0,
        last_joint_state_ns=5_000_000_007,
        last_belt_state_ns=-1,
        last_detections_ns=4_966_666_667,
        n_claims=1,
        last_claims_ns=-1,
    )
    _same(cdr.lockstep_tick_cdr(values), msg)


@pytest.mark.parametrize("count", [0, 1, 3])
def test_object_state_array(count: int) -> None:
    values = [
        cdr.ObjectStateValues(
            id=i + 1,
            class_name=("brick", "wood", "concrete_rubble")[i],
            position_m=(0.1 * i, 0.5, 0.02),
            orientation_xyzw=(0.0, 0.0, 0.6, 0.8),
            linear_velocity_mps=(0.4, 0.0, -0.01),
            angular_velocity_radps=(0.0, 0.1 * i, 0.0),
            length_m=0.2,
            width_m=0.05,
            height_m=0.03,
            area_m2=0.008,
            volume_m3=0.00024,
            mass_kg=0.45,
            on_belt=i != 1,
            in_workspace=i == 1,
            held=i == 2,
            in_bin=False,
        )
        for i in range(count)
    ]
    msg = ObjectStateArray()
    msg.header.stamp = Time(sec=9, nanosec=1)
    msg.header.frame_id = "world"
    for v in values:
        state = ObjectState(
            id=v.id,
            class_name=v.class_name,
            length_m=v.length_m,
            width_m=v.width_m,
            height_m=v.height_m,
            area_m2=v.area_m2,
            volume_m3=v.volume_m3,
            mass_kg=v.mass_kg,
            on_belt=v.on_belt,
            in_workspace=v.in_workspace,
            held=v.held,
            in_bin=v.in_bin,
        )
        p, o = state.pose.position, state.pose.orientation
        p.x, p.y, p.z = v.position_m
        o.x, o.y, o.z, o.w = v.orientation_xyzw
        lin, ang = state.twist.linear, state.twist.angular
        lin.x, lin.y, lin.z = v.linear_velocity_mps
        ang.x, ang.y, ang.z = v.angular_velocity_radps
        msg.objects.append(state)
    _same(cdr.object_state_array_cdr(9, 1, "world", values), msg)


@pytest.mark.parametrize("count", [0, 1, 4])
def test_detection_array(count: int) -> None:
    values = [
        cdr.DetectionValues(
            class_name=("brick", "wood", "concrete", "rubber")[i],
            confidence=cdr.float32(0.9 - 0.13 * i),
            position_m=(-1.0 + 0.1 * i, 0.45, 0.003),
            yaw_rad=0.3 * i,
            length_m=0.2,
            width_m=0.05,
            height_m=0.03,
            # the last one without a suction point (the message's default: none)
            suction_point_m=(-0.99 + 0.1 * i, 0.44, 0.033) if i < 3 else (0.0, 0.0, 0.0),
            suction_radius_m=0.021 if i < 3 else 0.0,
            suction_tilt_rad=0.1 * i if i < 3 else 0.0,
        )
        for i in range(count)
    ]
    msg = DetectionArray()
    msg.header.stamp = Time(sec=2, nanosec=33_333_333)
    msg.header.frame_id = "world"
    for v in values:
        det = Detection(
            class_name=v.class_name,
            confidence=v.confidence,
            yaw_rad=v.yaw_rad,
            length_m=v.length_m,
            width_m=v.width_m,
            height_m=v.height_m,
            suction_radius_m=v.suction_radius_m,
            suction_tilt_rad=v.suction_tilt_rad,
        )
        det.position.x, det.position.y, det.position.z = v.position_m
        det.suction_point.x, det.suction_point.y, det.suction_point.z = v.suction_point_m
        msg.detections.append(det)
    _same(cdr.detection_array_cdr(2, 33_333_333, "world", values), msg)


def test_float32_is_what_the_wire_carries() -> None:
    from rclpy.serialization import serialize_message

    msg = DetectionArray(detections=[Detection(confidence=0.1)])
    wire = deserialize_message(serialize_message(msg), DetectionArray).detections[0].confidence
    assert cdr.float32(0.1) == wire != 0.1
    assert cdr.float32(wire) == wire
