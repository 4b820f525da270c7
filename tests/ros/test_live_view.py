"""The live view (``--foxglove``): a Foxglove WebSocket client on loopback watches a real episode.

The client is the protocol written out with the standard library (handshake, frames, the
``foxglove.sdk.v1`` subprotocol's ``subscribe`` and binary message data), so the test checks
what goes over the wire, not what the SDK says about it. Every scene channel
(:data:`interfaces.contract.SCENE`) must be advertised with its ROS schema and deliver messages
that decode with it while the episode runs.
"""

from __future__ import annotations

import base64
import json
import math
import os
import selectors
import socket
import struct
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from interfaces.contract import SCENE, TOPICS
from twin.recording import message_definition

SUBPROTOCOLS = "foxglove.sdk.v1, foxglove.websocket.v1"
"""What the Foxglove app offers in its handshake."""
MESSAGE_DATA = 0x01
"""Opcode of a server's binary message data: subscription id, log time, payload."""
SCENE_TOPICS = [t.name for t in SCENE]
"""Every scene topic: all are sent with or without a controller (the targets' markers say
there is none)."""
START_TIMEOUT_S = 60.0
POSITION_TOL_M = 1e-3


class WsClient:
    """A minimal WebSocket client of Foxglove's protocol over one TCP connection."""

    def __init__(self, host: str, port: int, timeout_s: float = 10.0) -> None:
        self.sock = socket.create_connection((host, port), timeout=timeout_s)
        key = base64.b64encode(os.urandom(16)).decode()
        request = (
            f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
            f"Sec-WebSocket-Protocol: {SUBPROTOCOLS}\r\n\r\n"
        )
        self.sock.sendall(request.encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(1)
            if not chunk:
                msg = f"connection closed during the handshake: {head!r}"
                raise ConnectionError(msg)
            head += chunk
        self.response = head.decode()
        self.next_subscription = 1

    def _read(self, n: int) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            if not chunk:
                msg = "connection closed"
                raise ConnectionError(msg)
            buf += chunk
        return bytes(buf)

    def recv(self) -> tuple[int, bytes]:
        """The next whole message: (opcode 1 text or 2 binary, payload); pings are skipped."""
        parts: list[bytes] = []
        opcode = 0
        while True:
            b0, b1 = self._read(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._read(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._read(8))[0]
            payload = self._read(n)
            frame_op = b0 & 0x0F
            if frame_op in (0x9, 0xA):  # ping, pong
                continue
            if frame_op == 0x8:
                msg = f"server closed the connection: {payload!r}"
                raise ConnectionError(msg)
            opcode = opcode or frame_op
            parts.append(payload)
            if b0 & 0x80:
                return opcode, b"".join(parts)

    def recv_json(self) -> dict[str, Any]:
        """The next text message, parsed."""
        opcode, payload = self.recv()
        assert opcode == 1, f"expected a text message, got opcode {opcode}"
        return dict(json.loads(payload))

    def send_json(self, value: dict[str, Any]) -> None:
        """One masked text frame."""
        data = json.dumps(value).encode()
        mask = os.urandom(4)
        n = len(data)
        if n < 126:
            head = bytes([0x81, 0x80 | n])
        elif n < 65536:
            head = bytes([0x81, 0x80 | 126]) + struct.pack(">H", n)
        else:
            head = bytes([0x81, 0x80 | 127]) + struct.pack(">Q", n)
        masked = bytes(c ^ mask[i % 4] for i, c in enumerate(data))
        self.sock.sendall(head + mask + masked)

    def subscribe(self, channel_ids: list[int]) -> dict[int, int]:
        """Subscribe to channels; returns subscription id -> channel id."""
        subs = {}
        for channel_id in channel_ids:
            subs[self.next_subscription] = channel_id
            self.next_subscription += 1
        self.send_json(
            {
                "op": "subscribe",
                "subscriptions": [{"id": s, "channelId": c} for s, c in subs.items()],
            }
        )
        return subs

    def close(self) -> None:
        """Drop the connection."""
        self.sock.close()


@dataclass
class Received:
    """Binary messages received, by topic: (log time ns, payload)."""

    by_topic: dict[str, list[tuple[int, bytes]]] = field(default_factory=dict)

    def add(self, topic: str, log_time_ns: int, payload: bytes) -> None:
        """Keep one message."""
        self.by_topic.setdefault(topic, []).append((log_time_ns, payload))


def receive_until(
    client: WsClient,
    subs: dict[int, str],
    received: Received,
    wanted: list[str],
    timeout_s: float,
    count: int = 1,
) -> None:
    """Read messages until every ``wanted`` topic has ``count``, the time is up or the server
    closes the connection (the episode ended)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not all(
        len(received.by_topic.get(t, ())) >= count for t in wanted
    ):
        try:
            opcode, payload = client.recv()
        except (ConnectionError, TimeoutError):
            return
        if opcode != 2 or payload[0] != MESSAGE_DATA:
            continue
        sub_id, log_time_ns = struct.unpack_from("<IQ", payload, 1)
        if sub_id in subs:
            received.add(subs[sub_id], log_time_ns, payload[13:])


def wait_for_url(proc: subprocess.Popen[str], timeout_s: float) -> str:
    """The live view's address, from the line the twin node prints when it listens."""
    assert proc.stdout is not None
    selector = selectors.DefaultSelector()
    selector.register(proc.stdout, selectors.EVENT_READ)
    deadline = time.monotonic() + timeout_s
    lines = []
    while time.monotonic() < deadline:
        if not selector.select(timeout=0.5):
            if proc.poll() is not None:
                break
            continue
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if "live view on ws://" in line:
            return line.split("live view on ", 1)[1].split()[0]
    pytest.fail(f"no live view address printed; output: {''.join(lines)!r}")


def decode(schema_name: str, schema_text: str, payload: bytes) -> Any:
    """A CDR message decoded with the schema the live view advertised."""
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    schema = Schema(id=1, name=schema_name, encoding="ros2msg", data=schema_text.encode())
    decoder = DecoderFactory().decoder_for("cdr", schema)
    assert decoder is not None
    return decoder(payload)


def start_node(env: dict[str, str], dataset: Path, out: Path, *args: str) -> subprocess.Popen[str]:
    """A realtime twin node with a live view; its stdout is read for the address."""
    cmd = [
        sys.executable,
        "-m",
        "twin.cli",
        "twin-node",
        "--dataset",
        str(dataset),
        "--out",
        str(out),
        "--mode",
        "realtime",
        "--speed",
        "0.3",
        "--prefill",
        "1.2",
        "--objects",
        "15",
        "--seed",
        "2",
        *args,
    ]
    return subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def stop_node(proc: subprocess.Popen[str], timeout_s: float = 60.0) -> tuple[int, str]:
    """Wait for the node (killed after ``timeout_s``); returns its exit status and stderr."""
    try:
        _, stderr = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, stderr = proc.communicate()
    return proc.returncode, stderr


def check_advertised(channels: dict[str, dict[str, Any]]) -> None:
    """Every contract topic of a one-station cell is a channel, typed as on the wire."""
    for topic in TOPICS:
        wire = topic.resolve("")
        assert wire in channels, f"{wire} not advertised"
        channel = channels[wire]
        assert channel["encoding"] == "cdr"
        assert channel["schemaName"] == topic.msgtype
        assert channel["schemaEncoding"] == "ros2msg"
        assert channel["schema"] == message_definition(topic.msgtype)


def check_ground_truth(truth: Any) -> None:
    """Objects with finite poses, unit quaternions, those on the belt over the belt."""
    assert truth.header.frame_id == "world"
    assert truth.objects, "ground truth with no object after a 1.2 m prefill"
    for obj in truth.objects:
        p = obj.pose.position
        q = obj.pose.orientation
        assert all(math.isfinite(v) for v in (p.x, p.y, p.z))
        assert -3.0 < p.x < 3.0
        assert -0.5 < p.z < 1.5
        assert math.isclose(q.x**2 + q.y**2 + q.z**2 + q.w**2, 1.0, abs_tol=1e-6)
    on_belt = [o for o in truth.objects if o.on_belt]
    assert on_belt
    assert all(abs(o.pose.position.y - 0.5) < 0.35 for o in on_belt)


def check_tf(tf: Any, truth: Any) -> None:
    """A ``/tf`` of the ground truth's tick: the station's links and TCP are there, and every
    object in the simulation (not in a bin) has its frame at its ground-truth pose."""
    frames = {t.child_frame_id: t.transform for t in tf.transforms}
    assert all(t.header.frame_id == "world" for t in tf.transforms)
    for t in tf.transforms:
        r = t.transform.rotation
        assert math.isclose(r.x**2 + r.y**2 + r.z**2 + r.w**2, 1.0, abs_tol=1e-6)
    assert {"tcp", "panda_link7", "panda_hand"} <= set(frames), sorted(frames)
    simulated = {f"object/{o.id}" for o in truth.objects if not o.in_bin}
    assert {name for name in frames if name.startswith("object/")} == simulated
    for obj in truth.objects:
        if obj.in_bin:
            continue
        transform = frames[f"object/{obj.id}"]
        p, q = obj.pose.position, obj.pose.orientation
        v, r = transform.translation, transform.rotation
        assert math.dist((v.x, v.y, v.z), (p.x, p.y, p.z)) <= POSITION_TOL_M
        dot = abs(q.x * r.x + q.y * r.y + q.z * r.z + q.w * r.w)
        assert 2.0 * math.acos(min(1.0, dot)) <= math.radians(1.0)


def check_static_markers(static: Any) -> None:
    """``/scene/markers`` holds the belt, the bins and the robot's link meshes."""
    by_ns: dict[str, list[Any]] = {}
    for marker in static.markers:
        by_ns.setdefault(marker.ns, []).append(marker)
    assert [m.type for m in by_ns["belt"]] == [1]  # CUBE
    assert len(by_ns["bins"]) >= 2
    assert {m.header.frame_id for m in by_ns["links"]} >= {f"panda_link{i}" for i in range(8)}


def check_object_markers(objects: list[Any], tfs: list[Any]) -> None:
    """Each ``/scene/objects`` message adds every object then in the simulation as its own mesh
    locked to its frame, and every ``/tf`` has a frame for exactly the objects of the latest
    ``/scene/objects`` stamped at or before it. The client saw every message sent after it
    subscribed (one connection, sent in order), so the check leaves out only the ``/tf`` of the
    last tick received, whose ``/scene/objects`` may still have been on its way."""
    sets: list[tuple[tuple[int, int], set[int]]] = []
    for message in objects:
        added = [m for m in message.markers if m.action == 0]
        assert added, "a /scene/objects message with no object"
        for marker in added:
            assert marker.ns == "objects"
            assert marker.type == 11  # TRIANGLE_LIST
            assert marker.frame_locked
            assert marker.header.frame_id == f"object/{marker.id}"
            assert len(marker.points) >= 3 * 8  # a closed mesh: at least a box's triangles
            assert len(marker.points) % 3 == 0
        sets.append((stamp_of(message.markers[0].header), {m.id for m in added}))
    sets.sort()
    stamps = [stamp_of(tf.transforms[0].header) for tf in tfs]
    checked = 0
    for tf, stamp in zip(tfs, stamps, strict=True):
        if stamp == max(stamps):
            continue
        current = [ids for s, ids in sets if s <= stamp]
        assert current, f"/tf at {stamp} before any /scene/objects"
        names = {t.child_frame_id for t in tf.transforms if t.child_frame_id.startswith("object/")}
        assert names == {f"object/{i}" for i in current[-1]}, stamp
        checked += 1
    assert checked >= 3


def stamp_of(header: Any) -> tuple[int, int]:
    """A message header's stamp as (sec, nanosec)."""
    return int(header.stamp.sec), int(header.stamp.nanosec)


def decode_on(channels: dict[str, dict[str, Any]], topic: str, payload: bytes) -> Any:
    """A message of ``topic`` decoded with the schema its channel advertised."""
    channel = channels[topic]
    return decode(channel["schemaName"], channel["schema"], payload)


def watch(client: WsClient, channels: dict[str, dict[str, Any]], late: list[str]) -> Received:
    """Subscribe to ``/clock``; once it ticks (the node is stepping, its latched messages were
    sent long ago), subscribe to ``late`` and read until each has a message."""
    received = Received()
    names = {c["id"]: c["topic"] for c in channels.values()}
    subs = {s: names[c] for s, c in client.subscribe([channels["/clock"]["id"]]).items()}
    receive_until(client, subs, received, ["/clock"], START_TIMEOUT_S)
    assert "/clock" in received.by_topic
    new = client.subscribe([channels[t]["id"] for t in late])
    subs.update({s: names[c] for s, c in new.items()})
    receive_until(client, subs, received, late, 20.0)
    receive_until(client, subs, received, ["/objects/ground_truth", "/tf"], 5.0, count=5)
    return received


@pytest.mark.usefixtures("require_interfaces")
def test_a_websocket_client_watches_the_episode_as_it_runs(
    ros_env: dict[str, str], builtin_meshes: Path, tmp_path: Path
) -> None:
    out = tmp_path / "ep"
    proc = start_node(ros_env, builtin_meshes, out, "--duration", "6", "--foxglove", "0")
    late = ["/objects/ground_truth", "/cell/bins", *SCENE_TOPICS]
    try:
        url = wait_for_url(proc, START_TIMEOUT_S)
        host, port = url.removeprefix("ws://").rsplit(":", 1)
        assert host == "127.0.0.1"
        client = WsClient(host, int(port))
        assert "sec-websocket-protocol: foxglove.sdk.v1" in client.response.lower()
        assert client.recv_json()["op"] == "serverInfo"
        advertise = client.recv_json()
        assert advertise["op"] == "advertise"
        channels = {c["topic"]: c for c in advertise["channels"]}
        check_advertised(channels)
        for topic in SCENE_TOPICS:  # the scene's schemas: ROS's, which Foxglove renders
            assert channels[topic]["schemaName"] in (
                "tf2_msgs/msg/TFMessage",
                "visualization_msgs/msg/MarkerArray",
            )
        received = watch(client, channels, late)
        running = proc.poll() is None  # everything above arrived while the episode ran
        client.close()
    finally:
        code, stderr = stop_node(proc)
    assert code == 0, stderr[-2000:]
    assert running, "the episode ended before the client had every channel's messages"
    missing = [t for t in late if t not in received.by_topic]
    assert not missing, f"no message on {missing}"

    # latched messages sent before the client subscribed reach it
    bins = decode_on(channels, "/cell/bins", received.by_topic["/cell/bins"][0][1])
    assert len(bins.bins) >= 2
    static = decode_on(channels, "/tf_static", received.by_topic["/tf_static"][0][1])
    assert [t.child_frame_id for t in static.transforms] == [
        "panda_link0",
        "camera_link",
        "camera_optical_frame",
    ]

    log_ns, payload = received.by_topic["/objects/ground_truth"][-1]
    truth = decode_on(channels, "/objects/ground_truth", payload)
    check_ground_truth(truth)
    assert abs(log_ns - time.time_ns()) < 120e9  # the wall-clock log time of this run

    truths = {
        stamp_of(t.header): t
        for t in (
            decode_on(channels, "/objects/ground_truth", m)
            for _, m in received.by_topic["/objects/ground_truth"]
        )
    }
    tfs = [decode_on(channels, "/tf", m) for _, m in received.by_topic["/tf"]]
    pairs = [
        (tf, truths[stamp_of(tf.transforms[0].header)])
        for tf in tfs
        if tf.transforms and stamp_of(tf.transforms[0].header) in truths
    ]
    assert pairs, "no /tf at the tick of a ground truth received"
    for tf, tick_truth in pairs:
        check_tf(tf, tick_truth)

    check_static_markers(
        decode_on(channels, "/scene/markers", received.by_topic["/scene/markers"][0][1])
    )
    objects = [
        decode_on(channels, "/scene/objects", m) for _, m in received.by_topic["/scene/objects"]
    ]
    check_object_markers(objects, tfs)
    targets = decode_on(channels, "/scene/targets", received.by_topic["/scene/targets"][-1][1])
    assert {m.ns for m in targets.markers} == {"targets", "tcp_paths"}


def test_a_port_in_use_is_a_one_line_error(
    ros_env: dict[str, str], builtin_meshes: Path, tmp_path: Path
) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        out = tmp_path / "ep"
        proc = start_node(ros_env, builtin_meshes, out, "--duration", "2", "--foxglove", str(port))
        code, stderr = stop_node(proc)
    assert code == 2
    # the one line of the error (pybullet prints its build time when it is imported)
    lines = [line for line in stderr.splitlines() if not line.startswith("pybullet build time")]
    assert lines == [f"cdw-twin: error: --foxglove: port {port} on 127.0.0.1 is in use"]
    assert not out.exists(), "the episode started although its live view could not"


def free_port() -> int:
    """A port nothing listens on right now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def connect_new_session(port: int, seen: list[str], timeout_s: float) -> tuple[WsClient, str]:
    """Connect once a server whose session is not in ``seen`` listens on ``port``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            client = WsClient("127.0.0.1", port)
            session = str(client.recv_json()["sessionId"])
        except (ConnectionError, TimeoutError):
            time.sleep(0.2)
            continue
        if session not in seen:
            return client, session
        client.close()
        time.sleep(0.2)
    pytest.fail(f"no new live view on port {port} within {timeout_s} s (seen {seen})")


@pytest.mark.slow
@pytest.mark.usefixtures("require_interfaces")
def test_a_run_serves_each_episode_in_turn_on_one_port(
    builtin_meshes: Path, tmp_path: Path
) -> None:
    port = free_port()
    out = tmp_path / "run"
    runner = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "run",
            "--dataset",
            str(builtin_meshes),
            "--duration",
            "4",
            "--episodes",
            "2",
            "--out",
            str(out),
            "--foxglove",
            str(port),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    sessions: list[str] = []
    received: list[Received] = []
    wanted = ["/clock", "/objects/ground_truth", *SCENE_TOPICS]
    try:
        for _ in range(2):
            client, session = connect_new_session(port, sessions, START_TIMEOUT_S)
            sessions.append(session)
            advertise = client.recv_json()
            names = {c["id"]: c["topic"] for c in advertise["channels"]}
            ids = {c["topic"]: c["id"] for c in advertise["channels"]}
            subs = {s: names[c] for s, c in client.subscribe([ids[t] for t in wanted]).items()}
            got = Received()
            receive_until(client, subs, got, wanted, 30.0)
            received.append(got)
            client.close()
        stdout, stderr = runner.communicate(timeout=120)
    finally:
        if runner.poll() is None:
            runner.kill()
            runner.communicate()
    assert runner.returncode == 0, stderr[-2000:]
    assert f"live view on ws://127.0.0.1:{port}" in stdout
    assert len(set(sessions)) == 2
    for i, got in enumerate(received):
        missing = [t for t in wanted if t not in got.by_topic]
        assert not missing, f"episode {i}: no message on {missing}"
    assert json.loads((out / "run.json").read_text(encoding="utf-8"))["complete"] is True
    # the same tap fed the recording: every topic served live is in it too
    from mcap.reader import make_reader

    for episode in ("ep000", "ep001"):
        with (out / episode / "recording.mcap").open("rb") as handle:
            summary = make_reader(handle).get_summary()
        assert summary is not None
        assert summary.statistics is not None
        per_channel = summary.statistics.channel_message_counts
        counts = {summary.channels[cid].topic: n for cid, n in per_channel.items()}
        assert all(counts.get(t, 0) > 0 for t in wanted), counts


def test_a_run_refuses_a_port_in_use_before_it_starts(builtin_meshes: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = subprocess.run(
            [
                sys.executable,
                "-m",
                "twin.cli",
                "run",
                "--dataset",
                str(builtin_meshes),
                "--out",
                str(out),
                "--foxglove",
                str(port),
            ],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
    assert result.returncode == 2
    lines = [ln for ln in result.stderr.splitlines() if not ln.startswith("pybullet build time")]
    assert lines == [f"cdw-twin: error: --foxglove: port {port} on 127.0.0.1 is in use"]
    assert not out.exists()


def test_a_late_subscriber_gets_the_kept_messages_of_latched_topics() -> None:
    """The view alone (no node): each latched topic's last ``depth`` messages reach a client
    that subscribes after they were sent, in order; a volatile topic's do not. The view says
    which topics a client subscribed to."""
    from interfaces.contract import BINS, CLOCK_TOPIC, EVENTS_TOPIC
    from twin.live_view import LiveView

    view = LiveView(
        [(CLOCK_TOPIC.name, CLOCK_TOPIC), (EVENTS_TOPIC.name, EVENTS_TOPIC), ("/bins", BINS)],
        port=0,
    )
    try:
        for i in range(3):
            view.write("/bins", f"bins {i}".encode(), 100 + i)  # keep last 1
            view.write("/events", f"event {i}".encode(), 200 + i)  # keep last 1000
            view.write("/clock", f"clock {i}".encode(), 300 + i)  # volatile
        assert not view.wants("/bins")  # no client yet
        client = WsClient("127.0.0.1", view.port)
        client.recv_json()
        channels = {c["topic"]: c["id"] for c in client.recv_json()["channels"]}
        names = {i: t for t, i in channels.items()}
        subs = {s: names[c] for s, c in client.subscribe(list(channels.values())).items()}
        deadline = time.monotonic() + 10.0
        while not view.wants("/bins") and time.monotonic() < deadline:
            time.sleep(0.05)
        assert view.wants("/bins")
        assert not view.wants("/no/such/topic")
        received = Received()
        deadline = time.monotonic() + 10.0
        client.sock.settimeout(0.2)
        # the view sends the kept messages at its next write (from the node's thread)
        while time.monotonic() < deadline and (
            "/bins" not in received.by_topic or len(received.by_topic.get("/events", ())) < 3
        ):
            view.write("/clock", b"clock 3", 303)
            receive_until(client, subs, received, ["/bins", "/events"], 0.2, count=3)
        client.close()
    finally:
        view.close()
    assert received.by_topic["/bins"] == [(102, b"bins 2")]
    assert received.by_topic["/events"] == [(200, b"event 0"), (201, b"event 1"), (202, b"event 2")]
    assert {m for _, m in received.by_topic["/clock"]} == {b"clock 3"}
