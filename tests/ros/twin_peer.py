"""Peers for the twin node in the tests, run as separate processes.

python twin_peer.py lockstep OUT.json [--die-after TICKS] [--namespace NS]
    a scripted lockstep controller of the station with namespace NS (default: the empty one):
    waits for each tick's messages, sends a deterministic arm command every 24 ticks,
    acknowledges every tick; optionally dies (exit 3) after a tick
python twin_peer.py listen OUT.json SECONDS  (counted from the first message)
    records what arrives on /conveyor/state (setpoints) and how many messages per topic
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections import Counter
from typing import Any

import rclpy
from cdw_interfaces.msg import BeltState, DetectionArray, LockstepTick, StepAck
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

RELIABLE = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE
)
HOME = (0.0, -0.35, 0.0, -2.3, 0.0, 1.95, 0.785)
ARM = [f"panda_joint{i}" for i in range(1, 8)]


def _answer(k: int, arm: Any, ack: Any) -> None:
    """Tick k: an arm command every 24 ticks, then the ack counting it."""
    sent = 0
    if k % 24 == 0:
        t = k / 240.0
        q = [h + 0.3 * math.sin(t + i) for i, h in enumerate(HOME)]
        arm.publish(JointTrajectory(joint_names=ARM, points=[JointTrajectoryPoint(positions=q)]))
        sent += 1
    ack.publish(StepAck(tick=k, n_commands=sent))


def _stuck(ticks: list[LockstepTick], pending: Counter[str]) -> dict[str, Any] | None:
    """The first tick still waiting for its messages, if any (for a failing test's message)."""
    if not ticks:
        return None
    t0 = ticks[0]
    return {
        "tick": int(t0.tick),
        "need": [t0.n_joint_states, t0.n_belt_states, t0.n_detections],
        "pending": dict(pending),
    }


def lockstep(out: str, die_after: int | None, namespace: str = "") -> int:
    from interfaces.contract import ARM_TRAJECTORY, JOINT_STATES, LOCKSTEP_ACK

    rclpy.init()
    node = rclpy.create_node("peer_controller")
    executor = EventsExecutor()
    executor.add_node(node)
    pending: Counter[str] = Counter()
    ticks: list[LockstepTick] = []
    node.create_subscription(
        JointState,
        JOINT_STATES.resolve(namespace),
        lambda _m: pending.update(["joints"]),
        RELIABLE,
    )
    node.create_subscription(
        BeltState, "/conveyor/state", lambda _m: pending.update(["belt"]), RELIABLE
    )
    node.create_subscription(
        DetectionArray, "/objects/detections", lambda _m: pending.update(["det"]), RELIABLE
    )
    node.create_subscription(LockstepTick, "/lockstep/tick", ticks.append, RELIABLE)
    arm = node.create_publisher(JointTrajectory, ARM_TRAJECTORY.resolve(namespace), RELIABLE)
    ack = node.create_publisher(StepAck, LOCKSTEP_ACK.resolve(namespace), RELIABLE)
    handled = 0
    deadline = time.monotonic() + 60.0
    while arm.get_subscription_count() == 0 or ack.get_subscription_count() == 0:
        executor.spin_once(timeout_sec=0.05)
        if time.monotonic() > deadline:
            return 2
    idle_since = time.monotonic()
    while time.monotonic() - idle_since < 5.0:
        executor.spin_once(timeout_sec=0.05)
        while ticks:
            tick = ticks[0]
            need = {
                "joints": tick.n_joint_states,
                "belt": tick.n_belt_states,
                "det": tick.n_detections,
            }
            if any(pending[k] < n for k, n in need.items()):
                break
            ticks.pop(0)
            for k, n in need.items():
                pending[k] -= n
            _answer(int(tick.tick), arm, ack)
            handled += 1
            idle_since = time.monotonic()
            if die_after is not None and handled >= die_after:
                with open(out, "w", encoding="utf-8") as handle:
                    json.dump({"handled": handled, "died": True}, handle)
                os._exit(3)
    with open(out, "w", encoding="utf-8") as handle:
        json.dump({"handled": handled, "died": False, "stuck": _stuck(ticks, pending)}, handle)
    node.destroy_node()
    rclpy.shutdown()
    return 0


def listen(out: str, seconds: float) -> int:
    rclpy.init()
    node = rclpy.create_node("peer_listener")
    executor = EventsExecutor()
    executor.add_node(node)
    setpoints: set[float] = set()
    counts: Counter[str] = Counter()

    def on_belt(msg: BeltState) -> None:
        setpoints.add(round(msg.setpoint_mps, 6))
        counts["/conveyor/state"] += 1

    node.create_subscription(BeltState, "/conveyor/state", on_belt, RELIABLE)
    # the window starts with the first message (a loaded machine starts the twin late)
    start_by = time.monotonic() + 60.0
    while not counts and time.monotonic() < start_by:
        executor.spin_once(timeout_sec=0.05)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    with open(out, "w", encoding="utf-8") as handle:
        json.dump({"setpoints": sorted(setpoints), "counts": counts}, handle)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    if sys.argv[1] == "lockstep":
        parser = argparse.ArgumentParser()
        parser.add_argument("mode")
        parser.add_argument("out")
        parser.add_argument("--die-after", type=int, default=None)
        parser.add_argument("--namespace", default="")
        args = parser.parse_args()
        sys.exit(lockstep(args.out, args.die_after, args.namespace))
    sys.exit(listen(sys.argv[2], float(sys.argv[3])))
