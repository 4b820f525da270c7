"""The twin node across real processes: lockstep determinism, crashes, isolation, bad input."""

from __future__ import annotations

import json
import math
import os
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest
from process_helpers import finish, start, start_twin_node

PEER = Path(__file__).with_name("twin_peer.py")
HOME = (0.0, -0.35, 0.0, -2.3, 0.0, 1.95, 0.785)


def _twin(env: dict[str, str], dataset: Path, out: Path, *args: str) -> subprocess.Popen[bytes]:
    return start_twin_node(env, ["--dataset", str(dataset), "--out", str(out), *args])


def _peer(env: dict[str, str], *args: str) -> subprocess.Popen[bytes]:
    return start(env, str(PEER), *args)


def _finish(proc: subprocess.Popen[bytes], timeout_s: float = 90.0) -> int:
    return finish(proc, timeout_s)


def _summary(out: Path) -> dict[str, Any]:
    return json.loads((out / "summary.json").read_text(encoding="utf-8"))


LOCKSTEP = (
    "--mode",
    "lockstep",
    "--duration",
    "2.0",
    "--speed",
    "0.4",
    "--prefill",
    "1.2",
    "--objects",
    "20",
    "--seed",
    "3",
    "--ack-timeout",
    "1.0",
)


@pytest.mark.usefixtures("require_interfaces")
def test_lockstep_is_deterministic_with_an_external_controller(
    ros_env_factory: Any,
    builtin_meshes: Path,
    tmp_path: Path,
) -> None:
    runs = []
    for i in range(2):
        env = ros_env_factory()
        out = tmp_path / f"run{i}"
        twin = _twin(env, builtin_meshes, out, *LOCKSTEP)
        peer = _peer(env, "lockstep", str(tmp_path / f"peer{i}.json"))
        assert _finish(twin) == 0, twin.stderr.read().decode()[-3000:] if twin.stderr else ""
        _finish(peer)
        runs.append((out, json.loads((tmp_path / f"peer{i}.json").read_text())))
    (a, peer_a), (b, peer_b) = runs
    sa, sb = _summary(a), _summary(b)
    assert sa["lockstep_timeouts"] == sb["lockstep_timeouts"] == 0
    # every 24th tick of 0..479 (tick 480 is the last published; the episode ends there)
    assert sa["received_commands"] == sb["received_commands"] == 20
    assert peer_a["handled"] == peer_b["handled"] == 481
    assert sa["final_state"] == sb["final_state"]
    assert sa["final_state"]["joint_positions"] != list(HOME)
    assert (a / "events.jsonl").read_bytes() == (b / "events.jsonl").read_bytes()


@pytest.mark.usefixtures("require_interfaces")
def test_ticks_before_the_announced_next_tick_are_not_waited_for(
    ros_env_factory: Any,
    builtin_meshes: Path,
    tmp_path: Path,
) -> None:
    """A controller that acknowledges only every 4th tick, announcing the next one, drives the
    twin through the same episode as one that acknowledges every tick: the same commands at
    the same ticks give the same events and final state, and the twin never waits in vain."""
    runs = []
    for i, every in enumerate((1, 4)):
        env = ros_env_factory()
        out = tmp_path / f"run{i}"
        twin = _twin(env, builtin_meshes, out, *LOCKSTEP)
        peer = _peer(env, "lockstep", str(tmp_path / f"peer{i}.json"), "--every", str(every))
        assert _finish(twin) == 0, twin.stderr.read().decode()[-3000:] if twin.stderr else ""
        _finish(peer)
        runs.append((out, json.loads((tmp_path / f"peer{i}.json").read_text())))
    (a, peer_a), (b, peer_b) = runs
    sa, sb = _summary(a), _summary(b)
    assert sa["lockstep_timeouts"] == sb["lockstep_timeouts"] == 0
    assert sa["received_commands"] == sb["received_commands"] == 20
    assert peer_a["handled"] == peer_b["handled"] == 481
    assert len(peer_a["acked"]) == 481
    assert peer_b["acked"] == list(range(0, 481, 4))
    assert sa["final_state"] == sb["final_state"]
    assert (a / "events.jsonl").read_bytes() == (b / "events.jsonl").read_bytes()


