"""A tiny cell for the controller node's tests, run as its own process (real rclpy, real DDS).

python fake_cell.py OUT.json N_TICKS SPEED X0 Y0 HEIGHT [NAMESPACES] [OBJECTS]

Ideal arms, one per station namespace (NAMESPACES: comma-separated, "" the empty one): every joint
command becomes the measured joint state of the next step; the fingers report open. It publishes
each station's joint states, the belt state and detections (a brick at X0 + SPEED t, Y0, gone from
the belt once a station reports it picked, and, with OBJECTS = "bad", a NaN and an unknown-class
detection and one out-of-order frame mixed in; OBJECTS = "two": a second brick 0.3 m upstream),
relays the stations' claims like the twin (the board of every station's current claims on
/line/claims in every tick in which it changed, released and picked entries once) and runs the
lockstep handshake with every station's controller. It records what the controllers sent as JSON in
OUT.json.
"""

from __future__ import annotations

import json
import math
import sys
import time
from typing import Any

import rclpy
from builtin_interfaces.msg import Time
from cdw_interfaces.msg import (
    BeltState,
    Claim,
    ClaimArray,
    Detection,
    DetectionArray,
    LockstepTick,
    PickTarget,
    SortingPriorities,
    StepAck,
)
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64
from trajectory_msgs.msg import JointTrajectory

ARM = [f"panda_joint{i}" for i in range(1, 8)]
READY = [math.pi / 2, -0.3, 0.0, -2.2, 0.0, 1.9, math.pi / 4]
DT_S = 1.0 / 240.0


def qos(depth: int, latched: bool = False) -> QoSProfile:
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def stamp(t_s: float) -> Time:
    sec = int(t_s)
    return Time(sec=sec, nanosec=round((t_s - sec) * 1e9) % 1_000_000_000)


def seconds(s: Any) -> float:
    return float(s.sec + 1e-9 * s.nanosec)


def ns_of(s: Any) -> int:
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


class Station:
    """One station's ideal arm, its command subscriptions and its ack bookkeeping."""

    def __init__(self, node: Node, ns: str) -> None:
        self.ns = ns
        self.q = list(READY)
        self.ack = -1
        self.n_cmd = 0
        self.received = 0
        self.rec: dict[str, list[Any]] = {"traj": [], "gripper": [], "target": [], "acks": []}
        self.rec["claims"] = []
        self.claims: list[Any] = []

        def topic(name: str) -> str:
            return f"/{ns}/{name}" if ns else f"/{name}"

        node.create_subscription(
            JointTrajectory, topic("arm_controller/joint_trajectory"), self.on_traj, qos(10)
        )
        node.create_subscription(Float64, topic("gripper/command"), self.on_gripper, qos(10))
        node.create_subscription(PickTarget, topic("controller/target"), self.on_target, qos(10))
        node.create_subscription(Claim, topic("line/claim"), self.on_claim, qos(10))
        self.ack_sub = node.create_subscription(
            StepAck, topic("lockstep/ack"), self.on_ack, qos(100)
        )
        self.joints = node.create_publisher(JointState, topic("joint_states"), qos(10))

    def on_traj(self, msg: Any) -> None:
        self.received += 1
        p = msg.points[0]
        names = list(msg.joint_names)
        self.rec["traj"].append(
            {
                "t": seconds(msg.header.stamp),
                "names": names,
                "q": list(p.positions),
                "dq": list(p.velocities),
            }
        )
        self.q[:] = [p.positions[names.index(n)] for n in ARM]

    def on_gripper(self, msg: Any) -> None:
        self.received += 1
        self.rec["gripper"].append(msg.data)

    def on_target(self, msg: Any) -> None:
        self.received += 1
        g = msg.grasp_point
        self.rec["target"].append(
            {
                "t": seconds(msg.header.stamp),
                "id": msg.track_id,
                "cls": msg.class_name,
                "phase": msg.phase,
                "p": [g.x, g.y, g.z],
            }
        )

    def on_claim(self, msg: Any) -> None:
        self.received += 1
        self.claims.append(msg)
        self.rec["claims"].append(
            {
                "t": seconds(msg.header.stamp),
                "station": msg.station,
                "id": msg.track_id,
                "state": msg.state,
                "p": [msg.position.x, msg.position.y],
                "r": msg.radius_m,
            }
        )

    def on_ack(self, msg: Any) -> None:
        self.ack = max(self.ack, msg.tick)
        self.n_cmd += msg.n_commands
        self.rec["acks"].append([msg.tick, msg.n_commands])

    def done(self, k: int) -> bool:
        return self.ack >= k and self.received >= self.n_cmd


