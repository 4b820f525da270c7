"""The MCAP recorder across real processes, and offline metrics equal to the twin's own."""

from __future__ import annotations

import importlib.util
import json
import queue
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml

from experiments.offline import (
    episode_clock,
    header_stamp_ns,
    is_complete,
    iter_raw,
    offline_metrics,
    read_topic,
)
from experiments.record import (
    TOPICS,
    McapRecording,
    RecordingError,
    message_definition,
    recorder_command,
    recover_recording,
)

RELIABLE_TWIN_TOPICS = ("/joint_states", "/conveyor/state", "/objects/detections")
START_TIMEOUT_S = 60.0
EPISODE = (  # long enough that the recorder is killed while the episode runs
    "--duration",
    "10",
    "--speed",
    "0.4",
    "--prefill",
    "1.5",
    "--objects",
    "20",
    "--ack-timeout",
    "10",
)


def _has(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


needs_ros = pytest.mark.skipif(
    not (_has("rclpy") and _has("cdw_interfaces")),
    reason="rclpy or the built cdw_interfaces package is missing",
)


def _mcap_ros2(path: Path, topics: list[str] | None = None) -> list[Any]:
    """Every message decoded by mcap's reader with the mcap_ros2 decoder factory."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with path.open("rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        return list(reader.iter_decoded_messages(topics=topics))


# -- without a ROS graph ------------------------------------------------------------------------
def test_message_definition_has_every_dependency_once() -> None:
    text = message_definition("cdw_interfaces/msg/DetectionArray")
    sections = [line for line in text.splitlines() if line.startswith("MSG: ")]
    assert sections == [
        "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time",
        "MSG: cdw_interfaces/Detection",
        "MSG: geometry_msgs/Point",
    ]
    assert text.count("=" * 80 + "\n") == len(sections)


def test_message_definition_names_what_is_missing(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match=r"no message definition for nope_msgs/Thing"):
        message_definition("nope_msgs/msg/Thing", [tmp_path])
    with pytest.raises(RecordingError, match=r"'a/b/c/d' is not 'pkg/msg/Type'"):
        message_definition("a/b/c/d")


def test_recording_path_must_end_in_mcap(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match=r"rec\.bag must end in \.mcap"):
        McapRecording(tmp_path / "rec.bag", TOPICS)


@needs_ros
def test_written_messages_round_trip_through_mcap_ros2_and_rosbags(tmp_path: Path) -> None:
    from cdw_interfaces.msg import SortingEvent
    from rclpy.serialization import serialize_message
    from rosbags.highlevel import AnyReader
    from rosgraph_msgs.msg import Clock

    out = tmp_path / "rec.mcap"
    recording = McapRecording(out, TOPICS)
    assert recording.partial.exists()
    assert not out.exists()
    for k in range(5):
        clock = Clock()
        clock.clock.sec, clock.clock.nanosec = k, 250_000_000
        recording.write("/clock", serialize_message(clock), 1_000 + k)
    event = SortingEvent(type="spawned", object_id=7, class_name="wood", detail='{"mass_kg": 1.5}')
    event.header.stamp.sec = 3
    recording.write("/events", serialize_message(event), 2_000)
    assert recording.close() == out
    assert not recording.partial.exists()
    assert is_complete(out)

    clocks = list(read_topic(out, "/clock"))
    assert [t for t, _ in clocks] == [1_000, 1_001, 1_002, 1_003, 1_004]
    assert [(m.clock.sec, m.clock.nanosec) for _, m in clocks][-1] == (4, 250_000_000)
    stamps_ns = [header_stamp_ns(m.data) for _, _, m in iter_raw(out, ["/clock"])]
    assert stamps_ns[0] == 250_000_000
    decoded = [decoded for *_, decoded in _mcap_ros2(out, ["/events"])]
    assert [(e.type, e.object_id, e.detail) for e in decoded] == [
        ("spawned", 7, '{"mass_kg": 1.5}')
    ]
    with AnyReader([out]) as reader:
        got: list[Any] = [
            reader.deserialize(raw, conn.msgtype)
            for conn, _, raw in reader.messages()
            if conn.topic == "/events"
        ]
        assert {c.topic for c in reader.connections} == {name for name, _ in TOPICS}
    assert got[0].class_name == "wood"
    assert got[0].header.stamp.sec == 3


def test_a_recording_of_two_stations_has_each_station_topic_under_its_namespace(
    tmp_path: Path,
) -> None:
    from mcap.reader import make_reader

    from interfaces.contract import EVENTS_TOPIC, JOINT_STATES, resolved_topics
    from interfaces.contract import TOPICS as CONTRACT
    from twin.recording import McapRecording as TwinRecording

    out = tmp_path / "two.mcap"
    recording = TwinRecording(out, resolved_topics(("s1", "s2")))
    with pytest.raises(RecordingError, match=r"two\.mcap: topic '/joint_states' is not one"):
        recording.write("/joint_states", b"", 1)
    recording.close()
    with out.open("rb") as handle:
        channels = {c.topic: c for c in make_reader(handle).get_summary().channels.values()}
    station = [t for t in CONTRACT if t.scope == "station"]
    cell = [t for t in CONTRACT if t.scope == "cell"]
    assert set(channels) == {t.name for t in cell} | {
        f"/{ns}/{t.name}" for t in station for ns in ("s1", "s2")
    }
    assert "/s2/cell/bins" in channels
    assert "/s1/lockstep/ack" in channels
    for name, topic in (("/s1/joint_states", JOINT_STATES), ("/events", EVENTS_TOPIC)):
        qos = yaml.safe_load(channels[name].metadata["offered_qos_profiles"])[0]
        assert qos["depth"] == topic.qos.depth
        assert qos["durability"] == ("transient_local" if topic.qos.latched else "volatile")


def test_episode_clock_rebuilds_the_twins_duration() -> None:
    dt_s = 1.0 / 240.0
    stamps = [round(k * dt_s * 1e9) for k in range(1441)]
    clock = episode_clock(stamps, Path("x.mcap"))
    assert clock.physics_hz == 240.0
    assert clock.steps == 1440
    assert clock.duration_s == 1440 * dt_s
    with pytest.raises(RecordingError, match="fewer than two /joint_states stamps"):
        episode_clock([5, 5], Path("x.mcap"))


@needs_ros
def test_the_recorder_subscribes_to_the_station_topics_of_the_cell_it_is_given(
    tmp_path: Path,
) -> None:
    from twin.ros_isolation import ros_domain

    out = tmp_path / "cell.mcap"
    with ros_domain() as domain:
        recorder = _Recorder(domain.env, out, cell="two_pandas")
        stats = recorder.stop()
    assert stats["out"] == str(out)
    counts = stats["counts"]
    assert {"/s1/joint_states", "/s2/joint_states", "/s1/gripper/command", "/clock"} <= set(counts)
    assert "/joint_states" not in counts
    assert is_complete(out)


# -- a real episode: twin node, controller, one recorder stopped cleanly, one killed -------------
@dataclass
class Episode:
    """Artefacts of one recorded lockstep episode."""

    twin_out: Path
    clean: Path
    clean_stats: dict[str, Any]
    killed_partial: Path
    kill_wall_ns: int


def _wait(proc: subprocess.Popen[Any], timeout_s: float) -> int:
    try:
        return proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        raise


class _Recorder:
    """A recorder subprocess whose stdout lines a thread collects (so reads can time out)."""

    def __init__(self, env: dict[str, str], out: Path, cell: str | None = None) -> None:
        self.proc = subprocess.Popen(
            recorder_command(out, cell=cell), env=env, stdout=subprocess.PIPE, text=True
        )
        self.lines: queue.Queue[str] = queue.Queue()
        self._thread = threading.Thread(target=self._pump, daemon=True)
        self._thread.start()
        assert self.next_line(START_TIMEOUT_S) == f"recording {out}.partial"

    def _pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.strip())

    def next_line(self, timeout_s: float) -> str:
        """The next line it printed; fails the test after ``timeout_s``."""
        try:
            return self.lines.get(timeout=timeout_s)
        except queue.Empty:
            pytest.fail(f"the recorder printed nothing for {timeout_s} s")

    def wait_matched(self, topics: set[str]) -> None:
        """Wait for its ``matched <topic>`` line of every one of ``topics``."""
        waiting = set(topics)
        while waiting:
            waiting.discard(self.next_line(START_TIMEOUT_S).removeprefix("matched "))

    def stop(self) -> dict[str, Any]:
        """SIGTERM, a clean exit, and the statistics it printed last."""
        self.proc.send_signal(signal.SIGTERM)
        assert _wait(self.proc, 20.0) == 0
        self._thread.join(timeout=5.0)
        last = ""
        while not self.lines.empty():
            last = self.lines.get()
        return dict(json.loads(last))


@pytest.fixture(scope="module")
def episode(builtin_meshes: Path, tmp_path_factory: pytest.TempPathFactory) -> Episode:
    """Record one short lockstep episode twice: one recorder is SIGKILLed half-way."""
    from twin.ros_isolation import clean_stale_fastdds_shm, ros_domain

    if not (_has("rclpy") and _has("cdw_interfaces")):
        pytest.skip("rclpy or the built cdw_interfaces package is missing")
    clean_stale_fastdds_shm()
    base = tmp_path_factory.mktemp("recorded")
    twin_out, clean, killed = base / "twin", base / "clean.mcap", base / "killed.mcap"
    procs: list[subprocess.Popen[Any]] = []
    with ros_domain() as domain:
        env = domain.env
        try:
            recorder_a = _Recorder(env, clean)
            procs.append(recorder_a.proc)
            recorder_b = _Recorder(env, killed)
            procs.append(recorder_b.proc)
            twin_cmd = [sys.executable, "-m", "twin.cli", "twin-node", "--dataset"]
            twin_cmd += [str(builtin_meshes), "--out", str(twin_out), "--mode", "lockstep"]
            procs.append(twin := subprocess.Popen([*twin_cmd, *EPISODE], env=env))
            for recorder in (recorder_a, recorder_b):
                recorder.wait_matched({*RELIABLE_TWIN_TOPICS, "/tcp_pose", "/events"})
            ctl_cmd = [sys.executable, "-m", "twin.cli", "controller", "--lockstep"]
            procs.append(controller := subprocess.Popen(ctl_cmd, env=env))
            partial = Path(f"{killed}.partial")
            start_size = partial.stat().st_size
            deadline = time.monotonic() + 120.0
            while partial.stat().st_size < start_size + 20_000 and time.monotonic() < deadline:
                assert twin.poll() is None, "the twin ended before the recorder got any data"
                time.sleep(0.05)
            time.sleep(1.0)
            kill_wall_ns = time.time_ns()
            recorder_b.proc.send_signal(signal.SIGKILL)
            _wait(recorder_b.proc, 10.0)
            assert _wait(twin, 120.0) == 0
            controller.send_signal(signal.SIGINT)
            _wait(controller, 20.0)
            stats = recorder_a.stop()
        finally:
            for proc in procs:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
    return Episode(twin_out, clean, stats, partial, kill_wall_ns)


def _twin_summary(episode: Episode) -> dict[str, Any]:
    text = (episode.twin_out / "summary.json").read_text(encoding="utf-8")
    return dict(json.loads(text))


def _twin_events(episode: Episode) -> list[dict[str, Any]]:
    lines = (episode.twin_out / "events.jsonl").read_text(encoding="utf-8").splitlines()
    return [json.loads(line) for line in lines]


@needs_ros
def test_recording_holds_every_message_the_twin_published(episode: Episode) -> None:
    from rosbags.highlevel import AnyReader

    summary = _twin_summary(episode)
    assert summary["complete"] is True
    assert summary["lockstep_timeouts"] == 0
    assert is_complete(episode.clean)
    assert not Path(f"{episode.clean}.partial").exists()
    by_topic = Counter(channel.topic for _, channel, _, _ in _mcap_ros2(episode.clean))
    for topic in RELIABLE_TWIN_TOPICS:
        assert by_topic[topic] == summary["published"][topic], topic
    steps = round(summary["sim_seconds"] * 240)
    assert by_topic["/tcp_pose"] == steps + 1
    # the recorder joins /lockstep/tick once the twin steps: a contiguous tail of the ticks
    ticks = [msg.tick for _, msg in read_topic(episode.clean, "/lockstep/tick")]
    assert ticks == list(range(steps + 1 - len(ticks), steps + 1))
    assert 0 < len(ticks) <= steps + 1
    assert by_topic["/lockstep/ack"] > 0
    assert by_topic["/arm_controller/joint_trajectory"] > 0
    assert 0 < by_topic["/clock"] <= steps + 1
    assert dict(by_topic) == {k: v for k, v in episode.clean_stats["counts"].items() if v}

    with AnyReader([episode.clean]) as reader:
        seen: Counter[str] = Counter()
        for conn, _, raw in reader.messages():
            if seen[conn.topic] < 3:
                reader.deserialize(raw, conn.msgtype)
            seen[conn.topic] += 1
    assert seen == by_topic


@needs_ros
def test_offline_metrics_equal_the_twins_scores(episode: Episode) -> None:
    summary = _twin_summary(episode)
    metrics = offline_metrics(episode.clean)
    assert metrics.scores == summary["scores"]
    assert metrics.duration_s == summary["sim_seconds"]
    assert metrics.scores["spawned"] > 0
    assert "not recomputable" in metrics.tracking_note
    published = [e for e in _twin_events(episode) if e["type"] != "fault"]
    recorded = [msg for _, msg in read_topic(episode.clean, "/events")]
    assert [(m.type, m.object_id, m.class_name, json.loads(m.detail)) for m in recorded] == [
        (e["type"], e["object_id"], e["class_name"], e["data"]) for e in published
    ]


@needs_ros
def test_a_killed_recorder_leaves_a_readable_recording(episode: Episode) -> None:
    from rosbags.highlevel import AnyReader

    partial = episode.killed_partial
    assert partial.exists()
    assert not is_complete(partial)
    stamps = [t for t, _ in read_topic(partial, "/joint_states")]
    assert stamps
    # everything the clean recorder received up to 1 s before the kill is in the killed one
    clean_before = [t for t, _ in read_topic(episode.clean, "/joint_states")]
    assert len(stamps) >= sum(1 for t in clean_before if t <= episode.kill_wall_ns - 1_000_000_000)
    assert len(stamps) < len(clean_before)
    recovered = recover_recording(partial)
    assert recovered == partial.with_name("killed.mcap")
    assert is_complete(recovered)
    with AnyReader([recovered]) as reader:
        n = sum(1 for conn, _, _ in reader.messages() if conn.topic == "/joint_states")
    assert n == len(stamps)
