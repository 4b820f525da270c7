"""The controller node against a tiny fake cell in another process (real rclpy, real DDS).

The fake cell is an ideal arm: every joint command becomes the measured joint state of the next
step. It publishes joint states, belt state and detections (with NaN and unknown-class
detections and one out-of-order frame mixed in) and runs the lockstep handshake.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("cdw_interfaces")

from control.config import ControllerConfig
from control.ik import Kinematics
from interfaces.cell import load_cell
from twin.ros_isolation import ros_domain

N_TICKS = 720
SPEED_MPS = 0.3
X0_M = -0.6
OBJECT_Y_M = 0.5
HEIGHT_M = 0.04

FAKE_CELL = r"""
import json, math, sys, time
import rclpy
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from builtin_interfaces.msg import Time
from cdw_interfaces.msg import (BeltState, Detection, DetectionArray, LockstepTick, PickTarget,
                                SortingPriorities, StepAck)
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64
from trajectory_msgs.msg import JointTrajectory

out, n_ticks, speed, x0, y0, height = sys.argv[1], int(sys.argv[2]), *map(float, sys.argv[3:7])
ns = sys.argv[7] if len(sys.argv) > 7 else ""

def st(name):  # a station topic under the station's namespace
    return f"/{ns}{name}" if ns else name
arm = [f"panda_joint{i}" for i in range(1, 8)]
q = [math.pi / 2, -0.3, 0.0, -2.2, 0.0, 1.9, math.pi / 4]
dt = 1.0 / 240.0

def qos(depth, latched=False):
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                      else DurabilityPolicy.VOLATILE)

def stamp(t):
    sec = int(t)
    return Time(sec=sec, nanosec=round((t - sec) * 1e9) % 1_000_000_000)

def seconds(s):
    return s.sec + 1e-9 * s.nanosec

rclpy.init()
node = Node("fake_cell")
rec = {"traj": [], "gripper": [], "target": [], "acks": [], "timeouts": 0}
state = {"ack": -1, "n_cmd": 0, "received": 0}

def on_traj(msg):
    state["received"] += 1
    p = msg.points[0]
    rec["traj"].append({"t": seconds(msg.header.stamp), "names": list(msg.joint_names),
                        "q": list(p.positions), "dq": list(p.velocities)})
    q[:] = [p.positions[list(msg.joint_names).index(n)] for n in arm]

def on_gripper(msg):
    state["received"] += 1
    rec["gripper"].append(msg.data)

def on_target(msg):
    state["received"] += 1
    g = msg.grasp_point
    rec["target"].append({"t": seconds(msg.header.stamp), "id": msg.track_id,
                          "cls": msg.class_name, "phase": msg.phase, "p": [g.x, g.y, g.z]})

def on_ack(msg):
    state["ack"] = max(state["ack"], msg.tick)
    state["n_cmd"] += msg.n_commands
    rec["acks"].append([msg.tick, msg.n_commands])

node.create_subscription(JointTrajectory, st("/arm_controller/joint_trajectory"), on_traj, qos(10))
node.create_subscription(Float64, st("/gripper/command"), on_gripper, qos(10))
node.create_subscription(PickTarget, st("/controller/target"), on_target, qos(10))
ack_sub = node.create_subscription(StepAck, st("/lockstep/ack"), on_ack, qos(100))
pubs = {
    "/joint_states": node.create_publisher(JointState, st("/joint_states"), qos(10)),
    "/conveyor/state": node.create_publisher(BeltState, "/conveyor/state", qos(10)),
    "/objects/detections": node.create_publisher(DetectionArray, "/objects/detections", qos(10)),
    "/lockstep/tick": node.create_publisher(LockstepTick, "/lockstep/tick", qos(100)),
}
clock = node.create_publisher(Clock, "/clock", qos(1))
prio = node.create_publisher(SortingPriorities, "/sorting/priorities", qos(1, latched=True))
prio.publish(SortingPriorities(classes=["brick", "wood", "concrete", "rubber", "gypsum"]))
count = dict.fromkeys(pubs, 0)
last_ns = dict.fromkeys(pubs, -1)  # newest stamp published per topic, as the twin tells it

def sent(topic, msg):
    pubs[topic].publish(msg)
    count[topic] += 1
    s = msg.header.stamp
    last_ns[topic] = max(last_ns[topic], s.sec * 1_000_000_000 + s.nanosec)
