"""A hostile ROS 2 client of the twin node, run as its own process by ``test_hostile_clients.py``.

python hostile_client.py OUT.json

Waits for the twin node (cell ``two_pandas``) to subscribe to station ``s1``'s claims and arm
commands and to ``/sorting/priorities``, then sends on them, in this order:

- :data:`BAD_CLAIMS`: one claim per wrong field (NaN and infinite positions and velocities, a
  negative and a 1e300 radius, a forged station, a stamp far past the episode, ...);
- :data:`VALID_TRACKS` well-formed claims of distinct tracks (more than the board takes of one
  station);
- three oversized messages: a 10 000-point trajectory, a 100 000-entry priority list, a claim
  with a 100 kB class name;
- :data:`FLOOD` more bad claims as fast as it can.

Meanwhile it records every board relayed on ``/line/claims``, for :data:`LISTEN_S` after the
last message. OUT.json: ``{"boards": [[[station, track, state, x, vx, radius], ...], ...]}``.
"""

# rclpy's annotations are partial.
# mypy: disable-error-code="no-untyped-call"

from __future__ import annotations

import json
import math
import sys
import time
from typing import Any

import rclpy
from cdw_interfaces.msg import Claim, ClaimArray, SortingPriorities
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

RELIABLE = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE
)
ARM = [f"panda_joint{i}" for i in range(1, 8)]
VALID_TRACKS = 50
"""Well-formed claims of distinct tracks (the board takes 32 of one station)."""
FLOOD = 1000
"""Bad claims sent as fast as possible at the end."""
LISTEN_S = 1.5


def claim(track_id: int, **fields: Any) -> Claim:
    """A well-formed claim of ``track_id`` on the two_pandas belt, with ``fields`` changed."""
    values: dict[str, Any] = {
        "station": "",
        "class_name": "brick",
        "state": "claimed",
        "x": -1.5,
        "y": 0.5,
        "vx": 0.4,
        "vy": 0.0,
        "radius_m": 0.05,
        "sec": 0,
        "frame_id": "world",
    }
    values.update(fields)
    msg = Claim(
        station=values["station"],
        track_id=track_id,
        class_name=values["class_name"],
        state=values["state"],
        radius_m=values["radius_m"],
    )
    msg.header.frame_id = values["frame_id"]
    msg.header.stamp.sec = values["sec"]
    msg.position.x, msg.position.y = values["x"], values["y"]
    msg.velocity.x, msg.velocity.y = values["vx"], values["vy"]
    return msg


BAD_CLAIMS: list[dict[str, Any]] = [
    {"x": math.nan},
    {"y": math.inf},
    {"vx": -math.inf},
    {"vy": math.nan},
    {"radius_m": -0.05},
    {"radius_m": 1e300},
    {"radius_m": math.nan},
    {"station": "downstream"},
    {"state": "grabbed"},
    {"x": 1e6},
    {"vx": 300.0},
    {"sec": 2_000_000_000},
    {"frame_id": "map"},
    {"class_name": "x" * 500},
]
"""One claim per wrong field (each refused as ``bad_claim``)."""


def main(out: str) -> int:
    """Send the hostile messages, record the relayed boards; 2 when the twin never matched."""
    rclpy.init()
    node = rclpy.create_node("hostile_client")
    executor = EventsExecutor()
    executor.add_node(node)
    boards: list[list[list[Any]]] = []

    def on_board(msg: ClaimArray) -> None:
        boards.append(
            [
                [c.station, int(c.track_id), c.state, c.position.x, c.velocity.x, c.radius_m]
                for c in msg.claims
            ]
        )

    from interfaces import contract as c
    from interfaces.ros import message_class, qos_profile

    node.create_subscription(ClaimArray, c.CLAIMS.name, on_board, RELIABLE)
    claims = node.create_publisher(Claim, c.CLAIM.resolve("s1"), qos_profile(c.CLAIM.qos))
    arm = node.create_publisher(
        JointTrajectory, c.ARM_TRAJECTORY.resolve("s1"), qos_profile(c.ARM_TRAJECTORY.qos)
    )
    priorities = node.create_publisher(
        SortingPriorities, c.PRIORITIES.name, qos_profile(c.PRIORITIES.qos)
    )

    def pause(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.002)

    ticks: list[int] = []
    node.create_subscription(
        message_class(c.CLOCK_TOPIC),
        c.CLOCK_TOPIC.name,
        lambda _msg: ticks.append(1),
        qos_profile(c.CLOCK_TOPIC.qos),
    )
    deadline = time.monotonic() + 60.0
    # matched, and the twin stepping (its executor taking messages as they come)
    while len(ticks) < 20 or any(
        p.get_subscription_count() == 0 for p in (claims, arm, priorities)
    ):
        executor.spin_once(timeout_sec=0.05)
        if time.monotonic() > deadline:
            return 2
    # paced (the twin keeps the last 10 claims it has not taken yet, as the contract's QoS
    # says), so every one of these arrives
    for i, fields in enumerate(BAD_CLAIMS):
        claims.publish(claim(1000 + i, **fields))
        pause(0.01)
    for track in range(VALID_TRACKS):
        claims.publish(claim(track, x=-1.8 + 0.01 * track))
        pause(0.01)
    point = JointTrajectoryPoint(positions=[0.0] * 7)
    arm.publish(JointTrajectory(joint_names=ARM, points=[point] * 10_000))
    pause(0.05)
    priorities.publish(SortingPriorities(classes=["concrete"] * 100_000))
    pause(0.05)
    claims.publish(claim(2000, class_name="c" * 100_000))
    pause(0.05)
    for i in range(FLOOD):  # as fast as it can: some may be dropped by the twin's reader
        claims.publish(claim(3000 + i, radius_m=-1.0))
    end = time.monotonic() + LISTEN_S
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    with open(out, "w", encoding="utf-8") as handle:
        json.dump({"boards": boards}, handle)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
