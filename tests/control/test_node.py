"""The controller node against a tiny fake cell in another process (real rclpy, real DDS).

The fake cell (``fake_cell.py``) is an ideal arm per station: every joint command becomes the
measured joint state of the next step. It publishes joint states, belt state and detections
(with NaN and unknown-class detections and one out-of-order frame mixed in), relays the
stations' claims as the twin does, and runs the lockstep handshake.
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

FAKE_CELL = Path(__file__).resolve().parent / "fake_cell.py"


def _against_controllers(
    controllers: list[list[str]], peer_args: list[str], *, timeout_s: float
) -> subprocess.CompletedProcess[str]:
    """Run the Python script ``peer_args`` against lockstep controllers (one per argument list)
    on a domain of their own.

    Asserts that all exit cleanly (the controllers on SIGINT once the peer is done).
    """
    with ros_domain() as domain:
        procs = [
            subprocess.Popen(
                [sys.executable, "-m", "control", "--lockstep", *args],
                env=domain.env,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
            )
            for args in controllers
        ]
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
            for proc in procs:
                proc.send_signal(signal.SIGINT)
            logs = [proc.communicate(timeout=20)[0] for proc in procs]
    for proc, log in zip(procs, logs, strict=True):
        assert proc.returncode == 0, log
    return peer


def _against_controller(
    controller_args: list[str], peer_args: list[str], *, timeout_s: float
) -> subprocess.CompletedProcess[str]:
    """:func:`_against_controllers` with one controller."""
    return _against_controllers([controller_args], peer_args, timeout_s=timeout_s)


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
    """Acks every tick with exact counts (its claims among the commands), commands stay in
    limits, bad detections are counted; it claims its target, and says when it holds it."""
    record_path = tmp_path / "cell.json"
    stats_path = tmp_path / "stats.json"
    cell = _against_controller(
        ["--stats-out", str(stats_path)],
        [
            str(FAKE_CELL),
            str(record_path),
            *map(str, (N_TICKS, SPEED_MPS, X0_M, OBJECT_Y_M, HEIGHT_M)),
        ],
        timeout_s=60,
    )
    whole = json.loads(record_path.read_text(encoding="utf-8"))
    record = whole["stations"][""]
    stats = json.loads(stats_path.read_text(encoding="utf-8"))

    assert whole["timeouts"] == 0, cell.stderr
    assert {tick for tick, _ in record["acks"]} >= set(range(N_TICKS))
    per_tick = [n for _, n in record["acks"]]
    assert sum(per_tick) == record["received_commands"] == stats["n_commands"]
    assert stats["ticks_acked"] == len(record["acks"])

    config = ControllerConfig()
    kin = Kinematics.of_station(config.station, config.ik)
    _commands_are_safe(record, config, kin)

    claims = record["claims"]
    assert [c["state"] for c in claims] == ["claimed", "picked"]
    assert stats["published"]["/line/claim"] == len(claims)
    assert all(c["station"] == "panda" for c in claims)
    for claim in claims:  # the brick, where it was at the claim's stamp
        assert math.dist(claim["p"], (X0_M + SPEED_MPS * claim["t"], OBJECT_Y_M)) < 0.01
    assert [entry["claims"][0][2] for entry in whole["board"]] == ["claimed", "picked"]
    assert stats["received"]["/line/claims"] == len(whole["board"])

    frames = whole["published"]["/objects/detections"]
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
from cdw_interfaces.msg import BeltState, ClaimArray, DetectionArray, LockstepTick
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
rec["ack_publishers_without_claims"] = node.count_publishers("/lockstep/ack")
node.create_publisher(ClaimArray, "/line/claims", qos)
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
        "ack_publishers_without_claims": 0,
        "ack_publishers_without_tick": 0,
        "ack_publisher_appeared": True,
        "tick_matched": True,
    }


def test_a_controller_on_a_namespaced_station_speaks_under_its_namespace(tmp_path: Path) -> None:
    """The upstream station of the two-Panda cell (namespace ``s1``, base at x = -1.5): its
    joint states, commands and acks are ``/s1/...``, the belt, detections and the lockstep tick
    the cell's; it acks every tick and goes for an object in its own window, in world
    coordinates (the bare-name topics of a one-station cell carry nothing here)."""
    record_path = tmp_path / "cell.json"
    stats_path = tmp_path / "stats.json"
    n_ticks, x0 = 360, -2.1
    cell = _against_controller(
        ["--cell", "two_pandas", "--station", "upstream", "--stats-out", str(stats_path)],
        [
            str(FAKE_CELL),
            str(record_path),
            *map(str, (n_ticks, SPEED_MPS, x0, OBJECT_Y_M, HEIGHT_M, "s1")),
        ],
        timeout_s=60,
    )
    whole = json.loads(record_path.read_text(encoding="utf-8"))
    record = whole["stations"]["s1"]
    stats = json.loads(stats_path.read_text(encoding="utf-8"))
    assert whole["timeouts"] == 0, cell.stderr
    assert {tick for tick, _ in record["acks"]} >= set(range(n_ticks))
    assert sum(n for _, n in record["acks"]) == record["received_commands"] == stats["n_commands"]
    assert stats["station"] == "upstream"
    assert set(stats["published"]) == {
        "/s1/arm_controller/joint_trajectory",
        "/s1/gripper/command",
        "/s1/controller/target",
        "/s1/line/claim",
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
    assert sample.tool_measured == pytest.approx(0.04)
    no_tool = joint_sample(msg, arm)
    assert no_tool is not None
    assert math.isnan(no_tool.tool_measured)
    msg.position = [math.nan, 0.019] + [0.1 * i for i in range(7, 0, -1)]
    nan_finger = joint_sample(msg, arm, tool)
    assert nan_finger is not None
    assert math.isnan(nan_finger.tool_measured)
    msg.name, msg.position = arm, [0.1 * i for i in range(1, 8)]
    missing = joint_sample(msg, arm, tool)
    assert missing is not None
    assert math.isnan(missing.tool_measured)


OVERLAP_CELL = """
name: overlap
stations:
  - name: a
    namespace: s1
    robot: panda
    tool: panda_hand
    base_position_m: [-0.6, 0.0, 0.0]
    pick_window_x_m: [-0.8, -0.1]
    bins: [{class_name: brick, centre_x_m: -0.9, centre_y_m: 0.07}]
  - name: b
    namespace: s2
    robot: panda
    tool: panda_hand
    base_position_m: [-0.1, 0.0, 0.0]
    pick_window_x_m: [-0.7, 0.25]
    bins: [{class_name: brick, centre_x_m: 0.23, centre_y_m: 0.07}]
