"""The typed records of a run folder (:mod:`interfaces.run_folder`) and their JSON files.

Each record is a frozen dataclass that round-trips to its file exactly (same keys, same order,
same values): the twin's episode summary (:class:`EpisodeSummary`, ``twin/summary.json``), each
controller's stats (:class:`ControllerStats`, ``controller*.json``), an episode's metrics
(:class:`EpisodeMetrics` or :class:`FailedEpisode`, a row of ``episodes.json``) and the run's
means (:class:`RunMeans`, ``run.json``). Writers build a record and write it here; readers read
the record and never the file. A file that is not its record is a :class:`RecordError` naming
the file and the key.

The metric values are named by the metric table (:mod:`interfaces.metrics`, which computes them
from these records): a scope's metrics are a mapping from the table's names to numbers, so a
metric is defined in one place, there.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from interfaces.dataclass_io import from_data, to_data
from interfaces.errors import CdwTwinError, ConfigError, cut
from interfaces.fileio import MAX_JSON_BYTES, read_text_capped, write_atomic

MetricValue = int | float | None
"""A metric's value: a count, a rate or a time; None where it is undefined (no trials)."""
Metrics = Mapping[str, MetricValue]
"""The metric table's values of one scope, by metric name."""

R = TypeVar("R")


class RecordError(CdwTwinError):
    """A run-folder file that cannot be read as its record (names the file and the key)."""


# -- reading and writing ---------------------------------------------------------------------------
def read_json_file(path: Path) -> Any:
    """A JSON file of a run folder (at most :data:`interfaces.fileio.MAX_JSON_BYTES`);
    :class:`RecordError` naming it when it cannot be read or parsed."""
    text = read_text_capped(path, max_bytes=MAX_JSON_BYTES, what="JSON file", error=RecordError)
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        msg = f"{path}: not valid JSON: {cut(str(exc), 200)}"
        raise RecordError(msg) from None


def _record(cls: type[R], data: object, where: str) -> R:
    try:
        return from_data(cls, data, where)
    except ConfigError as exc:
        raise RecordError(str(exc)) from None


def _write(path: Path, data: object, *, sort_keys: bool) -> None:
    write_atomic(path, json.dumps(data, indent=2, sort_keys=sort_keys, allow_nan=False) + "\n")


def _present(data: dict[str, object], *optional: str) -> dict[str, object]:
    """``data`` without the ``optional`` keys whose value is None (written only when set)."""
    return {k: v for k, v in data.items() if not (k in optional and v is None)}


# -- the controllers' stats ------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class PickStats:
    """A pick controller's counters since construction.

    ``untargeted`` counts objects that were never targeted, by the last reason the scheduler gave;
    ``aborted`` counts aborted picks by reason (``target_lost``, ``too_late``, ``ruckig_error``,
    ``ik_failure``, ``grip_missed``: the tool closed on nothing); ``errors`` counts every
    Ruckig/IK error, also outside a pick;
    ``rate_limited`` counts joint commands slowed to the joint velocity limits;
    ``sync_fallbacks`` counts Ruckig plans (Cartesian steps and joint moves) whose time
    synchronisation failed and that were solved without it (see
    :func:`control.planner.calculate_synchronised`).
    """

    targeted: int = 0
    completed: int = 0
    completed_by_class: Mapping[str, int] = field(default_factory=dict)
    aborted: Mapping[str, int] = field(default_factory=dict)
    untargeted: Mapping[str, int] = field(default_factory=dict)
    errors: Mapping[str, int] = field(default_factory=dict)
    rate_limited: int = 0
    sync_fallbacks: int = 0


@dataclass(frozen=True, kw_only=True)
class TimingUs:
    """Mean, median, 95th and 99th percentiles and maximum in microseconds (None without
    samples)."""

    mean: float | None = None
    p50: float | None = None
    p95: float | None = None
    p99: float | None = None
    max: float | None = None


@dataclass(frozen=True, kw_only=True)
class ControllerStats:
    """What a station's controller writes when it stops (``controller*.json``)."""

    mode: str = ""
    station: str = ""
    pick: PickStats | None = None
    rejected_detections: Mapping[str, int] = field(default_factory=dict)
    skipped: Mapping[str, int] = field(default_factory=dict)
    received: Mapping[str, int] = field(default_factory=dict)
    published: Mapping[str, int] = field(default_factory=dict)
    n_commands: int = 0
    control_updates: int = 0
    ticks_acked: int = 0
    control_update_us: TimingUs = field(default_factory=TimingUs)
    tick_to_ack_us: TimingUs = field(default_factory=TimingUs)

    def write(self, path: Path) -> None:
        """Write the stats file (atomically)."""
        _write(path, to_data(self), sort_keys=True)

    @classmethod
    def read(cls, path: Path) -> ControllerStats:
        """A stats file; :class:`RecordError` naming the file and key when it is not one."""
        return _record(cls, read_json_file(path), str(path))


