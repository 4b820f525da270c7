"""The in-process bus delivers what DDS would: in order, queued, latched, as the wire gives it."""

from __future__ import annotations

from typing import Any

import pytest

pytest.importorskip("cdw_interfaces")

from cdw_interfaces.msg import Detection, DetectionArray, LockstepTick
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from interfaces.contract import LATCHED, STATE
from interfaces.inproc import Bus, needs_wire_copy


def test_callbacks_run_from_spin_once_in_publish_order_never_inside_publish() -> None:
    bus = Bus()
    got: list[tuple[str, int]] = []
    pub = bus.create_publisher(LockstepTick, "/tick", STATE)
    echo = bus.create_publisher(LockstepTick, "/echo", STATE)

    def on_tick(msg: Any) -> None:
        got.append(("tick", msg.tick))
        echo.publish(LockstepTick(tick=msg.tick + 100))

    bus.create_subscription(LockstepTick, "/tick", on_tick, STATE)
    bus.create_subscription(LockstepTick, "/echo", lambda m: got.append(("echo", m.tick)), STATE)
    pub.publish(LockstepTick(tick=1))
    pub.publish(LockstepTick(tick=2))
    assert got == []
    bus.spin_once(timeout_sec=0.0)
    assert got == [("tick", 1), ("tick", 2), ("echo", 101), ("echo", 102)]
    assert bus.idle


def test_a_float32_field_arrives_rounded_as_over_the_wire() -> None:
    bus = Bus()
    received: list[Any] = []
    pub = bus.create_publisher(DetectionArray, "/objects/detections", STATE)
    bus.create_subscription(DetectionArray, "/objects/detections", received.append, STATE)
    sent = DetectionArray(detections=[Detection(class_name="brick", confidence=0.1, yaw_rad=0.1)])
    pub.publish(sent)
    bus.spin_once()
    wire = deserialize_message(serialize_message(sent), DetectionArray)
    (msg,) = received
    assert msg.detections[0].confidence == wire.detections[0].confidence != 0.1
    assert msg.detections[0].yaw_rad == 0.1  # float64 untouched
    assert msg is not sent
    assert needs_wire_copy(DetectionArray)
    assert not needs_wire_copy(JointState)


def test_raw_subscriptions_take_bytes_and_bytes_reach_typed_ones_deserialized() -> None:
    bus = Bus()
    raw: list[Any] = []
    typed: list[Any] = []
    pub = bus.create_publisher(JointState, "/joint_states", STATE)
    bus.create_subscription(JointState, "/joint_states", raw.append, STATE, raw=True)
    bus.create_subscription(JointState, "/joint_states", typed.append, STATE)
    msg = JointState(name=["j1"], position=[0.5])
    pub.publish(msg)
    pub.publish(serialize_message(JointState(name=["j2"], position=[0.25])))
    bus.spin_once()
    assert all(isinstance(data, bytes) for data in raw)
    assert [list(deserialize_message(data, JointState).name) for data in raw] == [["j1"], ["j2"]]
    assert [list(m.name) for m in typed] == [["j1"], ["j2"]]
    assert typed[1].position[0] == 0.25


def test_a_late_subscriber_of_a_latched_topic_gets_the_kept_messages() -> None:
    bus = Bus()
    pub = bus.create_publisher(LockstepTick, "/latched", LATCHED)
    pub.publish(LockstepTick(tick=1))
    pub.publish(LockstepTick(tick=2))  # keep last 1
    late: list[Any] = []
    bus.create_subscription(LockstepTick, "/latched", late.append, LATCHED)
    bus.spin_once()
    assert [m.tick for m in late] == [2]


def test_counts_match_the_graph_and_a_destroyed_subscription_gets_nothing_more() -> None:
    bus = Bus()
    got: list[Any] = []
    pub = bus.create_publisher(LockstepTick, "/t", STATE)
    sub = bus.create_subscription(LockstepTick, "/t", got.append, STATE)
    assert (pub.get_subscription_count(), sub.get_publisher_count()) == (1, 1)
    assert (bus.count_publishers("/t"), bus.count_subscribers("/t")) == (1, 1)
    pub.publish(LockstepTick(tick=1))
    sub.destroy()
    bus.spin_once()
    assert got == []
    assert pub.get_subscription_count() == 0