"""


def test_two_controllers_share_a_brick_through_the_relayed_claims(tmp_path: Path) -> None:
    """Two stations whose windows overlap, each its own controller process, the claims relayed
    by a peer as the twin relays them: the upstream station claims the brick and picks it, the
    downstream one leaves it as ``claimed_by_other`` and never targets it; every claim is a
    command of its tick, counted in the ack."""
    cell_path = tmp_path / "overlap.yaml"
    cell_path.write_text(OVERLAP_CELL, encoding="utf-8")
    record_path = tmp_path / "cell.json"
    n_ticks, x0 = 840, -1.2  # the brick enters after the arms reached their ready poses
    stats = {name: tmp_path / f"{name}.json" for name in ("a", "b")}
    peer = _against_controllers(
        [
            ["--cell", str(cell_path), "--station", name, "--stats-out", str(path)]
            for name, path in stats.items()
        ],
        [
            str(FAKE_CELL),
            str(record_path),
            *map(str, (n_ticks, SPEED_MPS, x0, OBJECT_Y_M, HEIGHT_M, "s1,s2", "one")),
        ],
        timeout_s=90,
    )
    whole = json.loads(record_path.read_text(encoding="utf-8"))
    assert whole["timeouts"] == 0, peer.stderr
    a, b = (json.loads(path.read_text(encoding="utf-8")) for path in stats.values())
    for ns, summary in (("s1", a), ("s2", b)):
        record = whole["stations"][ns]
        assert sum(n for _, n in record["acks"]) == record["received_commands"]
        assert record["received_commands"] == summary["n_commands"]
        assert summary["received"]["/line/claims"] == len(whole["board"])
    assert [c["state"] for c in whole["stations"]["s1"]["claims"]] == ["claimed", "picked"]
    assert whole["stations"]["s2"]["claims"] == []
    assert a["pick"]["targeted"] == 1
    assert b["pick"]["targeted"] == 0
    assert b["pick"]["untargeted"] == {"claimed_by_other": 1}
    assert [entry["claims"] for entry in whole["board"]] == [
        [["a", whole["stations"]["s1"]["claims"][0]["id"], state]]
        for state in ("claimed", "picked")
    ]


def test_a_detection_without_a_suction_point_reaches_the_tracker_without_one() -> None:
    """A camera that fills no suction point leaves the message's zeros: the tracker gets NaN
    (no point), not a point at the origin with no room; a filled one arrives as it was sent."""
    from cdw_interfaces.msg import Detection, DetectionArray

    from control.node import detections_of

    msg = DetectionArray()
    msg.header.stamp.sec = 3
    plain = Detection(class_name="wood", confidence=0.9, length_m=0.2, width_m=0.06, height_m=0.03)
    plain.position.x, plain.position.y = -1.0, 0.45
    pointed = Detection(
        class_name="brick", confidence=0.8, length_m=0.1, width_m=0.08, height_m=0.04
    )
    pointed.position.x, pointed.position.y = -0.8, 0.5
    pointed.suction_point.x, pointed.suction_point.y, pointed.suction_point.z = -0.82, 0.51, 0.04
    pointed.suction_radius_m = 0.03
    pointed.suction_tilt_rad = 0.2
    plain.suction_tilt_rad = 0.3  # no point (radius 0): no tilt either
    msg.detections = [plain, pointed]
    stamp_s, (first, second) = detections_of(msg)
    assert stamp_s == 3.0
    assert all(
        math.isnan(v)
        for v in (
            first.suction_x_m,
            first.suction_y_m,
            first.suction_radius_m,
            first.suction_tilt_rad,
        )
    )
    assert second.suction_tilt_rad == 0.2
    assert (second.suction_x_m, second.suction_y_m, second.suction_radius_m) == (-0.82, 0.51, 0.03)