executor = EventsExecutor()
executor.add_node(node)

def det(cls, x, y):
    d = Detection(class_name=cls, confidence=0.9, yaw_rad=0.3, length_m=0.12, width_m=0.05,
                  height_m=height)
    d.position.x, d.position.y = x, y
    return d

def publish(k):
    t = k * dt
    before = dict(count)
    clock.publish(Clock(clock=stamp(t)))
    js = JointState(name=arm + ["panda_finger_joint1", "panda_finger_joint2"],
                    position=list(q) + [0.04, 0.04], velocity=[0.0] * 9)
    js.header.stamp = stamp(t)
    sent("/joint_states", js)
    if k % 4 == 0:
        belt = BeltState(setpoint_mps=speed, speed_mps=speed, position_m=speed * t)
        belt.header.stamp = stamp(t)
        sent("/conveyor/state", belt)
    if k > 0 and k % 8 == 0:
        capture = t - 0.03 if k != 240 else 0.05  # the frame at k = 240 is out of order
        frame = DetectionArray()
        frame.header.stamp = stamp(capture)
        frame.detections = [det("brick", x0 + speed * capture, y0),
                            det("brick", float("nan"), 0.4),
                            det("gypsum", x0 + speed * capture - 0.2, 0.6)]
        sent("/objects/detections", frame)
    per_tick = {topic: count[topic] - before[topic] for topic in count}
    pubs["/lockstep/tick"].publish(LockstepTick(
        tick=k, stamp=stamp(t), n_joint_states=per_tick["/joint_states"],
        n_belt_states=per_tick["/conveyor/state"], n_detections=per_tick["/objects/detections"],
        last_joint_state_ns=last_ns["/joint_states"], last_belt_state_ns=last_ns["/conveyor/state"],
        last_detections_ns=last_ns["/objects/detections"]))

deadline = time.monotonic() + 30.0
# like the twin: wait until both sides have matched (the controller's ack publisher appears once
# its readers have matched), then publish tick 0 once and wait for it
def matched():
    writers = all(p.get_subscription_count() > 0 for p in pubs.values())
    return writers and ack_sub.get_publisher_count() > 0

while not matched() and time.monotonic() < deadline:
    executor.spin_once(timeout_sec=0.05)
publish(0)
while state["ack"] < 0 and time.monotonic() < deadline:
    executor.spin_once(timeout_sec=0.05)
for k in range(1, n_ticks):
    publish(k)
    end = time.monotonic() + 5.0
    while not (state["ack"] >= k and state["received"] >= state["n_cmd"]):
        if time.monotonic() > end:
            rec["timeouts"] += 1
            print(f"tick {k}: ack {state['ack']}, commands {state['received']} of"
                  f" {state['n_cmd']}", file=sys.stderr, flush=True)
            break
        executor.spin_once(timeout_sec=0.05)
    if rec["timeouts"] >= 3:
        break
rec["published"] = count
rec["received_commands"] = state["received"]
with open(out, "w") as f:
    json.dump(rec, f)
