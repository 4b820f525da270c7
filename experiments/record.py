"""``cdw-twin record OUT``: record every topic of the cell contract to one MCAP file.

Example (next to a running twin and controller, same ``ROS_DOMAIN_ID``)::

    cdw-twin record runs/ep0/recording.mcap        # SIGINT or SIGTERM ends it, exit status 0

The recorder subscribes to every topic of ``docs/interfaces.md`` with raw subscriptions (the
serialized CDR bytes are written as they arrive; nothing is deserialized) and QoS that matches
each publisher: best effort for ``/clock`` and ``/objects/ground_truth``, reliable transient local
for ``/events`` and ``/sorting/priorities`` (so a late start still gets the event history and the
priorities), reliable volatile for the rest. The file is a ROS 2 MCAP (profile ``ros2``, schemas
``ros2msg`` with the ``====``/``MSG:`` dependency sections rosbag2 writes, message encoding
``cdr``, channel metadata ``offered_qos_profiles``), readable by ``mcap_ros2``, by rosbags'
``AnyReader([Path("x.mcap")])`` (no ``metadata.yaml`` needed: rosbags 0.11 reads a bare ``.mcap``
and learns the ``cdw_interfaces`` types from the embedded schemas) and by Foxglove.

Times: ``log_time`` is the receive wall time (ns since the Unix epoch). ``publish_time`` is the
same receive time: the EventsExecutor cannot hand the middleware's source timestamp to a
callback, and a header's sim-time stamp would put another epoch into the same field; the stamps
stay in the messages (see :func:`experiments.offline.read_topic`).

Crash safety: the file is written as ``OUT.partial`` and renamed to ``OUT`` when the recorder
stops cleanly, so a file named ``OUT`` is always complete (with its summary and index). The
chunk in progress is closed and flushed every ``--flush-interval`` seconds (0.5 s), so after a
SIGKILL ``OUT.partial`` holds everything up to that interval before the kill. Such a file has no
footer: :func:`experiments.offline.read_topic` reads it with the non-seeking reader and stops at
the cut; :func:`recover_recording` rewrites it as a complete ``OUT`` for tools that need an index.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import math
import os
import re
import signal
import sys
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import IO, Any

import yaml

from twin.errors import CdwTwinError

PARTIAL_SUFFIX = ".partial"
DEFAULT_FLUSH_INTERVAL_S = 0.5
RECORDER_QUEUE_DEPTH = 1000
MATCH_CHECK_S = 0.05
SEPARATOR = "=" * 80
_PRIMITIVES = frozenset(
    {
        "bool",
        "byte",
        "char",
        "float32",
        "float64",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "string",
        "wstring",
    }
)
_INFINITE = {"sec": 9223372036, "nsec": 854775807}


class RecordingError(CdwTwinError):
    """A recording cannot be written or read (bad path, missing message definition, no data)."""


@dataclass(frozen=True, kw_only=True)
class TopicSpec:
    """One recorded topic: name, ROS 2 type (``pkg/msg/Type``) and the publisher's QoS."""

    name: str
    msgtype: str
    reliable: bool = True
    latched: bool = False
    depth: int = 10


TOPICS: tuple[TopicSpec, ...] = (
    TopicSpec(name="/clock", msgtype="rosgraph_msgs/msg/Clock", reliable=False, depth=1),
    TopicSpec(name="/joint_states", msgtype="sensor_msgs/msg/JointState"),
    TopicSpec(name="/tcp_pose", msgtype="geometry_msgs/msg/PoseStamped"),
    TopicSpec(name="/conveyor/state", msgtype="cdw_interfaces/msg/BeltState"),
    TopicSpec(name="/objects/detections", msgtype="cdw_interfaces/msg/DetectionArray"),
    TopicSpec(
        name="/objects/ground_truth",
        msgtype="cdw_interfaces/msg/ObjectStateArray",
        reliable=False,
        depth=1,
    ),
    TopicSpec(name="/events", msgtype="cdw_interfaces/msg/SortingEvent", latched=True, depth=1000),
    TopicSpec(name="/twin/faults", msgtype="std_msgs/msg/String", depth=100),
    TopicSpec(name="/lockstep/tick", msgtype="cdw_interfaces/msg/LockstepTick", depth=100),
    TopicSpec(name="/lockstep/ack", msgtype="cdw_interfaces/msg/StepAck", depth=100),
    TopicSpec(
        name="/arm_controller/joint_trajectory", msgtype="trajectory_msgs/msg/JointTrajectory"
    ),
    TopicSpec(name="/gripper/command", msgtype="std_msgs/msg/Float64"),
    TopicSpec(name="/controller/target", msgtype="cdw_interfaces/msg/PickTarget"),
    TopicSpec(name="/conveyor/speed_setpoint", msgtype="std_msgs/msg/Float64"),
    TopicSpec(
        name="/sorting/priorities",
        msgtype="cdw_interfaces/msg/SortingPriorities",
        latched=True,
        depth=1,
    ),
    TopicSpec(name="/cell/bins", msgtype="cdw_interfaces/msg/SortingBins", latched=True, depth=1),
    TopicSpec(name="/ping", msgtype="cdw_interfaces/msg/Ping", depth=100),
    TopicSpec(name="/ping/echo", msgtype="cdw_interfaces/msg/Ping", depth=100),
)
"""Every topic of ``docs/interfaces.md`` with the QoS its publisher offers."""

