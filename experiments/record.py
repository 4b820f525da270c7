"""``cdw-twin record OUT``: record every topic of a cell's contract to one MCAP file.

Example (next to a running twin and controller, same ``ROS_DOMAIN_ID``)::

    cdw-twin record runs/ep0/recording.mcap                 # the default cell
    cdw-twin record runs/ep0/recording.mcap --cell two_pandas

SIGINT or SIGTERM ends it, exit status 0. ``cdw-twin run`` does not need it: the twin node
records its own episodes (:mod:`twin.recording`, whose writer this recorder uses too).

The recorder subscribes to every topic of ``docs/interfaces.md`` for the cell's station
namespaces (:func:`interfaces.contract.resolved_topics`: cell topics once, station topics once
per station) with raw subscriptions (the serialized CDR bytes are written as they arrive;
nothing is deserialized) and the QoS of the contract, so it matches each publisher: best
effort for ``/clock`` and ``/objects/ground_truth``, reliable transient local for ``/events``
and the latched topics (a late start still gets the event history, the priorities and the
bins), reliable volatile for the rest. The file format is :class:`twin.recording.McapRecording`'s.

Times: ``log_time`` is the receive wall time (ns since the Unix epoch). ``publish_time`` is the
same receive time: the EventsExecutor cannot hand the middleware's source timestamp to a
callback, and a header's sim-time stamp would put another epoch into the same field; the stamps
stay in the messages (see :func:`experiments.offline.read_topic`).

Crash safety: the file is written as ``OUT.partial`` and renamed to ``OUT`` when the recorder
stops cleanly. The chunk in progress is closed and flushed every ``--flush-interval`` seconds
(0.5 s), so after a SIGKILL ``OUT.partial`` holds everything up to that interval before the
kill; :func:`experiments.offline.read_topic` reads it up to the cut and
:func:`recover_recording` rewrites it as a complete ``OUT`` for tools that need an index.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import signal
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from types import FrameType
from typing import Any

from interfaces.contract import JOINT_STATES, LOCKSTEP_TICK, Topic, resolved_topics
from twin.recording import (
    DEFAULT_FLUSH_INTERVAL_S,
    PARTIAL_SUFFIX,
    McapRecording,
    RecordingError,
    message_definition,
)

RECORDER_QUEUE_DEPTH = 1000
MATCH_CHECK_S = 0.05

TOPICS: list[tuple[str, Topic]] = resolved_topics(("",))
"""Every topic of a one-station cell whose station has the empty namespace (the default
cell), as ``(wire name, topic)``; other cells: ``resolved_topics(namespaces)``."""

DEFERRED: tuple[Topic, ...] = (LOCKSTEP_TICK,)
"""Subscribed only once the first joint state arrives (the twin is stepping).