node.destroy_node()
rclpy.shutdown()
"""


def _against_controller(
    controller_args: list[str], peer_args: list[str], *, timeout_s: float
) -> subprocess.CompletedProcess[str]:
    """Run the Python script ``peer_args`` against a lockstep controller on a domain of their own.

    Asserts that both exit cleanly (the controller on SIGINT once the peer is done).
    """
    with ros_domain() as domain:
        controller = subprocess.Popen(
            [sys.executable, "-m", "control", "--lockstep", *controller_args],
            env=domain.env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        try:
            peer = subprocess.run(
                [sys.executable, *peer_args],
                env=domain.env,
                capture_output=True,
                text=True,
                timeout=timeout_s,
                check=False,
            )
            assert peer.returncode == 0, peer.stderr
        finally:
            controller.send_signal(signal.SIGINT)
            log, _ = controller.communicate(timeout=20)
    assert controller.returncode == 0, log
    return peer


def _commands_are_safe(record: dict[str, Any], config: ControllerConfig, kin: Kinematics) -> None:
    """Every joint command names the arm joints, is inside the limits and no faster than the
    velocity limits; every gripper command is inside the opening range."""
    assert record["traj"]
    for point in record["traj"]:
        assert point["names"] == list(config.robot.arm_joints)
        assert kin.within_limits(np.array(point["q"]))
        assert np.all(np.abs(point["dq"]) <= kin.velocity_limit_rps + 1e-9)
    assert record["gripper"]
    assert all(0.0 <= w <= config.station.tool.max_opening_m for w in record["gripper"])


def test_lockstep_node_against_fake_cell(tmp_path: Path) -> None:
    """Acks every tick with exact counts, commands stay in limits, bad detections are counted."""
    cell_py = tmp_path / "fake_cell.py"
    cell_py.write_text(FAKE_CELL, encoding="utf-8")
    record_path = tmp_path / "cell.json"
    stats_path = tmp_path / "stats.json"
    cell = _against_controller(
        ["--stats-out", str(stats_path)],
        [
            str(cell_py),
            str(record_path),
            *map(str, (N_TICKS, SPEED_MPS, X0_M, OBJECT_Y_M, HEIGHT_M)),
        ],
        timeout_s=60,
    )
    record = json.loads(record_path.read_text(encoding="utf-8"))
    stats = json.loads(stats_path.read_text(encoding="utf-8"))

    assert record["timeouts"] == 0, cell.stderr
    assert {tick for tick, _ in record["acks"]} >= set(range(N_TICKS))
    per_tick = [n for _, n in record["acks"]]
    assert sum(per_tick) == record["received_commands"] == stats["n_commands"]
    assert stats["ticks_acked"] == len(record["acks"])

    config = ControllerConfig()
    kin = Kinematics.of_station(config.station, config.ik)
    _commands_are_safe(record, config, kin)

    frames = record["published"]["/objects/detections"]
    assert stats["received"]["/objects/detections"] == frames
    rejected = stats["rejected_detections"]
    assert rejected["non_finite"] == frames
    assert rejected["unknown_class"] == frames
    assert rejected["out_of_order"] == 1
    assert stats["skipped"]["unknown_priority_class"] == 1

    phases = [t["phase"] for t in record["target"]]
    assert "approach" in phases
    assert all(t["cls"] == "brick" for t in record["target"] if t["phase"] == "approach")
    closes = [t for t in record["target"] if t["phase"] == "close"]
    assert closes, phases
    close = closes[0]
    grasp_z = HEIGHT_M - config.pick.grasp_below_top_m
    truth = (X0_M + SPEED_MPS * close["t"], OBJECT_Y_M, grasp_z)
    assert math.dist(close["p"], truth) < 0.01
    command = next(p for p in record["traj"] if abs(p["t"] - close["t"]) < 1e-6)
    tcp = kin.fk(np.array(command["q"])).translation
    ahead = (truth[0] + SPEED_MPS * config.motion.command_latency_s, truth[1], truth[2])
    assert math.dist(tuple(float(v) for v in tcp), ahead) < 0.004


PROBE_CELL = r"""
import json, sys, time
import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from cdw_interfaces.msg import BeltState, DetectionArray, LockstepTick
from sensor_msgs.msg import JointState

qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.VOLATILE)
rclpy.init()
node = Node("probe_cell")
rec = {}

def spin_until(done, timeout_s):
    end = time.monotonic() + timeout_s
    while not done() and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.02)
    return done()

