"""Small ROS 2 processes for the tests in this folder (run as scripts, imported for samples).

    python ros_nodes.py publish --token 7    # latch one sample of every type, wait for stdin EOF
    python ros_nodes.py receive --per-topic 1 --linger-s 0.5   # print what arrived as JSON
    python ros_nodes.py idle                 # one node, print "ready", wait for stdin EOF

Every topic is reliable + transient-local (publisher depth 1, receiver depth 10 so samples of
several publishers all arrive), so a receiver that starts after the publisher still gets them.
The environment (``ROS_DOMAIN_ID`` ...) comes from the caller.
"""

# rclpy's annotations are partial (QoSProfile, destroy_node).
# mypy: disable-error-code="no-untyped-call"

from __future__ import annotations

import argparse
import array
import json
import sys
import time
from collections.abc import Callable
from typing import Any

READY = "ready"


def sample_messages(token: int) -> dict[str, Any]:
    """One message of every tested type, keyed by topic; every one carries ``token``."""
    from builtin_interfaces.msg import Duration, Time
    from cdw_interfaces import msg as cdw
    from geometry_msgs.msg import Point, Pose, Quaternion, Twist, Vector3
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64, Header
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    header = Header(stamp=Time(sec=token, nanosec=500_000_000), frame_id="world")
    joints = [f"joint_{i}" for i in range(1, 7)]

    def object_state(object_id: int, class_name: str) -> Any:
        return cdw.ObjectState(
            id=object_id,
            class_name=class_name,
            pose=Pose(
                position=Point(x=1.25, y=-0.5, z=0.875),
                orientation=Quaternion(x=0.0, y=0.0, z=0.6, w=0.8),
            ),
            twist=Twist(linear=Vector3(x=0.5, y=0.0, z=0.0), angular=Vector3(z=-0.25)),
            length_m=0.3,
            width_m=0.2,
            height_m=0.1,
            area_m2=0.06,
            volume_m3=0.0045,
            mass_kg=8.5,
            on_belt=True,
            in_workspace=False,
            held=True,
            in_bin=False,
        )

    def detection(class_name: str, x_m: float) -> Any:
        return cdw.Detection(
            class_name=class_name,
            confidence=0.875,
            position=Point(x=x_m, y=0.125, z=0.9),
            yaw_rad=-1.5,
            length_m=0.31,
            width_m=0.19,
            height_m=0.09,
        )

    return {
        "/rt/object_state": object_state(token, "brick"),
        "/rt/object_states": cdw.ObjectStateArray(
            header=header,
            objects=[object_state(token, "brick"), object_state(token + 1, "wood")],
        ),
        "/rt/detection": detection("concrete", 1.5),
        "/rt/detections": cdw.DetectionArray(
            header=header, detections=[detection("gypsum", 2.0), detection("metal", 2.5)]
        ),
        "/rt/event": cdw.SortingEvent(
            header=header,
            type="placed_in_bin",
            object_id=token,
            class_name="métal",
            detail=json.dumps({"bin": "metal", "x_m": 1.5, "token": token}),
        ),
        "/rt/bins": cdw.SortingBins(
            header=header,
            bins=[
                cdw.SortingBin(
                    class_name="wood",
                    position=Point(x=0.33, y=0.07, z=-0.1),
                    inner_half_m=0.11,
                    size_m=0.24,
                    floor_z_m=-0.4,
                ),
                cdw.SortingBin(
                    class_name="béton", position=Point(x=-0.6, y=float(token)), size_m=1.0
                ),
            ],
        ),
        "/rt/belt": cdw.BeltState(
            header=header,
            setpoint_mps=0.5,
            speed_mps=0.4999,
            position_m=float(token),
            motor_torque_nm=12.25,
            motor_current_a=3.5,
            load_mass_kg=41.0,
        ),
        "/rt/pick_target": cdw.PickTarget(
            header=header,
            track_id=token,
            class_name="wood",
            grasp_point=Point(x=1.0, y=0.25, z=0.95),
            velocity=Vector3(x=0.5),
            yaw_rad=0.75,
            phase="descend",
        ),
        "/rt/ping": cdw.Ping(
            seq=token, client_send_ns=-123_456_789_012, sim_step=2**40 + token, echo_ns=2**62
        ),
        "/rt/step_ack": cdw.StepAck(tick=2**33 + token, n_commands=3, next_tick=2**33 + token + 2),
        "/rt/joint_states": JointState(
            header=header,
            name=joints,
            position=[token * 0.001 + 0.1 * i for i in range(6)],
            velocity=[-0.5 * i for i in range(6)],
            effort=[],
        ),
        "/rt/float64": Float64(data=token + 0.5),
        "/rt/clock": Clock(clock=Time(sec=token, nanosec=999_999_999)),
        "/rt/joint_trajectory": JointTrajectory(
            header=header,
            joint_names=joints,
            points=[
                JointTrajectoryPoint(
                    positions=[0.01 * token + i for i in range(6)],
                    velocities=[0.0] * 6,
                    time_from_start=Duration(sec=1, nanosec=500_000_000),
                )
            ],
        ),
    }