# -- the twin's episode summary --------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class TrackingSummary:
    """The tracking time to 4 mm of the pursuits of an episode or a station
    (:func:`interfaces.metrics.tracking_summary`)."""

    pursuits: int = 0
    settled: int = 0
    unsettled: int = 0
    tracking_time_4mm_mean_s: float | None = None
    tracking_time_4mm_p95_s: float | None = None
    tracking_times_s: tuple[float, ...] = ()


@dataclass(frozen=True, kw_only=True)
class LatencySummary:
    """Round-trip latency of the twin's ticks to the controllers' commands (ms)."""

    rtt_ms_p50: float | None = None
    rtt_ms_p99: float | None = None
    rtt_ms_mean: float | None = None
    samples: int = 0
    unmatched_commands: int = 0


EventScores = Mapping[str, int | float | Mapping[str, int | float]]
"""The twin's event scores (:func:`interfaces.metrics.event_scores`): the table's event metrics,
with ``dropped_by_reason`` and ``recovery_by_class`` as mappings."""


@dataclass(frozen=True, kw_only=True)
class StationSummary:
    """One station's block of the twin's summary."""

    scores: EventScores = field(default_factory=dict)
    tracking: TrackingSummary | None = None
    latency: LatencySummary = field(default_factory=LatencySummary)


@dataclass(frozen=True, kw_only=True)
class EpisodeSummary:
    """What the twin writes when its episode ends (``twin/summary.json``): settings, timing,
    its event scores, tracking, counters, the final state and, with a camera, the perception
    scores. Fields other than ``seed``, ``sim_seconds`` and ``complete`` default (a summary
    written by hand, in a test, gives what it has)."""

    scenario: str = ""
    seed: int
    mode: str = ""
    belt_speed_mps: float | None = None
    complete: bool
    sim_seconds: float
    wall_seconds: float = 0.0
    match_wall_seconds: float = 0.0
    transport: str = ""
    real_time_factor: float | None = None
    cell: str = ""
    scores: EventScores = field(default_factory=dict)
    stations: Mapping[str, StationSummary] = field(default_factory=dict)
    landing_in_bins: tuple[int, ...] = ()
    tracking: TrackingSummary | None = None
    published: Mapping[str, int] = field(default_factory=dict)
    received_commands: int = 0
    rejected_commands: Mapping[str, int] = field(default_factory=dict)
    unlogged_rejections: int = 0
    lockstep_timeouts: int = 0
    priorities: tuple[str, ...] = ()
    final_state: Any = None
    """Belt position, joint positions and every object's pose at the end (opaque here)."""
    latency: LatencySummary = field(default_factory=LatencySummary)
    step_rate_hz_mean: float | None = None
    perception: Mapping[str, MetricValue] | None = None
    """The camera's detections scored against ground truth (``perception.source: camera``)."""
    stopped_by: str | None = None
    """The signal that stopped an interrupted episode."""

    def write(self, path: Path) -> None:
        """Write ``summary.json`` (atomically, keys sorted)."""
        _write(path, _present(to_data(self), "perception", "stopped_by"), sort_keys=True)

    @classmethod
    def read(cls, path: Path) -> EpisodeSummary:
        """A ``summary.json``; :class:`RecordError` naming the file and key when it is not one."""
        return _record(cls, read_json_file(path), str(path))