A lockstep twin starts as soon as every topic a tick counts has a matched subscriber, and would
take a recorder for its controller: it would step before the controller is matched and the
controller would never see tick 0. Joining ``/lockstep/tick`` late leaves that decision to the
controller; the recording then lacks the first few ticks (the handshake, not the cell's state).
"""


def cell_namespaces(cell: str | Path | None) -> tuple[str, ...]:
    """The station namespaces of the cell ``cell`` names (a shipped name, a path, None: the
    default cell)."""
    from interfaces.cell import load_cell

    return tuple(s.namespace for s in load_cell(cell).stations)


def recover_recording(partial: Path, out: Path | None = None) -> Path:
    """Rewrite a crashed recording (``OUT.partial``, no footer) as a complete MCAP at ``out``.

    Every message up to the cut is kept; the result is written atomically (default ``out``: the
    name without ``.partial``). Returns the path written.
    """
    if out is None:
        if not partial.name.endswith(PARTIAL_SUFFIX):
            msg = f"{partial} does not end in {PARTIAL_SUFFIX}; pass out="
            raise RecordingError(msg)
        out = partial.with_name(partial.name.removesuffix(PARTIAL_SUFFIX))
    tmp = out.with_name(f".{out.name}.tmp")
    try:
        with partial.open("rb") as src, tmp.open("wb") as dst:
            _copy_messages(src, dst)
        tmp.replace(out)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return out


def _copy_messages(src: Any, dst: Any) -> None:
    """Copy every readable message of the MCAP stream ``src`` into a new MCAP on ``dst``."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader
    from mcap.writer import Writer

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


# -- the process --------------------------------------------------------------------------------
def recorder_command(
    out: Path, *, flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S, cell: str | Path | None = None
) -> list[str]:
    """The argv that starts a recorder of ``out`` as a subprocess (stop it with SIGINT/SIGTERM).

    On its stdout the process prints ``recording <OUT.partial>`` once it has subscribed to every
    topic, ``matched <topic>`` the first time a topic has a publisher, and one JSON line of
    statistics (messages, bytes, CPU seconds) when it has finished the file.

    Start protocol: a publisher sends volatile messages only to the subscriptions it has already
    matched, and a lockstep twin steps once its controller has matched (the recorder joins
    ``/lockstep/tick`` late so it never starts the twin itself, see :data:`DEFERRED`). To
    record from step 0: start the recorder and the twin, wait for the recorder's ``matched
    /joint_states`` (and ``/tcp_pose``, ``/conveyor/state``, ``/objects/detections``), then start
    the controller. Stop protocol: SIGINT or SIGTERM; the file is finished, renamed from
    ``OUT.partial`` to ``OUT``, and the process exits 0.
    """
    cmd = [sys.executable, "-m", "twin.cli", "record", str(out)]
    cmd += ["--flush-interval", str(flush_interval_s)]
    if cell is not None:
        cmd += ["--cell", str(cell)]
    return cmd


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the recorder's options."""
    parser.add_argument("out", type=Path, help="the MCAP file to write (ends in .mcap)")
    parser.add_argument(
        "--flush-interval",
        type=float,
        default=DEFAULT_FLUSH_INTERVAL_S,
        help="seconds between chunk flushes: what a SIGKILL may lose at most (default 0.5)",
    )
    parser.add_argument(
        "--cell",
        default=None,
        help="the cell file (a shipped name or a path) whose station topics to record "
        "(default: the default cell)",
    )


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


class _Recorder:
    """The recorder node: raw subscriptions writing into ``recording``, deferred ones joined
    once ``first`` (a station's joint states) has a message, ``matched`` lines printed."""

    def __init__(self, node: Any, recording: McapRecording, topics: list[tuple[str, Topic]]):
        self.node = node
        self.recording = recording
        self.unmatched: dict[str, Any] = {}
        self.deferred = [(name, t) for name, t in topics if t in DEFERRED]
        self.first = next(name for name, t in topics if t == JOINT_STATES)
        for name, topic in topics:
            if topic not in DEFERRED:
                self.subscribe(name, topic)

    def subscribe(self, name: str, topic: Topic) -> None:
        """A raw subscription to ``name`` writing every message's bytes as it arrives."""
        from interfaces.ros import message_class, qos_profile

        write, now_ns = self.recording.write, time.time_ns

        def callback(data: bytes, wire: str = name) -> None:
            write(wire, data, now_ns())

        qos = dataclasses.replace(topic.qos, depth=max(topic.qos.depth, RECORDER_QUEUE_DEPTH))
        self.unmatched[name] = self.node.create_subscription(
            message_class(topic), name, callback, qos_profile(qos), raw=True
        )

    def check(self) -> None:
        """Join the deferred topics once the twin steps; report newly matched topics."""
        if self.deferred and self.recording.counts[self.first] > 0:
            for name, topic in self.deferred:
                self.subscribe(name, topic)
            self.deferred = []
        for name in [n for n, s in self.unmatched.items() if s.get_publisher_count() > 0]:
            del self.unmatched[name]
            print(f"matched {name}", flush=True)


def _record(
    recording: McapRecording,
    topics: list[tuple[str, Topic]],
    flush_interval_s: float,
    stop: dict[str, bool],
) -> None:
    """Spin the recorder until ``stop`` is requested, flushing every ``flush_interval_s``."""
    import rclpy
    from rclpy.experimental.events_executor import EventsExecutor
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("cdw_recorder")
    recorder = _Recorder(node, recording, topics)
    executor = EventsExecutor()
    executor.add_node(node)
    print(f"recording {recording.partial}", flush=True)
    next_flush = next_check = time.monotonic()
    while not stop["requested"]:
        executor.spin_once(timeout_sec=MATCH_CHECK_S)
        if time.monotonic() >= next_check:
            recorder.check()
            next_check = time.monotonic() + MATCH_CHECK_S
        if time.monotonic() >= next_flush:
            recording.flush()
            next_flush = time.monotonic() + flush_interval_s
    drain_until = time.monotonic() + 0.2
    while time.monotonic() < drain_until:
        executor.spin_once(timeout_sec=0.02)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()


def run(args: argparse.Namespace) -> int:
    """Record until SIGINT or SIGTERM; finish the file; exit 0."""
    from interfaces.ros import message_class
    from twin.ros_isolation import clean_stale_fastdds_shm, local_ros_defaults

    if not args.flush_interval > 0:
        msg = f"--flush-interval {args.flush_interval!r} must be > 0 s"
        raise RecordingError(msg)
    topics = resolved_topics(cell_namespaces(args.cell))
    for _, topic in topics:
        try:
            message_class(topic)
        except (ImportError, AttributeError) as exc:
            msg = f"message type {topic.msgtype} is not importable ({exc})"
            raise RecordingError(msg) from exc
    local_ros_defaults()
    clean_stale_fastdds_shm()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    with _stop_on_signals() as stop:
        recording = McapRecording(args.out, topics, library="cdw-twin record")
        _record(recording, topics, args.flush_interval, stop)
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
    "DEFAULT_FLUSH_INTERVAL_S",
    "TOPICS",
    "McapRecording",
    "RecordingError",
    "cell_namespaces",
    "configure",
    "message_definition",
    "recorder_command",
    "recover_recording",
    "run",
]
