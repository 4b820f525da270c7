"""Metrics recomputed offline from a recording, with the metric table's own functions.

The twin scores an episode from its events alone (:func:`interfaces.metrics.count_events`,
:func:`interfaces.metrics.event_scores`); every event goes out on ``/events``, so the recording
is enough to recompute the scores exactly, for the line and for each station::

    from experiments.offline import offline_metrics, read_topic
    metrics = offline_metrics(Path("runs/a/ep000/recording.mcap"), Path("runs/a/cell.yaml"))
    metrics.scores                          # == summary.json["scores"]
    metrics.stations["upstream"]            # == summary.json["stations"]["upstream"]["scores"]
    metrics.bins["upstream"]["brick"]       # the purity of upstream's brick bin
    metrics.mismatches(row)                 # [] for the episode's row of episodes.json
    for log_time_ns, msg in read_topic(Path("runs/ep0/recording.mcap"), "/conveyor/state"):
        msg.header.stamp.sec, msg.speed_mps

What a recording cannot give:

- ``step`` of an event: ``SortingEvent`` carries no step; it is rebuilt as
  ``round(time_s * physics_hz)``. Scores do not use it.
- the episode duration (the twin scores with ``step_count * (1 / physics_hz)``) is rebuilt from
  the joint-state stamps (``/joint_states``, or a station's ``/<ns>/joint_states``: every
  station publishes one per physics step with the same stamp): ``physics_hz`` is the
  rounded inverse of their median spacing (an integer rate is assumed) and the step count is the
  last stamp times that rate. So the recording must run until the twin's last step.
- the tracking time to 4 mm: the twin measures it every physics step against the true pose of the
  pursued object, from the moment a ``PickTarget`` reaches it. The recording holds ground truth
  at 30 Hz over a best-effort topic and the targets' send times, not the twin's receive step, so
  the twin's tracking results cannot be reproduced exactly; ``tracking_note`` says why.

Partial recordings (``OUT.partial`` left by a killed recorder, no footer) are read up to the cut.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import statistics
import struct
from collections import Counter
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from interfaces.contract import EVENTS_TOPIC, JOINT_STATES
from interfaces.run_records import EpisodeMetrics, EventScores, Metrics, ScopeMetrics
from twin.recording import RecordingError

TRACKING_NOTE = (
    "not recomputable: the twin measures tracking every physics step against the true pose "
    "from the step a PickTarget arrives; the recording has ground truth at 30 Hz (best effort) "
    "and target send times only"
)
_MAGIC = b"\x89MCAP0\r\n"


def is_complete(recording: Path) -> bool:
    """Whether ``recording`` was finished cleanly (it ends in a footer and the MCAP magic)."""
    with recording.open("rb") as handle:
        size = handle.seek(0, 2)
        if size < 2 * len(_MAGIC):
            return False
        handle.seek(-len(_MAGIC), 2)
        return handle.read() == _MAGIC


def iter_raw(
    recording: Path, topics: Iterable[str] | None = None
) -> Iterator[tuple[Any, Any, Any]]:
    """``(schema, channel, message)`` records of ``recording`` (mcap types), raw CDR data.

    A complete file is read through its index in log-time order; a partial one (no footer)
    in file order with the non-seeking reader, up to the last whole chunk.
    """
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader, SeekingReader

    if not recording.is_file():
        msg = f"recording {recording} does not exist"
        raise RecordingError(msg)
    wanted = None if topics is None else list(topics)
    complete = is_complete(recording)
    with recording.open("rb") as handle:
        if complete:
            yield from SeekingReader(handle).iter_messages(topics=wanted)
            return
        reader = NonSeekingReader(handle)
        try:
            yield from reader.iter_messages(topics=wanted, log_time_order=False)
        except (McapError, EOFError):
            return


def read_topic(recording: Path, topic: str) -> Iterator[tuple[int, Any]]:
    """``(log_time_ns, message)`` of every recorded message on ``topic``, decoded.

    Messages are ``mcap_ros2`` dynamic objects with the ROS field names
    (``msg.header.stamp.sec``, ``msg.speed_mps``, ``msg.clock.nanosec``).
    """
    from mcap_ros2.decoder import DecoderFactory

    factory = DecoderFactory()
    for schema, channel, message in iter_raw(recording, [topic]):
        decode = factory.decoder_for(channel.message_encoding, schema)
        if decode is None:
            msg = f"{recording}: topic {topic} has no ros2msg schema to decode it with"
            raise RecordingError(msg)
        yield message.log_time, decode(message.data)


def header_stamp_ns(data: bytes) -> int:
    """The stamp (ns) of a CDR message whose first field is a ``Header`` or a ``Time``."""
    if len(data) < 12:
        msg = f"CDR message of {len(data)} bytes is too short for a stamp"
        raise RecordingError(msg)
    order = "<" if data[1] & 1 else ">"
    sec, nanosec = struct.unpack_from(f"{order}iI", data, 4)
    return int(sec) * 1_000_000_000 + int(nanosec)


@dataclasses.dataclass(frozen=True, kw_only=True)
class EpisodeClock:
    """The physics rate and the last step, rebuilt from the per-step ``/joint_states`` stamps."""

    physics_hz: float
    steps: int

    @property
    def duration_s(self) -> float:
        """Simulated seconds, computed as the twin computes them: ``steps * (1 / hz)``."""
        return self.steps * (1.0 / self.physics_hz)


def episode_clock(stamps_ns: list[int], recording: Path) -> EpisodeClock:
    """The clock of an episode from its ``/joint_states`` stamps (ns, at least two distinct)."""
    ordered = sorted(set(stamps_ns))
    gaps = [b - a for a, b in itertools.pairwise(ordered)]
    if not gaps:
        msg = f"{recording}: fewer than two /joint_states stamps; cannot tell the physics rate"
        raise RecordingError(msg)
    hz = float(round(1e9 / statistics.median(gaps)))
    return EpisodeClock(physics_hz=hz, steps=round(ordered[-1] * hz / 1e9))


def decode_events(recording: Path, hz: float) -> list[Any]:
    """The ``/events`` of ``recording`` as :class:`interfaces.events.Event`, in recorded order."""
    from interfaces.events import Event, EventType

    events = []
    for index, (_, msg) in enumerate(read_topic(recording, EVENTS_TOPIC.name)):
        try:
            kind = EventType(msg.type)
        except ValueError:
            text = f"{recording}: /events message {index} has unknown type {msg.type!r}"
            raise RecordingError(text) from None
        try:
            data = json.loads(msg.detail) if msg.detail else {}
        except json.JSONDecodeError as exc:
            text = f"{recording}: /events message {index} has bad JSON detail: {exc}"
            raise RecordingError(text) from None
        time_s = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        events.append(
            Event(
                time_s=time_s,
                step=round(time_s * hz),
                type=kind,
                object_id=int(msg.object_id),
                class_name=str(msg.class_name),
                data=dict(data),
            )
        )
    return events


def is_joint_states(topic: str) -> bool:
    """Whether ``topic`` is a station's joint states (``/joint_states``, ``/s1/joint_states``)."""
    name = JOINT_STATES.name
    return topic == f"/{name}" or topic.endswith(f"/{name}")