rec["controller_seen"] = spin_until(lambda: node.count_subscribers("/lockstep/tick") > 0, 30.0)
node.create_publisher(JointState, "/joint_states", qos)
node.create_publisher(BeltState, "/conveyor/state", qos)
node.create_publisher(DetectionArray, "/objects/detections", qos)
spin_until(lambda: False, 1.5)
rec["ack_publishers_without_tick"] = node.count_publishers("/lockstep/ack")
tick = node.create_publisher(LockstepTick, "/lockstep/tick", qos)
rec["ack_publisher_appeared"] = spin_until(lambda: node.count_publishers("/lockstep/ack") > 0, 20.0)
rec["tick_matched"] = spin_until(lambda: tick.get_subscription_count() == 1, 10.0)
print(json.dumps(rec), flush=True)
node.destroy_node()
rclpy.shutdown()
"""


def test_ack_publisher_waits_for_the_readers_to_match(tmp_path: Path) -> None:
    """The controller announces itself (its /lockstep/ack publisher) only once its readers of
    the tick and of every counted topic have matched a writer: the twin's tick 0 cannot reach a
    reader that does not yet know its writer, where a volatile message may be lost."""
    probe_py = tmp_path / "probe_cell.py"
    probe_py.write_text(PROBE_CELL, encoding="utf-8")
    probe = _against_controller([], [str(probe_py)], timeout_s=90)
    record = json.loads(probe.stdout.strip().splitlines()[-1])
    assert record == {
        "controller_seen": True,
        "ack_publishers_without_tick": 0,
        "ack_publisher_appeared": True,
        "tick_matched": True,
    }


def test_a_controller_on_a_namespaced_station_speaks_under_its_namespace(tmp_path: Path) -> None:
    """The upstream station of the two-Panda cell (namespace ``s1``, base at x = -1.5): its
    joint states, commands and acks are ``/s1/...``, the belt, detections and the lockstep tick
    the cell's; it acks every tick and goes for an object in its own window, in world
    coordinates (the bare-name topics of a one-station cell carry nothing here)."""
    cell_py = tmp_path / "fake_cell.py"
    cell_py.write_text(FAKE_CELL, encoding="utf-8")
    record_path = tmp_path / "cell.json"
    stats_path = tmp_path / "stats.json"
    n_ticks, x0 = 360, -2.1
    cell = _against_controller(
        ["--cell", "two_pandas", "--station", "upstream", "--stats-out", str(stats_path)],
        [
            str(cell_py),
            str(record_path),
            *map(str, (n_ticks, SPEED_MPS, x0, OBJECT_Y_M, HEIGHT_M, "s1")),
        ],
        timeout_s=60,
    )
    record = json.loads(record_path.read_text(encoding="utf-8"))
    stats = json.loads(stats_path.read_text(encoding="utf-8"))
    assert record["timeouts"] == 0, cell.stderr
    assert {tick for tick, _ in record["acks"]} >= set(range(n_ticks))
    assert sum(n for _, n in record["acks"]) == record["received_commands"] == stats["n_commands"]
    assert stats["station"] == "upstream"
    assert set(stats["published"]) == {
        "/s1/arm_controller/joint_trajectory",
        "/s1/gripper/command",
        "/s1/controller/target",
    }
    assert stats["received"]["/s1/joint_states"] == n_ticks

    config = ControllerConfig(cell=load_cell("two_pandas"), station_name="upstream")
    _commands_are_safe(record, config, Kinematics.of_station(config.station, config.ik))
    approach = [t for t in record["target"] if t["phase"] == "approach"]
    assert approach, [t["phase"] for t in record["target"]]
    x_min, x_max = config.pick_window_x_m
    for target in approach:
        x, y, _ = target["p"]  # the object's grasp point, where it is (world frame)
        assert abs(x - (x0 + SPEED_MPS * target["t"])) < 0.01
        assert abs(y - OBJECT_Y_M) < 0.01
    last = record["traj"][-1]
    tcp = Kinematics.of_station(config.station, config.ik).fk(np.array(last["q"])).translation
    assert x_min - 0.05 <= float(tcp[0]) <= x_max  # the arm works in its own window


def test_joint_sample_reads_the_gripper_opening_from_the_finger_joints() -> None:
    """Each finger joint reports half the opening; a missing or NaN finger leaves it unmeasured
    (NaN), and the arm joints are read in the configured order whatever the message's order."""
    from sensor_msgs.msg import JointState

    from control.node import joint_sample

    tool = ControllerConfig().tool
    arm = [f"panda_joint{i}" for i in range(1, 8)]
    fingers = ["panda_finger_joint1", "panda_finger_joint2"]
    msg = JointState()
    msg.name = fingers[::-1] + arm[::-1]
    msg.position = [0.021, 0.019] + [0.1 * i for i in range(7, 0, -1)]
    sample = joint_sample(msg, arm, tool)
    assert sample is not None
    assert sample.positions_rad.tolist() == pytest.approx([0.1 * i for i in range(1, 8)])
    assert sample.tool_measured_m == pytest.approx(0.04)
    no_tool = joint_sample(msg, arm)
    assert no_tool is not None
    assert math.isnan(no_tool.tool_measured_m)
    msg.position = [math.nan, 0.019] + [0.1 * i for i in range(7, 0, -1)]
    nan_finger = joint_sample(msg, arm, tool)
    assert nan_finger is not None
    assert math.isnan(nan_finger.tool_measured_m)
    msg.name, msg.position = arm, [0.1 * i for i in range(1, 8)]
    missing = joint_sample(msg, arm, tool)
    assert missing is not None
    assert math.isnan(missing.tool_measured_m)
