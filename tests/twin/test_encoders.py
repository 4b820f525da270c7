"""Both forms of each outgoing message (:mod:`twin.encoders`) carry the same values: the CDR
bytes decode (rclpy) to the message the in-process bus is handed."""

from __future__ import annotations

import math
from typing import Any

import pytest

pytest.importorskip("cdw_interfaces")

from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message

from interfaces import cdr
from interfaces.detections import Detection
from twin import encoders as enc
from twin.ground_truth import GroundTruth
from twin.top_view import TopView

STAMP = Time(sec=12, nanosec=345_678_901)


def _same_values(out: enc.Outgoing) -> Any:
    """The message ``out`` builds, checked equal to its bytes decoded."""
    built = out.build()
    assert deserialize_message(out.encode(), type(built)) == built
    return built


def test_clock_and_tcp_pose() -> None:
    assert _same_values(enc.clock(STAMP)).clock == STAMP
    pose = _same_values(enc.pose_stamped(STAMP, (0.1, -0.2, 0.3), (0.0, 0.0, 0.6, 0.8)))
    assert pose.header.frame_id == enc.WORLD
    assert (pose.pose.orientation.z, pose.pose.orientation.w) == (0.6, 0.8)


def test_joint_states_keep_names_and_order() -> None:
    names = ["j1", "j2", "finger"]
    msg = _same_values(enc.joint_state(STAMP, names, [0.1, 0.2, 0.04], [0.0, -1.5, 0.0]))
    assert list(msg.name) == names
    assert list(msg.velocity) == [0.0, -1.5, 0.0]


def test_lockstep_tick() -> None:
    values = cdr.TickValues(
        tick=7,
        sec=STAMP.sec,
        nanosec=STAMP.nanosec,
        n_joint_states=2,
        n_belt_states=1,
        n_detections=0,
        n_claims=3,
        last_joint_state_ns=12_345_678_901,
        last_belt_state_ns=-1,
        last_detections_ns=-1,
        last_claims_ns=9,
    )
    tick = _same_values(enc.lockstep_tick(STAMP, values))
    assert (tick.tick, tick.n_claims, tick.last_belt_state_ns) == (7, 3, -1)


def test_detections_round_confidence_to_float32_and_zero_a_missing_suction_point() -> None:
    with_point = Detection(
        class_name="brick",
        confidence=0.1,  # not a float32
        x_m=0.5,
        y_m=0.1,
        z_m=0.9,
        yaw_rad=0.3,
        length_m=0.2,
        width_m=0.1,
        height_m=0.05,
        suction_point_m=(0.51, 0.11, 0.95),
        suction_radius_m=0.02,
        suction_tilt_rad=0.1,
    )
    without = Detection(
        class_name="wood",
        confidence=0.9,
        x_m=0.7,
        y_m=0.0,
        z_m=0.9,
        yaw_rad=0.0,
        length_m=0.3,
        width_m=0.1,
        height_m=0.02,
    )
    msg = _same_values(enc.detections(STAMP, [with_point, without]))
    first, second = msg.detections
    assert first.confidence == cdr.float32(0.1)
    assert first.confidence != 0.1
    assert first.suction_radius_m == 0.02
    assert (second.suction_point.x, second.suction_radius_m) == (0.0, 0.0)
    assert math.isnan(without.suction_radius_m)


def test_ground_truth() -> None:
    gt = GroundTruth(
        id=3,
        source_id="img_0",
        class_name="brick",
        position_m=(0.4, 0.0, 0.92),
        orientation_xyzw=(0.0, 0.0, 0.0, 1.0),
        linear_velocity_mps=(0.4, 0.0, 0.0),
        angular_velocity_radps=(0.0, 0.0, 0.1),
        top_view=TopView(yaw_rad=0.0, length_m=0.2, width_m=0.1, height_m=0.05, below_m=0.025),
        length_m=0.2,
        width_m=0.1,
        area_m2=0.02,
        volume_m3=0.001,
        height_m=0.05,
        mass_kg=1.5,
        on_belt=True,
        in_workspace=False,
        held=False,
        in_bin=False,
    )
    msg = _same_values(enc.ground_truth(STAMP, [gt]))
    (state,) = msg.objects
    assert (state.id, state.mass_kg, state.on_belt) == (3, 1.5, True)
