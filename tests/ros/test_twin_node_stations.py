"""A twin node of the two-station ``two_pandas`` cell: every station's topics under its namespace,
its commands applied to its own arm, lockstep waiting for every station's controller."""

# rclpy's annotations are partial.
# mypy: disable-error-code="no-untyped-call"

from __future__ import annotations

import json
import os
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from process_helpers import finish, start, start_twin_node
from twin_helpers import box_px

from interfaces import contract
from interfaces.cell import Cell, load_cell
from interfaces.tools import ParallelJawSpec
from twin.scenario import Scenario, SystemLevel
from twin.sim import Twin

pytestmark = pytest.mark.usefixtures("require_interfaces")

PEER = Path(__file__).with_name("twin_peer.py")
ONE_BOX = {"img": [(1, box_px(500, 500, 100, 50))]}


def _client(node: Any, got: dict[str, list[Any]]) -> tuple[Any, Any]:
    """Subscribe ``node`` to both stations' ``joint_states`` and ``cell/bins`` and to
    ``/events`` (into ``got``); returns its publishers of station s2's gripper command and
    station s1's arm command."""
    from interfaces.ros import message_class, qos_profile

    for ns in ("s1", "s2"):
        for topic in (contract.JOINT_STATES, contract.BINS):
            wire = topic.resolve(ns)
            node.create_subscription(
                message_class(topic),
                wire,
                lambda msg, wire=wire: got.setdefault(wire, []).append(msg),
                qos_profile(topic.qos),
            )
    return tuple(
        node.create_publisher(message_class(t), t.resolve(ns), qos_profile(t.qos))
        for t, ns in ((contract.GRIPPER_COMMAND, "s2"), (contract.ARM_TRAJECTORY, "s1"))
    )


def test_each_station_publishes_and_listens_under_its_namespace(
    ros_env: dict[str, str], mesh_polygons: Callable[..., Path]
) -> None:
    import rclpy
    from rclpy.experimental.events_executor import EventsExecutor
    from std_msgs.msg import Float64
    from trajectory_msgs.msg import JointTrajectory

    from twin.ros_node import TwinNode, run_loop

    cell = load_cell("two_pandas")
    scenario = Scenario(duration_s=0.5, system=SystemLevel(belt_speed_mps=0.2, repeat_images=False))
    saved = dict(os.environ)
    os.environ.update(ros_env)
    rclpy.init()
    executor = EventsExecutor()
    got: dict[str, list[Any]] = {}
    try:
        with Twin(scenario, dataset_dir=mesh_polygons(ONE_BOX), cell=cell) as twin:
            twin.reset(seed=0)
            node = TwinNode(twin, lockstep=False)
            client = rclpy.create_node("station_client")
            gripper, arm = _client(client, got)
            executor.add_node(node)
            executor.add_node(client)
            deadline = time.monotonic() + 20.0
            while gripper.get_subscription_count() == 0 or arm.get_subscription_count() == 0:
                executor.spin_once(timeout_sec=0.05)
                assert time.monotonic() < deadline, "the twin node's subscriptions did not match"
            names = dict(client.get_topic_names_and_types())
            gripper.publish(Float64(data=0.02))  # closes station s2's gripper only
            arm.publish(JointTrajectory())  # no points: rejected, naming station s1
            run_loop(node, executor)
            end = time.monotonic() + 2.0
            while time.monotonic() < end and len(got.get("/s2/cell/bins", [])) < 1:
                executor.spin_once(timeout_sec=0.05)
            widths = [arm_state.gripper_width_m for arm_state in twin.observe().arms]
            events = twin.events
            node.destroy_node()
            client.destroy_node()
    finally:
        executor.shutdown()
        rclpy.shutdown()
        os.environ.clear()
        os.environ.update(saved)
    # the names on the wire: every station topic under each namespace, none bare
    for ns in ("s1", "s2"):
        for topic in (contract.JOINT_STATES, contract.TCP_POSE, contract.ARM_TRAJECTORY):
            assert topic.resolve(ns) in names, topic.resolve(ns)
    assert "/joint_states" not in names
    assert "/arm_controller/joint_trajectory" not in names
    _check_streams(got, cell)
    assert widths == pytest.approx([0.08, 0.02], abs=2e-3)
    (fault,) = [e for e in events if e.type == "fault"]
    assert fault.data["station"] == "upstream"
    assert fault.data["detail"].startswith("/s1/arm_controller/joint_trajectory: rejected (empty)")


def _check_streams(got: dict[str, list[Any]], cell: Cell) -> None:
    """Each station's joint states and bins are its own."""
    for ns, station in (("s1", cell.stations[0]), ("s2", cell.stations[1])):
        joints = got[f"/{ns}/joint_states"]
        assert len(joints) > 100
        assert isinstance(station.tool, ParallelJawSpec)
        assert list(joints[-1].name) == [*station.robot.arm_joints, *station.tool.joints]
        (bins,) = got[f"/{ns}/cell/bins"]
        assert [(b.class_name, b.position.x) for b in bins.bins] == [
            (b.class_name, b.centre_x_m) for b in station.bins
        ]
    # s2 closed its gripper (each finger reports half the opening), s1 stays open
    finger = len(cell.stations[0].robot.arm_joints)
    assert got["/s1/joint_states"][-1].position[finger] == pytest.approx(0.04, abs=1e-3)
    assert got["/s2/joint_states"][-1].position[finger] == pytest.approx(0.01, abs=1e-3)