DEFERRED_TOPICS = frozenset({"/lockstep/tick"})
"""Subscribed only once the first ``/joint_states`` arrives (the twin is stepping).

A lockstep twin starts as soon as every topic a tick counts has a matched subscriber, and would
take a recorder for its controller: it would step before the controller is matched and the
controller would never see tick 0. Joining ``/lockstep/tick`` late leaves that decision to the
controller; the recording then lacks the first few ticks (the handshake, not the cell's state).
"""


# -- message definitions ------------------------------------------------------------------------
def share_dirs() -> list[Path]:
    """Where ``<pkg>/msg/<Type>.msg`` files are looked up: ``AMENT_PREFIX_PATH``, then the venv."""
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(Path(sys.prefix))
    return [p / "share" for p in prefixes]


def _split_type(msgtype: str) -> tuple[str, str]:
    parts = msgtype.split("/")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[1] != "msg"):
        msg = f"message type {msgtype!r} is not 'pkg/msg/Type' or 'pkg/Type'"
        raise RecordingError(msg)
    return parts[0], parts[-1]


def _msg_text(package: str, name: str, dirs: Sequence[Path]) -> str:
    for share in dirs:
        path = share / package / "msg" / f"{name}.msg"
        if path.is_file():
            return path.read_text(encoding="utf-8")
    searched = ", ".join(str(d / package / "msg" / f"{name}.msg") for d in dirs)
    msg = f"no message definition for {package}/{name}: searched {searched}"
    raise RecordingError(msg)


def _field_types(text: str, package: str) -> list[tuple[str, str]]:
    """The non-primitive (package, Type) of every field or constant in a ``.msg`` text."""
    found: list[tuple[str, str]] = []
    for line in text.splitlines():
        code = line.split("#", 1)[0].strip()
        if not code:
            continue
        base = re.sub(r"\[.*\]$", "", code.split()[0])
        base = base.split("<=", 1)[0]
        if base in _PRIMITIVES:
            continue
        if "/" in base:
            found.append(_split_type(base))
        elif base == "Header":
            found.append(("std_msgs", "Header"))
        else:
            found.append((package, base))
    return found


def message_definition(msgtype: str, dirs: Sequence[Path] | None = None) -> str:
    """The ``ros2msg`` schema text of ``msgtype`` as rosbag2 writes it.

    The type's own ``.msg`` text, then each type it depends on (depth first, once each) after a
    line of 80 ``=`` and a ``MSG: pkg/Type`` line.
    """
    dirs = share_dirs() if dirs is None else dirs
    package, name = _split_type(msgtype)
    root = _msg_text(package, name, dirs)
    seen = {(package, name)}
    sections: list[str] = []
    stack = list(reversed(_field_types(root, package)))
    while stack:
        dep = stack.pop()
        if dep in seen:
            continue
        seen.add(dep)
        text = _msg_text(*dep, dirs)
        sections.append(f"{SEPARATOR}\nMSG: {dep[0]}/{dep[1]}\n{text}")
        stack.extend(reversed(_field_types(text, dep[0])))
    return "\n".join([root.rstrip("\n"), *(s.rstrip("\n") for s in sections)]) + "\n"


def offered_qos_yaml(spec: TopicSpec) -> str:
    """The ``offered_qos_profiles`` channel metadata rosbag2 (Jazzy) writes, for ``spec``."""
    profile = {
        "history": "keep_last",
        "depth": spec.depth,
        "reliability": "reliable" if spec.reliable else "best_effort",
        "durability": "transient_local" if spec.latched else "volatile",
        "deadline": _INFINITE,
        "lifespan": _INFINITE,
        "liveliness": "automatic",
        "liveliness_lease_duration": _INFINITE,
        "avoid_ros_namespace_conventions": False,
    }
    return yaml.safe_dump([profile], sort_keys=False)


# -- the file -----------------------------------------------------------------------------------
def partial_path(out: Path) -> Path:
    """Where the recording of ``out`` is written until it is finished cleanly."""
    return out.with_name(out.name + PARTIAL_SUFFIX)