def to_plain(value: Any) -> Any:
    """A ROS message (or field value) as JSON-compatible dicts, lists and scalars."""
    if hasattr(value, "get_fields_and_field_types"):
        return {name: to_plain(getattr(value, name)) for name in value.get_fields_and_field_types()}
    if isinstance(value, list | tuple | array.array):
        return [to_plain(item) for item in value]
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


def _qos(depth: int = 1) -> Any:
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


def _wait_for_stdin_eof() -> None:
    sys.stdin.read()


def publish(token: int) -> int:
    """Latch one sample per topic, then wait until stdin closes."""
    import rclpy

    rclpy.init()
    node = rclpy.create_node(f"rt_publisher_{token}")
    publishers = []
    for topic, message in sample_messages(token).items():
        publisher = node.create_publisher(type(message), topic, _qos())
        publisher.publish(message)
        publishers.append(publisher)
    print(READY, flush=True)
    _wait_for_stdin_eof()
    node.destroy_node()
    rclpy.shutdown()
    return 0


def receive(timeout_s: float, linger_s: float, per_topic: int = 1) -> int:
    """Collect ``per_topic`` samples of every topic; print ``{topic: [message dicts]}`` as JSON."""
    import rclpy
    from rclpy.experimental.events_executor import EventsExecutor

    rclpy.init()
    node = rclpy.create_node("rt_receiver")
    received: dict[str, list[Any]] = {}

    def on_message(topic: str) -> Callable[[Any], None]:
        return lambda message: received.setdefault(topic, []).append(to_plain(message))

    topics = sample_messages(0)
    for topic, message in topics.items():
        node.create_subscription(type(message), topic, on_message(topic), _qos(depth=10))
    executor = EventsExecutor()
    executor.add_node(node)
    deadline_s = time.monotonic() + timeout_s
    complete_at_s: float | None = None
    while time.monotonic() < deadline_s:
        executor.spin_once(timeout_sec=0.05)
        if complete_at_s is None and _complete(received, topics, per_topic):
            complete_at_s = time.monotonic()
        if complete_at_s is not None and time.monotonic() - complete_at_s >= linger_s:
            break
    print(json.dumps(received), flush=True)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()
    return 0 if _complete(received, topics, per_topic) else 3


def _complete(received: dict[str, list[Any]], topics: dict[str, Any], per_topic: int) -> bool:
    return all(len(received.get(topic, [])) >= per_topic for topic in topics)


def idle() -> int:
    """Start one node with a publisher, print ``ready`` and wait until stdin closes."""
    import rclpy
    from std_msgs.msg import Float64

    rclpy.init()
    node = rclpy.create_node("rt_idle")
    publisher = node.create_publisher(Float64, "/rt/idle", _qos())
    publisher.publish(Float64(data=1.0))
    print(READY, flush=True)
    _wait_for_stdin_eof()
    node.destroy_node()
    rclpy.shutdown()
    return 0


def main() -> int:
    """Dispatch the sub-commands."""
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="mode", required=True)
    pub = sub.add_parser("publish")
    pub.add_argument("--token", type=int, required=True)
    rec = sub.add_parser("receive")
    rec.add_argument("--timeout-s", type=float, default=15.0)
    rec.add_argument("--linger-s", type=float, default=0.5)
    rec.add_argument("--per-topic", type=int, default=1)
    sub.add_parser("idle")
    args = parser.parse_args()
    if args.mode == "publish":
        return publish(args.token)
    if args.mode == "receive":
        return receive(args.timeout_s, args.linger_s, args.per_topic)
    return idle()


if __name__ == "__main__":
    sys.exit(main())