def _twin_node(env: dict[str, str], dataset: Path, out: Path) -> subprocess.Popen[bytes]:
    args = [
        *("--cell", "two_pandas", "--dataset", str(dataset), "--out", str(out)),
        *("--mode", "lockstep", "--record", str(out / "recording.mcap")),
        *("--duration", "2.0", "--speed", "0.4", "--prefill", "2.5", "--objects", "20"),
        *("--seed", "3", "--ack-timeout", "1.0"),
    ]
    proc: subprocess.Popen[bytes] = start_twin_node(env, args)
    return proc


def _peer(env: dict[str, str], out: Path, ns: str, *args: str) -> subprocess.Popen[bytes]:
    proc: subprocess.Popen[bytes] = start(
        env, str(PEER), "lockstep", str(out), "--namespace", ns, *args
    )
    return proc


def _finish(proc: subprocess.Popen[bytes], timeout_s: float = 120.0) -> int:
    code: int = finish(proc, timeout_s)
    return code


def test_lockstep_waits_for_every_station_and_loses_one_controller_alone(
    ros_env: dict[str, str], builtin_meshes: Path, tmp_path: Path
) -> None:
    """Both stations' controllers acknowledge every tick; the upstream one dies after 100
    ticks: a ``controller_timeout`` naming it, and the downstream one is still waited for (it
    handles every tick)."""
    out = tmp_path / "run"
    twin = _twin_node(ros_env, builtin_meshes, out)
    up = _peer(ros_env, tmp_path / "s1.json", "s1", "--die-after", "100")
    down = _peer(ros_env, tmp_path / "s2.json", "s2")
    assert _finish(up) == 3
    assert _finish(twin) == 0, twin.stderr.read().decode()[-3000:] if twin.stderr else ""
    _finish(down)
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    downstream = json.loads((tmp_path / "s2.json").read_text(encoding="utf-8"))
    assert summary["complete"] is True
    assert summary["lockstep_timeouts"] == 1
    assert downstream["handled"] == 481  # ticks 0..480, every one waited for
    events = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    faults = [e for e in events if e["type"] == "fault"]
    assert [(f["data"]["kind"], f["data"]["station"], f["step"]) for f in faults] == [
        ("controller_timeout", "upstream", 100)
    ]
    assert set(summary["stations"]) == {"upstream", "downstream"}
    assert summary["published"]["/s1/joint_states"] == summary["published"]["/s2/joint_states"]
    assert len(summary["final_state"]["joint_positions"]) == 14  # two Pandas' arm joints
    # the recording has every station's topics under its namespace, as sent
    from mcap.reader import make_reader

    with (out / "recording.mcap").open("rb") as handle:
        stats = make_reader(handle).get_summary()
    assert stats is not None
    assert stats.statistics is not None
    counts = {
        stats.channels[i].topic: n for i, n in stats.statistics.channel_message_counts.items()
    }
    assert counts["/s1/joint_states"] == counts["/s2/joint_states"] == 481
    assert counts["/s2/lockstep/ack"] >= 480  # every tick stepped on (480's may come too late)


def test_the_claims_board_is_relayed_with_the_station_and_counted_in_the_tick(
    ros_env: dict[str, str], mesh_polygons: Callable[..., Path], tmp_path: Path
) -> None:
    """The upstream station's controller sends the claims of ``twin_peer.CLAIMS`` on
    ``/s1/line/claim``; both controllers get the same boards on ``/line/claims``, each in the
    tick after the claim (the claims of tick k are commands of tick k: they change the board
    relayed after step k + 1), named ``upstream`` (the controller left it empty), a released or
    picked entry relayed once and then gone, each board counted by its tick. The bad state is
    a ``bad_claim`` fault and changes nothing."""
    out = tmp_path / "run"
    args = [
        *("--cell", "two_pandas", "--dataset", str(mesh_polygons(ONE_BOX)), "--out", str(out)),
        *("--mode", "lockstep", "--duration", "0.3", "--speed", "0.4", "--seed", "3"),
        *("--ack-timeout", "5.0"),
    ]
    twin = start_twin_node(ros_env, args)
    up = _peer(ros_env, tmp_path / "s1.json", "s1", "--claims")
    down = _peer(ros_env, tmp_path / "s2.json", "s2")
    assert _finish(twin) == 0, twin.stderr.read().decode()[-3000:] if twin.stderr else ""
    assert (_finish(up), _finish(down)) == (0, 0)
    upstream, downstream = (
        json.loads((tmp_path / f"{ns}.json").read_text(encoding="utf-8")) for ns in ("s1", "s2")
    )
    assert upstream["handled"] == downstream["handled"] == 73  # ticks 0..72, none lost
    stamp_ns = [round(tick * 1e9 / 240.0) for tick in (11, 12, 31, 61)]
    up7, up8 = ["upstream", 7, "claimed"], ["upstream", 8, "claimed"]
    expected = [
        {"stamp_ns": stamp_ns[0], "claims": [up7]},
        {"stamp_ns": stamp_ns[1], "claims": [up7, up8]},
        {"stamp_ns": stamp_ns[2], "claims": [["upstream", 7, "released"], up8]},
        {"stamp_ns": stamp_ns[3], "claims": [["upstream", 8, "picked"]]},
    ]
    assert upstream["boards"] == downstream["boards"] == expected
    # the tick counts each board: n_claims 1 in its tick, last_claims_ns its stamp
    counted = [[tick, 1, ns] for tick, ns in zip((11, 12, 31, 61), stamp_ns, strict=True)]
    assert upstream["counted"] == downstream["counted"] == counted
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["published"]["/line/claims"] == 4
    events = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    faults = [e["data"] for e in events if e["type"] == "fault"]
    assert [(f["kind"], f["station"]) for f in faults] == [("bad_claim", "upstream")]
    assert faults[0]["detail"].startswith("/s1/line/claim: rejected (bad_claim): state 'grabbed'")