@pytest.mark.usefixtures("require_interfaces")
def test_controller_crash_is_recorded_and_the_episode_completes(
    ros_env: dict[str, str],
    builtin_meshes: Path,
    tmp_path: Path,
) -> None:
    out = tmp_path / "run"
    twin = _twin(ros_env, builtin_meshes, out, *LOCKSTEP)
    peer = _peer(ros_env, "lockstep", str(tmp_path / "peer.json"), "--die-after", "100")
    assert _finish(peer) == 3
    assert _finish(twin) == 0
    summary = _summary(out)
    assert summary["complete"] is True
    assert summary["sim_seconds"] == pytest.approx(2.0)
    assert summary["lockstep_timeouts"] == 1
    faults = [
        json.loads(line)
        for line in (out / "events.jsonl").read_text().splitlines()
        if json.loads(line)["type"] == "fault"
    ]
    assert [f["data"]["kind"] for f in faults] == ["controller_timeout"]
    assert faults[0]["step"] == 100


@pytest.mark.usefixtures("require_interfaces")
def test_parallel_runs_on_separate_domains_do_not_cross_talk(
    ros_env_factory: Any,
    builtin_meshes: Path,
    tmp_path: Path,
) -> None:
    procs = []
    for i, speed in enumerate(("0.2", "0.5")):
        env = ros_env_factory()
        procs.append(
            _twin(
                env,
                builtin_meshes,
                tmp_path / f"run{i}",
                "--speed",
                speed,
                "--duration",
                "6",
                "--objects",
                "5",
            )
        )
        procs.append(_peer(env, "listen", str(tmp_path / f"listen{i}.json"), "3"))
    for proc in procs:
        assert _finish(proc) == 0
    seen = [json.loads((tmp_path / f"listen{i}.json").read_text()) for i in range(2)]
    assert seen[0]["setpoints"] == [0.2]
    assert seen[1]["setpoints"] == [0.5]
    assert all(s["counts"]["/conveyor/state"] > 20 for s in seen)


def _listen(node: Any, got: dict[str, list[Any]]) -> None:
    """Subscribe ``node`` to every topic the twin publishes (bare names), into ``got``."""
    from interfaces import contract as c
    from interfaces.ros import message_class, qos_profile

    for topic in c.PUBLISHED:
        if topic is c.LOCKSTEP_TICK:
            continue
        wire = topic.resolve("")
        node.create_subscription(
            message_class(topic),
            wire,
            lambda msg, wire=wire: got.setdefault(wire, []).append(msg),
            qos_profile(topic.qos),
        )


def _publishers(node: Any) -> dict[Any, Any]:
    """A publisher of ``node`` on every topic the twin takes but the lockstep ack."""
    from interfaces import contract as c
    from interfaces.ros import message_class, qos_profile

    return {
        t: node.create_publisher(message_class(t), t.resolve(""), qos_profile(t.qos))
        for t in c.SUBSCRIBED
        if t is not c.LOCKSTEP_ACK
    }


def _send_bad_commands(pubs: dict[Any, Any]) -> None:
    """Publish one bad command of each kind the cell rejects."""
    from std_msgs.msg import Float64
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from interfaces import contract as c
    from interfaces.ros import message_class

    arm = pubs[c.ARM_TRAJECTORY]
    arm_names = [f"panda_joint{i}" for i in range(1, 8)]

    def trajectory(names: list[str], point: JointTrajectoryPoint) -> JointTrajectory:
        return JointTrajectory(joint_names=names, points=[point])

    arm.publish(trajectory(arm_names[:6], JointTrajectoryPoint(positions=list(HOME[:6]))))
    arm.publish(trajectory(arm_names, JointTrajectoryPoint(positions=[math.nan, *HOME[1:]])))
    arm.publish(trajectory(arm_names, JointTrajectoryPoint(positions=[0.0, 3.5, *HOME[2:]])))
    duplicate = [*arm_names[:6], arm_names[0]]
    arm.publish(trajectory(duplicate, JointTrajectoryPoint(positions=HOME)))
    too_fast = JointTrajectoryPoint(positions=list(HOME), velocities=[0, 0, 0, 3.0, 0, 0, 0])
    arm.publish(trajectory(arm_names, too_fast))
    pubs[c.GRIPPER_COMMAND].publish(Float64(data=0.5))
    pubs[c.BELT_SETPOINT].publish(Float64(data=-0.3))
    pubs[c.BELT_SETPOINT].publish(Float64(data=50.0))
    priorities = message_class(c.PRIORITIES)(classes=["wood", "plastic"])
    pubs[c.PRIORITIES].publish(priorities)