@dataclass(frozen=True, kw_only=True)
class OfflineMetrics:
    """What a recording holds, and the metrics its events give (the metric table's functions).

    ``scores`` is the line's event scores (as ``summary.json`` ``scores``), ``stations`` each
    station's (as ``summary.json`` ``stations[name]["scores"]``), ``classes`` each class's
    metrics (scope class) and ``bins`` each station's bins' (scope bin); :meth:`matches` holds
    them against the metrics an episode's row was written with.
    """

    recording: Path
    complete: bool
    """The recording was finished cleanly (it ends in a footer)."""
    message_counts: Mapping[str, int]
    physics_hz: float
    steps: int
    duration_s: float
    events: Mapping[str, int]
    """Events by type."""
    scores: EventScores
    stations: Mapping[str, EventScores]
    classes: Mapping[str, Metrics]
    bins: Mapping[str, Mapping[str, Metrics]]
    tracking_note: str = TRACKING_NOTE
    """Why the tracking time is not recomputed."""

    def mismatches(self, row: EpisodeMetrics) -> list[str]:
        """Where the written row differs from what the recording gives, one line each (empty:
        every metric the events give is the row's): the line's and each station's event
        metrics, the drops by reason, the classes and each station's bins."""
        out = _scope_mismatches("line", self.scores, row.line)
        for name, block in row.stations.items():
            out += _scope_mismatches(name, self.stations.get(name, {}), block)
            if block.bins is not None and block.bins != self.bins.get(name, {}):
                out.append(f"{name}.bins: written {block.bins}, recorded {self.bins.get(name)}")
        if dict(row.classes) != dict(self.classes):
            out.append(f"classes: written {row.classes}, recorded {self.classes}")
        return out


def _scope_mismatches(name: str, scores: EventScores, block: ScopeMetrics) -> list[str]:
    """The event scores of one scope that its written block holds and states otherwise."""
    written: dict[str, object] = {**block.values, "dropped_by_reason": block.dropped_by_reason}
    return [
        f"{name}.{key}: written {written[key]}, recorded {value}"
        for key, value in scores.items()
        if key in written and written[key] != value
    ]


def offline_metrics(recording: Path, cell: Path | str | None = None) -> OfflineMetrics:
    """The twin's scores recomputed from ``recording``, and what the recording holds.

    ``cell`` is the cell the episode ran (a run folder's ``cell.yaml``, a shipped name; None:
    the default cell): its most downstream station decides which objects the line missed
    (:func:`interfaces.metrics.count_events`, ``line_exit``).
    """
    from interfaces.cell import load_cell
    from interfaces.metrics import (
        bin_scores,
        class_scores,
        count_events,
        event_scores,
        exit_station,
        station_names,
    )

    line_exit = exit_station(load_cell(cell).stations)

    counts: Counter[str] = Counter()
    joint_stamps: dict[str, list[int]] = {}
    for _, channel, message in iter_raw(recording):
        counts[channel.topic] += 1
        if is_joint_states(channel.topic):
            joint_stamps.setdefault(channel.topic, []).append(header_stamp_ns(message.data))
    first = min(joint_stamps, default=None)
    clock = episode_clock([] if first is None else joint_stamps[first], recording)
    events = decode_events(recording, clock.physics_hz)
    duration_s = clock.duration_s
    return OfflineMetrics(
        recording=recording,
        complete=is_complete(recording),
        message_counts=dict(sorted(counts.items())),
        physics_hz=clock.physics_hz,
        steps=clock.steps,
        duration_s=duration_s,
        events=dict(sorted(Counter(str(e.type) for e in events).items())),
        scores=event_scores(count_events(events, duration_s, line_exit=line_exit)),
        stations={
            name: event_scores(count_events(events, duration_s, station=name))
            for name in station_names(events)
        },
        classes=class_scores(events, duration_s, line_exit=line_exit),
        bins=bin_scores(events),
    )


__all__ = [
    "EpisodeClock",
    "OfflineMetrics",
    "decode_events",
    "episode_clock",
    "header_stamp_ns",
    "is_complete",
    "is_joint_states",
    "iter_raw",
    "offline_metrics",
    "read_topic",
]
