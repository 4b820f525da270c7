"""Peers for the twin node in the tests, run as separate processes.

python twin_peer.py lockstep OUT.json [--die-after TICKS] [--namespace NS] [--claims]
                                [--every N]
    a scripted lockstep controller of the station with namespace NS (default: the empty one):
    waits for each tick's messages (the claims board on /line/claims too), sends a
    deterministic arm command every 24 ticks, with --claims the claims of :data:`CLAIMS` on its
    line/claim, acknowledges every tick (with --every N only every N-th, announcing the next
    one in next_tick); optionally dies (exit 3) after a tick. OUT.json has the boards it
    received, the ticks that counted one and the ticks it acknowledged
python twin_peer.py listen OUT.json SECONDS  (counted from the first message)
    records what arrives on /conveyor/state (setpoints) and how many messages per topic
"""

# rclpy's annotations are partial.
# mypy: disable-error-code="no-untyped-call"

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
from cdw_interfaces.msg import (
    BeltState,
    Claim,
    ClaimArray,
    DetectionArray,
    LockstepTick,
    StepAck,
)
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

RELIABLE = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE
)
HOME = (0.0, -0.35, 0.0, -2.3, 0.0, 1.95, 0.785)
ARM = [f"panda_joint{i}" for i in range(1, 8)]
CLAIMS: dict[int, tuple[int, str]] = {
    10: (7, "claimed"),
    11: (8, "claimed"),
    30: (7, "released"),
    50: (9, "grabbed"),  # not a claim state: rejected, the board unchanged
    60: (8, "picked"),
}
"""With --claims: tick -> (track id, state) of the claim sent while handling that tick."""


def _claim(track_id: int, state: str) -> Claim:
    """A claim as a controller sends it; ``station`` is left empty (the twin sets it: a claim
    naming another station is refused)."""
    msg = Claim(station="", track_id=track_id, class_name="brick", state=state)
    msg.header.frame_id = "world"
    msg.position.x, msg.position.y = -1.5 + 0.01 * track_id, 0.5
    msg.velocity.x = 0.4
    msg.radius_m = 0.05
    return msg


def _answer(k: int, arm: Any, ack: Any, claim: Any = None, every: int = 1) -> bool:
    """Tick k: an arm command every 24 ticks (and the scripted claim, with ``claim``), then the
    ack counting them; with ``every`` > 1 only every ``every``-th tick is acknowledged, with
    the next such tick as ``next_tick``. True when tick k was acknowledged."""
    if every > 1 and k % every:
        return False
    sent = 0
    if k % 24 == 0:
        t = k / 240.0
        q = [h + 0.3 * math.sin(t + i) for i, h in enumerate(HOME)]
        arm.publish(JointTrajectory(joint_names=ARM, points=[JointTrajectoryPoint(positions=q)]))
        sent += 1
    if claim is not None and k in CLAIMS:
        claim.publish(_claim(*CLAIMS[k]))
        sent += 1
    ack.publish(StepAck(tick=k, n_commands=sent, next_tick=k + every if every > 1 else 0))
    return True


def _stuck(ticks: list[LockstepTick], pending: Counter[str]) -> dict[str, Any] | None:
    """The first tick still waiting for its messages, if any (for a failing test's message)."""
    if not ticks:
        return None
    t0 = ticks[0]
    return {
        "tick": int(t0.tick),
        "need": [t0.n_joint_states, t0.n_belt_states, t0.n_detections, t0.n_claims],
        "pending": dict(pending),
    }


def _board(msg: ClaimArray) -> dict[str, Any]:
    stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
    claims = [[c.station, int(c.track_id), c.state] for c in msg.claims]
    return {"stamp_ns": stamp_ns, "claims": claims}


def lockstep(  # noqa: PLR0915 (one scripted loop)
    out: str, die_after: int | None, namespace: str = "", claims: bool = False, every: int = 1
) -> int:
    from interfaces.contract import ARM_TRAJECTORY, CLAIM, CLAIMS, JOINT_STATES, LOCKSTEP_ACK

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
    boards: list[dict[str, Any]] = []

    def on_claims(msg: ClaimArray) -> None:
        pending.update(["claims"])
        boards.append(_board(msg))

    node.create_subscription(ClaimArray, CLAIMS.name, on_claims, RELIABLE)
    node.create_subscription(LockstepTick, "/lockstep/tick", ticks.append, RELIABLE)
    arm = node.create_publisher(JointTrajectory, ARM_TRAJECTORY.resolve(namespace), RELIABLE)
    claim = node.create_publisher(Claim, CLAIM.resolve(namespace), RELIABLE) if claims else None
    counted: list[list[int]] = []  # [tick, n_claims, last_claims_ns] of ticks counting a board
    ack = node.create_publisher(StepAck, LOCKSTEP_ACK.resolve(namespace), RELIABLE)
    handled = 0
    acked: list[int] = []
    deadline = time.monotonic() + 60.0
    outputs = [p for p in (arm, ack, claim) if p is not None]
    while any(p.get_subscription_count() == 0 for p in outputs):
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
                "claims": tick.n_claims,
            }
            if any(pending[k] < n for k, n in need.items()):
                break
            ticks.pop(0)
            for k, n in need.items():
                pending[k] -= n
            if tick.n_claims:
                counted.append([int(tick.tick), int(tick.n_claims), int(tick.last_claims_ns)])
            if _answer(int(tick.tick), arm, ack, claim, every):
                acked.append(int(tick.tick))
            handled += 1
            idle_since = time.monotonic()
            if die_after is not None and handled >= die_after:
                with open(out, "w", encoding="utf-8") as handle:
                    json.dump({"handled": handled, "died": True}, handle)
                os._exit(3)
    with open(out, "w", encoding="utf-8") as handle:
        json.dump(
            {
                "handled": handled,
                "died": False,
                "stuck": _stuck(ticks, pending),
                "boards": boards,
                "counted": counted,
                "acked": acked,
            },
            handle,
        )
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
        parser.add_argument("--claims", action="store_true")
        parser.add_argument("--every", type=int, default=1)
        args = parser.parse_args()
        sys.exit(lockstep(args.out, args.die_after, args.namespace, args.claims, args.every))
    sys.exit(listen(sys.argv[2], float(sys.argv[3])))