class McapRecording:
    """An open ROS 2 MCAP file taking raw CDR messages; :meth:`close` renames it into place.

    With ``flush_interval_s``, :meth:`write` also flushes once that long has passed since the
    last flush (for a writer with no loop of its own, such as the twin node's tap).
    """

    def __init__(
        self,
        out: Path,
        topics: Iterable[TopicSpec],
        dirs: Sequence[Path] | None = None,
        *,
        flush_interval_s: float | None = None,
    ):
        from mcap.writer import CompressionType, Writer

        if out.suffix != ".mcap":
            msg = f"recording path {out} must end in .mcap"
            raise RecordingError(msg)
        self.out = out
        self.partial = partial_path(out)
        out.parent.mkdir(parents=True, exist_ok=True)
        self._stream: IO[bytes] = self.partial.open("wb")
        self._writer = Writer(self._stream, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library="cdw-twin record")
        self.channels: dict[str, int] = {}
        self.counts: dict[str, int] = {}
        self.n_bytes = 0
        schema_ids: dict[str, int] = {}
        for spec in topics:
            if spec.msgtype not in schema_ids:
                text = message_definition(spec.msgtype, dirs)
                schema_ids[spec.msgtype] = self._writer.register_schema(
                    name=spec.msgtype, encoding="ros2msg", data=text.encode()
                )
            self.channels[spec.name] = self._writer.register_channel(
                topic=spec.name,
                message_encoding="cdr",
                schema_id=schema_ids[spec.msgtype],
                metadata={"offered_qos_profiles": offered_qos_yaml(spec)},
            )
            self.counts[spec.name] = 0
        self._flush_interval_s = flush_interval_s
        self._next_flush = math.inf
        self.flush()

    def write(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Append one serialized message received at ``log_time_ns``."""
        self._writer.add_message(
            self.channels[topic], log_time=log_time_ns, data=data, publish_time=log_time_ns
        )
        self.counts[topic] += 1
        self.n_bytes += len(data)
        if time.monotonic() >= self._next_flush:
            self.flush()

    def flush(self) -> None:
        """Close the chunk in progress and hand everything to the operating system."""
        self._writer.flush()
        if self._flush_interval_s is not None:
            self._next_flush = time.monotonic() + self._flush_interval_s

    def close(self) -> Path:
        """Write the summary and footer, close, rename ``OUT.partial`` to ``OUT``; returns OUT."""
        self._writer.finish()
        self._stream.close()
        self.partial.replace(self.out)
        return self.out


def recover_recording(partial: Path, out: Path | None = None) -> Path:
    """Rewrite a crashed recording (``OUT.partial``, no footer) as a complete MCAP at ``out``.

    Every message up to the cut is kept; the result is written atomically (default ``out``: the
    name without ``.partial``). Returns the path written.
    """
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader
    from mcap.writer import Writer

    if out is None:
        if not partial.name.endswith(PARTIAL_SUFFIX):
            msg = f"{partial} does not end in {PARTIAL_SUFFIX}; pass out="
            raise RecordingError(msg)
        out = partial.with_name(partial.name.removesuffix(PARTIAL_SUFFIX))
    tmp = out.with_name(f".{out.name}.tmp")
    try:
        with partial.open("rb") as src, tmp.open("wb") as dst:
            writer = Writer(dst)
            writer.start(profile="ros2", library="cdw-twin record (recovered)")
            schemas: dict[int, int] = {}
            channels: dict[int, int] = {}
            reader = NonSeekingReader(src)
            with contextlib.suppress(McapError):
                for schema, channel, message in reader.iter_messages(log_time_order=False):
                    if channel.id not in channels:
                        schema_id = 0
                        if schema is not None:
                            if schema.id not in schemas:
                                schemas[schema.id] = writer.register_schema(
                                    schema.name, schema.encoding, schema.data
                                )
                            schema_id = schemas[schema.id]
                        channels[channel.id] = writer.register_channel(
                            channel.topic, channel.message_encoding, schema_id, channel.metadata
                        )
                    writer.add_message(
                        channels[channel.id],
                        log_time=message.log_time,
                        data=message.data,
                        publish_time=message.publish_time,
                        sequence=message.sequence,
                    )
            writer.finish()
        tmp.replace(out)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return out


# -- the process --------------------------------------------------------------------------------
def recorder_command(out: Path, *, flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S) -> list[str]:
    """The argv that starts a recorder of ``out`` as a subprocess (stop it with SIGINT/SIGTERM).

    On its stdout the process prints ``recording <OUT.partial>`` once it has subscribed to every
    topic, ``matched <topic>`` the first time a topic has a publisher, and one JSON line of
    statistics (messages, bytes, CPU seconds) when it has finished the file.

    Start protocol: a publisher sends volatile messages only to the subscriptions it has already
    matched, and a lockstep twin steps once its controller has matched (the recorder joins
    ``/lockstep/tick`` late so it never starts the twin itself, see :data:`DEFERRED_TOPICS`). To
    record from step 0: start the recorder and the twin, wait for the recorder's ``matched
    /joint_states`` (and ``/tcp_pose``, ``/conveyor/state``, ``/objects/detections``), then start
    the controller. Stop protocol: SIGINT or SIGTERM; the file is finished, renamed from
    ``OUT.partial`` to ``OUT``, and the process exits 0.
    """
    return [
        sys.executable,
        "-m",
        "twin.cli",
        "record",
        str(out),
        "--flush-interval",
        str(flush_interval_s),
    ]


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the recorder's options."""
    parser.add_argument("out", type=Path, help="the MCAP file to write (ends in .mcap)")
    parser.add_argument(
        "--flush-interval",
        type=float,
        default=DEFAULT_FLUSH_INTERVAL_S,
        help="seconds between chunk flushes: what a SIGKILL may lose at most (default 0.5)",
    )


def _qos(spec: TopicSpec) -> Any:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=max(spec.depth, RECORDER_QUEUE_DEPTH),
        reliability=ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if spec.latched else DurabilityPolicy.VOLATILE,
    )