@pytest.mark.usefixtures("require_interfaces")
def test_every_topic_flows_and_bad_commands_are_rejected_and_counted(
    ros_env: dict[str, str],
    builtin_meshes: Path,
    tmp_path: Path,
) -> None:
    import rclpy
    from cdw_interfaces.msg import Ping
    from rclpy.experimental.events_executor import EventsExecutor

    from interfaces import contract as c

    out = tmp_path / "run"
    twin = _twin(
        ros_env,
        builtin_meshes,
        out,
        *("--duration", "8", "--speed", "0.4", "--prefill", "1.5", "--objects", "20"),
        *("--perception", "zero"),
    )
    saved = dict(os.environ)
    os.environ.update(ros_env)
    rclpy.init()
    try:
        node = rclpy.create_node("test_client")
        executor = EventsExecutor()
        executor.add_node(node)
        got: dict[str, list[Any]] = {}
        _listen(node, got)
        pubs = _publishers(node)
        arm, ping = pubs[c.ARM_TRAJECTORY], pubs[c.PING]

        def spin(seconds: float) -> None:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                executor.spin_once(timeout_sec=0.02)

        deadline = time.monotonic() + 60
        while "/clock" not in got or arm.get_subscription_count() == 0:
            spin(0.1)
            assert time.monotonic() < deadline, "the twin node did not come up"
        _send_bad_commands(pubs)
        for seq in range(20):
            ping.publish(Ping(seq=seq, client_send_ns=time.monotonic_ns()))
            spin(0.02)
        spin(1.0)
    finally:
        rclpy.shutdown()
        os.environ.clear()
        os.environ.update(saved)
    assert _finish(twin) == 0
    for topic in (
        "/clock",
        "/joint_states",
        "/tcp_pose",
        "/conveyor/state",
        "/objects/detections",
        "/objects/ground_truth",
        "/events",
        "/ping/echo",
        "/twin/faults",
        "/cell/bins",
    ):
        assert got.get(topic), f"nothing on {topic}"
    assert len(got["/ping/echo"]) == 20
    assert any(d.detections for d in got["/objects/detections"])
    assert {msg.type for msg in got["/events"]} >= {"spawned"}
    summary = _summary(out)
    assert summary["rejected_commands"] == {
        "wrong_joint_count": 1,
        "duplicate_joint": 1,
        "not_finite": 1,
        "beyond_limits": 3,
        "bad_setpoint": 2,
        "unknown_class": 1,
    }
    assert summary["final_state"]["joint_positions"] == pytest.approx(HOME, abs=2e-3)
    assert got["/conveyor/state"][-1].setpoint_mps == pytest.approx(0.4)
    faults = [msg.data for msg in got["/twin/faults"]]
    assert len(faults) == 9
    assert (
        "/arm_controller/joint_trajectory: rejected (duplicate_joint):"
        " duplicate joint name 'panda_joint1'"
    ) in faults
    assert (
        "/arm_controller/joint_trajectory: rejected (beyond_limits):"
        " panda_joint4 velocity 3.0000 rad/s outside its limit [-2.1750, 2.1750]"
    ) in faults
    fault_events = [json.loads(m.detail) for m in got["/events"] if m.type == "fault"]
    assert [e["detail"] for e in fault_events] == faults
    assert [b.class_name for b in got["/cell/bins"][0].bins] == [
        "concrete",
        "brick",
        "wood",
        "rubber",
    ]