# -- an episode's metrics (a row of episodes.json) ------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class ScopeMetrics:
    """The metric table's values (:mod:`interfaces.metrics`) of the line or of one station,
    with the objects never targeted and the drops, by reason; a station's also each reason's
    share of the objects its controllers decided about (``untargeted_share``) and its bins'
    metrics (scope ``bin``)."""

    values: Metrics
    untargeted: Mapping[str, int] = field(default_factory=dict)
    dropped_by_reason: Mapping[str, int] = field(default_factory=dict)
    untargeted_share: Mapping[str, float] | None = None
    bins: Mapping[str, Metrics] | None = None

    def __getitem__(self, name: str) -> MetricValue:
        return self.values[name]

    def get(self, name: str) -> MetricValue:
        """The metric ``name``, None when this scope has none of that name."""
        return self.values.get(name)

    def to_data(self) -> dict[str, object]:
        """The block as written: the metrics at its top level, then the reason mappings."""
        out: dict[str, object] = {
            **self.values,
            "untargeted": dict(self.untargeted),
            "dropped_by_reason": dict(self.dropped_by_reason),
        }
        if self.untargeted_share is not None:
            out["untargeted_share"] = dict(self.untargeted_share)
        if self.bins is not None:
            out["bins"] = {name: dict(values) for name, values in self.bins.items()}
        return out

    @classmethod
    def from_data(
        cls, data: Mapping[str, object], where: str, *, other: Sequence[str] = ()
    ) -> ScopeMetrics:
        """The block from its written mapping: every key is a metric but the reason mappings
        and the ``other`` keys (those of the row around the line's block)."""
        blocks = ("untargeted", "dropped_by_reason", "untargeted_share", "bins")
        values = {k: v for k, v in data.items() if k not in (*blocks, *other)}
        return _record(cls, {"values": values, **{k: data[k] for k in blocks if k in data}}, where)


PERCEPTION_PREFIX = "perception_"
"""An episode row's perception scores (with a camera) are its keys with this prefix."""

PERCEPTION_RATES: Mapping[str, tuple[str, str]] = {
    "recall": ("matched", "truth_instances"),
    "precision": ("matched", "detections"),
}
"""The perception rates that pool over episodes as (successes, trials) of their counts: recall
at mask IoU 0.5 (matched / pieces in view), precision (matched / detections)."""

_ROW_KEYS = ("episode", "speed_mps", "seed", "mode", "picks", "stations", "classes", "complete")


@dataclass(frozen=True, kw_only=True)
class EpisodeMetrics:
    """One finished episode's metrics: a row of ``episodes.json``.

    The line's metrics (:attr:`line`) stand at the row's top level (``picks`` is ``picked``
    under its older name), each station's under ``stations``, each object class's under
    ``classes``; with a camera the perception scores as ``perception_<name>``.
    """

    episode: int
    seed: int
    mode: str
    speed_mps: float | None
    line: ScopeMetrics
    stations: Mapping[str, ScopeMetrics] = field(default_factory=dict)
    classes: Mapping[str, Metrics] = field(default_factory=dict)
    perception: Metrics = field(default_factory=dict)
    complete: bool = True

    failed = False

    def metric(self, name: str) -> MetricValue:
        """A line metric or a ``perception_*`` score by its row key (None when absent)."""
        if name.startswith(PERCEPTION_PREFIX):
            return self.perception.get(name[len(PERCEPTION_PREFIX) :])
        return self.line.get("picked" if name == "picks" else name)

    def to_data(self) -> dict[str, object]:
        """The row as ``episodes.json`` holds it."""
        return {
            "episode": self.episode,
            **{f"{PERCEPTION_PREFIX}{k}": v for k, v in self.perception.items()},
            "speed_mps": self.speed_mps,
            "seed": self.seed,
            "mode": self.mode,
            "picks": self.line.get("picked"),
            **self.line.to_data(),
            "stations": {name: block.to_data() for name, block in self.stations.items()},
            "classes": {name: dict(values) for name, values in self.classes.items()},
            "complete": self.complete,
            "failed": False,
        }

    @classmethod
    def from_data(cls, data: Mapping[str, Any], where: str) -> EpisodeMetrics:
        """A row of ``episodes.json``; :class:`RecordError` naming ``where`` and the key."""
        other = [*_ROW_KEYS, "failed", *(k for k in data if k.startswith(PERCEPTION_PREFIX))]
        line = ScopeMetrics.from_data(data, where, other=other)
        stations = data.get("stations") or {}
        return cls(
            episode=_record(int, data.get("episode"), f"{where}.episode"),
            seed=_record(int, data.get("seed"), f"{where}.seed"),
            mode=_record(str, data.get("mode"), f"{where}.mode"),
            speed_mps=_record(float | None, data.get("speed_mps"), f"{where}.speed_mps"),  # type: ignore[arg-type]
            line=line,
            stations={
                name: ScopeMetrics.from_data(block, f"{where}.stations.{name}")
                for name, block in stations.items()
            },
            classes=_record(dict[str, dict[str, MetricValue]], data.get("classes") or {}, where),
            perception={
                k[len(PERCEPTION_PREFIX) :]: v
                for k, v in data.items()
                if k.startswith(PERCEPTION_PREFIX)
            },
            complete=_record(bool, data.get("complete", True), f"{where}.complete"),
        )