def _message_class(msgtype: str) -> Any:
    package, name = _split_type(msgtype)
    try:
        return getattr(importlib.import_module(f"{package}.msg"), name)
    except (ImportError, AttributeError) as exc:
        msg = f"message type {msgtype} is not importable ({exc})"
        raise RecordingError(msg) from exc


@contextlib.contextmanager
def _stop_on_signals() -> Iterator[dict[str, bool]]:
    stop = {"requested": False}

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop["requested"] = True

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def run(args: argparse.Namespace) -> int:
    """Record until SIGINT or SIGTERM; finish the file; exit 0."""
    import rclpy
    from rclpy.experimental.events_executor import EventsExecutor
    from rclpy.signals import SignalHandlerOptions

    from twin.ros_isolation import clean_stale_fastdds_shm, local_ros_defaults

    if not args.flush_interval > 0:
        msg = f"--flush-interval {args.flush_interval!r} must be > 0 s"
        raise RecordingError(msg)
    local_ros_defaults()
    clean_stale_fastdds_shm()
    classes = {spec.msgtype: _message_class(spec.msgtype) for spec in TOPICS}
    wall0, cpu0 = time.perf_counter(), time.process_time()
    with _stop_on_signals() as stop:
        recording = McapRecording(args.out, TOPICS)
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node("cdw_recorder")
        write, now_ns = recording.write, time.time_ns
        unmatched: dict[str, Any] = {}

        def subscribe(spec: TopicSpec) -> None:
            def callback(data: bytes, topic: str = spec.name) -> None:
                write(topic, data, now_ns())

            unmatched[spec.name] = node.create_subscription(
                classes[spec.msgtype], spec.name, callback, _qos(spec), raw=True
            )

        deferred = [spec for spec in TOPICS if spec.name in DEFERRED_TOPICS]
        for spec in TOPICS:
            if spec not in deferred:
                subscribe(spec)
        executor = EventsExecutor()
        executor.add_node(node)
        print(f"recording {recording.partial}", flush=True)
        next_flush = next_check = time.monotonic()
        while not stop["requested"]:
            executor.spin_once(timeout_sec=MATCH_CHECK_S)
            if time.monotonic() >= next_check:
                if deferred and recording.counts["/joint_states"] > 0:
                    for spec in deferred:
                        subscribe(spec)
                    deferred = []
                for topic in [t for t, s in unmatched.items() if s.get_publisher_count() > 0]:
                    del unmatched[topic]
                    print(f"matched {topic}", flush=True)
                next_check = time.monotonic() + MATCH_CHECK_S
            if time.monotonic() >= next_flush:
                recording.flush()
                next_flush = time.monotonic() + args.flush_interval
        drain_until = time.monotonic() + 0.2
        while time.monotonic() < drain_until:
            executor.spin_once(timeout_sec=0.02)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown()
        out = recording.close()
    wall_s = time.perf_counter() - wall0
    cpu_s = time.process_time() - cpu0
    stats = {
        "out": str(out),
        "messages": sum(recording.counts.values()),
        "payload_bytes": recording.n_bytes,
        "file_bytes": out.stat().st_size,
        "wall_s": round(wall_s, 3),
        "cpu_s": round(cpu_s, 3),
        "cpu_fraction": round(cpu_s / wall_s, 4) if wall_s > 0 else 0.0,
        "counts": recording.counts,
    }
    print(json.dumps(stats, sort_keys=True), flush=True)
    return 0


__all__ = [
    "TOPICS",
    "McapRecording",
    "RecordingError",
    "TopicSpec",
    "configure",
    "message_definition",
    "recorder_command",
    "recover_recording",
    "run",
]