class Board:
    """The claims board as the twin keeps it: one entry per station and track."""

    def __init__(self) -> None:
        self.entries: dict[tuple[str, int], Any] = {}
        self.relayed: list[dict[str, Any]] = []
        self.picked = False  # a station reported a pick: the first brick left the belt

    def publish(self, stations: list[Station], pub: Any, t_s: float) -> bool:
        """Take the claims that arrived; publish the board if it changed."""
        arrived = [c for s in stations for c in s.claims]
        for s in stations:
            s.claims.clear()
        if not arrived:
            return False
        for claim in arrived:
            self.entries[(claim.station, claim.track_id)] = claim
            self.picked = self.picked or claim.state == "picked"
        board = ClaimArray(claims=[self.entries[k] for k in sorted(self.entries)])
        board.header.stamp = stamp(t_s)
        board.header.frame_id = "world"
        pub.publish(board)
        self.relayed.append(
            {"t": t_s, "claims": [[c.station, c.track_id, c.state] for c in board.claims]}
        )
        for key in [k for k, c in self.entries.items() if c.state != "claimed"]:
            del self.entries[key]
        return True


class FakeCell:
    """The cell's side: clock, belt, detections, the claims board and the lockstep tick."""

    def __init__(self, node: Node, args: list[str]) -> None:
        self.n_ticks = int(args[0])
        self.speed, self.x0, self.y0, self.height = map(float, args[1:5])
        namespaces = args[5].split(",") if len(args) > 5 else [""]
        self.objects = args[6] if len(args) > 6 else "bad"
        self.stations = [Station(node, ns) for ns in namespaces]
        self.pubs = {
            "/conveyor/state": node.create_publisher(BeltState, "/conveyor/state", qos(10)),
            "/objects/detections": node.create_publisher(
                DetectionArray, "/objects/detections", qos(10)
            ),
            "/line/claims": node.create_publisher(ClaimArray, "/line/claims", qos(10)),
        }
        self.tick_pub = node.create_publisher(LockstepTick, "/lockstep/tick", qos(100))
        self.clock = node.create_publisher(Clock, "/clock", qos(1))
        self.prio = node.create_publisher(
            SortingPriorities, "/sorting/priorities", qos(1, latched=True)
        )
        self.prio.publish(
            SortingPriorities(classes=["brick", "wood", "concrete", "rubber", "gypsum"])
        )
        topics = ["/joint_states", *self.pubs]
        self.count = dict.fromkeys(topics, 0)
        self.last_ns = dict.fromkeys(topics, -1)
        self.board = Board()

    def sent(self, topic: str, s: Any) -> None:
        self.count[topic] += 1
        self.last_ns[topic] = max(self.last_ns[topic], ns_of(s))

    def det(self, cls: str, x: float, y: float) -> Any:
        d = Detection(
            class_name=cls,
            confidence=0.9,
            yaw_rad=0.3,
            length_m=0.12,
            width_m=0.05,
            height_m=self.height,
        )
        d.position.x, d.position.y = x, y
        return d

    def frame_of(self, k: int, t: float) -> DetectionArray | None:
        if k == 0 or k % 8:
            return None
        bad = self.objects == "bad"
        capture = 0.05 if (k == 240 and bad) else t - 0.03  # with "bad": one out of order
        frame = DetectionArray()
        frame.header.stamp = stamp(capture)
        x = self.x0 + self.speed * capture
        found = [] if self.board.picked else [self.det("brick", x, self.y0)]
        if bad:
            found += [self.det("brick", float("nan"), 0.4), self.det("gypsum", x - 0.2, 0.6)]
        elif self.objects == "two":
            found.append(self.det("brick", x - 0.3, self.y0))
        frame.detections = found
        return frame

    def publish(self, k: int) -> None:
        t = k * DT_S
        before = dict(self.count)
        self.clock.publish(Clock(clock=stamp(t)))
        for st in self.stations:
            js = JointState(
                name=[*ARM, "panda_finger_joint1", "panda_finger_joint2"],
                position=[*st.q, 0.04, 0.04],
                velocity=[0.0] * 9,
            )
            js.header.stamp = stamp(t)
            st.joints.publish(js)
        self.sent("/joint_states", stamp(t))  # one per station, all with one stamp
        if k % 4 == 0:
            belt = BeltState(
                setpoint_mps=self.speed, speed_mps=self.speed, position_m=self.speed * t
            )
            belt.header.stamp = stamp(t)
            self.pubs["/conveyor/state"].publish(belt)
            self.sent("/conveyor/state", belt.header.stamp)
        frame = self.frame_of(k, t)
        if frame is not None:
            self.pubs["/objects/detections"].publish(frame)
            self.sent("/objects/detections", frame.header.stamp)
        if self.board.publish(self.stations, self.pubs["/line/claims"], t):
            self.sent("/line/claims", stamp(t))
        n = {topic: self.count[topic] - before[topic] for topic in self.count}
        last = self.last_ns
        self.tick_pub.publish(
            LockstepTick(
                tick=k,
                stamp=stamp(t),
                n_joint_states=n["/joint_states"],
                n_belt_states=n["/conveyor/state"],
                n_detections=n["/objects/detections"],
                n_claims=n["/line/claims"],
                last_joint_state_ns=last["/joint_states"],
                last_belt_state_ns=last["/conveyor/state"],
                last_detections_ns=last["/objects/detections"],
                last_claims_ns=last["/line/claims"],
            )
        )

    def matched(self) -> bool:
        """Like the twin: every writer has its readers, every controller its ack publisher."""
        n = len(self.stations)
        writers = all(p.get_subscription_count() >= n for p in self.pubs.values())
        joints = all(st.joints.get_subscription_count() > 0 for st in self.stations)
        return (
            writers and joints and all(st.ack_sub.get_publisher_count() > 0 for st in self.stations)
        )

    def run(self, executor: EventsExecutor) -> int:
        """Step every tick once every station acked the previous; the number of timeouts."""
        deadline = time.monotonic() + 30.0
        while not self.matched() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        timeouts = 0
        for k in range(self.n_ticks):
            self.publish(k)
            end = time.monotonic() + (30.0 if k == 0 else 5.0)
            while not all(st.done(k) for st in self.stations):
                if time.monotonic() > end:
                    timeouts += 1
                    acks = [st.ack for st in self.stations]
                    print(f"tick {k}: acks {acks}", file=sys.stderr, flush=True)
                    break
                executor.spin_once(timeout_sec=0.05)
            if timeouts >= 3:
                break
        return timeouts


def main() -> None:
    rclpy.init()
    node = Node("fake_cell")
    cell = FakeCell(node, sys.argv[2:])
    executor = EventsExecutor()
    executor.add_node(node)
    timeouts = cell.run(executor)
    record = {
        "stations": {st.ns: {**st.rec, "received_commands": st.received} for st in cell.stations},
        "published": cell.count,
        "board": cell.board.relayed,
        "timeouts": timeouts,
    }
    with open(sys.argv[1], "w", encoding="utf-8") as f:
        json.dump(record, f)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