@dataclass(frozen=True, kw_only=True)
class FailedEpisode:
    """An episode that failed: a row of ``episodes.json`` without metrics, with the reason."""

    episode: int
    seed: int
    mode: str
    reason: str
    speed_mps: float | None = None
    """The run's belt speed (a failed episode has no summary of its own)."""

    failed = True
    complete = False

    def to_data(self) -> dict[str, object]:
        """The row as ``episodes.json`` holds it."""
        row: dict[str, object] = {
            "episode": self.episode,
            "seed": self.seed,
            "mode": self.mode,
            "complete": False,
            "failed": True,
            "reason": self.reason,
        }
        return row if self.speed_mps is None else {**row, "speed_mps": self.speed_mps}


EpisodeRow = EpisodeMetrics | FailedEpisode
"""A row of ``episodes.json``: a finished episode's metrics or a failed episode."""


def row_from_data(data: object, where: str) -> EpisodeRow:
    """A row of ``episodes.json`` from its JSON value."""
    if not isinstance(data, Mapping):
        msg = f"{where}: an episode row must be a mapping, not {cut(data)}"
        raise RecordError(msg)
    if data.get("failed"):
        values = {k: v for k, v in data.items() if k not in ("complete", "failed")}
        return _record(FailedEpisode, values, where)
    return EpisodeMetrics.from_data(data, where)


def read_rows(path: Path) -> list[EpisodeRow]:
    """The rows of an ``episodes.json``."""
    data = read_json_file(path)
    if not isinstance(data, list):
        msg = f"{path}: must be a list of episode rows"
        raise RecordError(msg)
    return [row_from_data(row, f"{path}[{i}]") for i, row in enumerate(data)]


def write_rows(path: Path, rows: Sequence[EpisodeRow]) -> None:
    """Write an ``episodes.json`` (atomically)."""
    _write(path, [row.to_data() for row in rows], sort_keys=False)


def succeeded(rows: Sequence[EpisodeRow]) -> list[EpisodeMetrics]:
    """The rows of episodes that did not fail (the ones metrics are aggregated over)."""
    return [r for r in rows if isinstance(r, EpisodeMetrics)]


# -- the run's means (run.json) --------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class RunInfo:
    """What a run ran: the settings ``run.json`` states beside its means (a sweep's cell adds
    ``record``, ``duration_s`` and its ``overrides``)."""

    scenario: str
    scenario_path: str | None = None
    dataset: str
    cell: str
    stations: tuple[str, ...]
    mode: str
    transport: str
    record: bool | None = None
    speed_mps: float
    duration_s: float | None = None
    overrides: Mapping[str, Any] | None = None
    episodes_planned: int
    stopped: str | None = None
    """Why the run stopped before its last episode (interrupted, an episode failed)."""

    def to_data(self) -> dict[str, object]:
        """The settings as ``run.json`` holds them (keys that do not apply left out)."""
        return _present(to_data(self), "record", "duration_s", "overrides", "stopped")


@dataclass(frozen=True, kw_only=True)
class RunMeans:
    """``run.json``: whether every episode finished, the failures, what ran, and the means over
    the successful episodes of the line's metrics (``mean``), each station's and each class's."""

    complete: bool
    episodes: int
    failed: int
    failures: tuple[str, ...]
    info: RunInfo
    mean: Metrics
    mean_by_station: Mapping[str, Metrics]
    mean_by_class: Mapping[str, Metrics]

    def to_data(self) -> dict[str, object]:
        """``run.json`` as written: the counts, the settings, then the means."""
        return {
            "complete": self.complete,
            "episodes": self.episodes,
            "failed": self.failed,
            "failures": list(self.failures),
            **self.info.to_data(),
            "mean": dict(self.mean),
            "mean_by_station": {k: dict(v) for k, v in self.mean_by_station.items()},
            "mean_by_class": {k: dict(v) for k, v in self.mean_by_class.items()},
        }

    def write(self, path: Path) -> None:
        """Write ``run.json`` (atomically)."""
        _write(path, self.to_data(), sort_keys=False)

    @classmethod
    def read(cls, path: Path) -> RunMeans:
        """A ``run.json``; :class:`RecordError` naming the file and key when it is not one."""
        data = read_json_file(path)
        if not isinstance(data, Mapping):
            msg = f"{path}: must be a mapping"
            raise RecordError(msg)
        own = ("complete", "episodes", "failed", "failures", "mean")
        means = ("mean_by_station", "mean_by_class")
        info = {k: v for k, v in data.items() if k not in (*own, *means)}
        return _record(
            cls,
            {
                **{k: data[k] for k in (*own, *means) if k in data},
                "info": info,
            },
            str(path),
        )
