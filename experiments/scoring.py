"""An episode's metrics, scored once, and the run's tables of them.

:func:`episode_metrics` reads an episode folder's records (the twin's summary, its events, every
controller's stats: :mod:`interfaces.run_records`) and applies the metric table
(:mod:`interfaces.metrics`) to them: the line's metrics, each station's and each class's. The
runner writes the result as a row of ``episodes.json`` (:func:`write_tables`, with
``episodes.csv`` and the means in ``run.json``); every later reader (sweep, report, demo) reads
those rows (:func:`interfaces.run_records.read_rows`) and never scores an episode again.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from experiments.stats import mean_of
from interfaces.errors import CdwTwinError
from interfaces.fileio import read_text_capped, write_atomic
from interfaces.metrics import in_scope
from interfaces.run_folder import EpisodeFolder, RunFolder
from interfaces.run_records import (
    ControllerStats,
    EpisodeMetrics,
    EpisodeRow,
    EpisodeSummary,
    FailedEpisode,
    Metrics,
    MetricValue,
    PickStats,
    RunInfo,
    RunMeans,
    ScopeMetrics,
    TrackingSummary,
    write_rows,
)
from interfaces.run_records import succeeded as good_rows

if TYPE_CHECKING:
    from interfaces.cell import Cell
    from interfaces.events import Event

METRIC_KEYS = ("speed_mps", "seed", "mode", "picks", *in_scope("line"))
"""The metric columns of ``episodes.csv``, in order: the episode's settings, ``picks`` (the
table's ``picked`` under its older name) and every line metric of the table."""

EPISODE_COLUMNS = (*METRIC_KEYS, "failed", "reason")
"""The columns of ``episodes.csv``: the metrics, whether the episode failed and why."""

MAX_EVENTS_BYTES = 1_000_000_000
"""The largest ``events.jsonl`` read (a day-long episode's is a few hundred MB)."""


def failure_text(index: int, seed: int, reason: str) -> str:
    """How ``run.json`` and ``sweep.json`` list a failed episode."""
    return f"episode {index} (seed {seed}) failed: {reason}"


def read_events(path: Path) -> list[Event]:
    """The events of an ``events.jsonl``."""
    from interfaces.events import Event

    text = read_text_capped(path, max_bytes=MAX_EVENTS_BYTES, what="event log", error=CdwTwinError)
    return [Event.from_json(line) for line in text.splitlines()]


def episode_cell(folder: EpisodeFolder) -> Cell:
    """The cell an episode ran: its run folder's ``cell.yaml``, else the default cell (a run
    folder written before cells were data)."""
    from interfaces.cell import load_cell

    copy = folder.run.cell
    return load_cell(copy if copy.is_file() else None)


def controller_stats(
    folder: EpisodeFolder, stations: Sequence[str]
) -> dict[str, list[PickStats | None]]:
    """Every controller's pick counters in an episode folder, per station, in instance order."""
    return {
        station: [ControllerStats.read(p).pick for p in folder.stats_files(station, stations)]
        for station in stations
    }


@dataclass(frozen=True, kw_only=True)
class EpisodeRecord:
    """What an episode folder holds that the metrics are computed from."""

    summary: EpisodeSummary
    events: list[Event]
    picks: dict[str, list[PickStats | None]]
    """Each station's controllers' pick counters, in instance order (restarts add instances)."""
    line_exit: str | None = None
    """The station whose window ends the line (:func:`interfaces.metrics.exit_station`)."""

    @property
    def duration_s(self) -> float:
        """The episode's simulated seconds."""
        return self.summary.sim_seconds

    @property
    def landing(self) -> tuple[int, ...]:
        """Objects still falling into a bin when the episode ended."""
        return self.summary.landing_in_bins


@dataclass(frozen=True)
class _ScopeInputs:
    picks: list[PickStats | None]
    landing: int
    tracking: TrackingSummary | None
    restarts: int


def _scope_inputs(record: EpisodeRecord, station: str | None) -> _ScopeInputs:
    """The pick counters, landing objects, tracking block and restarts of the line (``station``
    None) or of one station."""
    from interfaces.metrics import landing_by_station

    summary = record.summary
    if station is None:
        return _ScopeInputs(
            picks=[p for instances in record.picks.values() for p in instances],
            landing=len(record.landing),
            tracking=summary.tracking,
            restarts=max((len(s) for s in record.picks.values()), default=1) - 1,
        )
    picks = record.picks.get(station, [])
    block = summary.stations.get(station)
    tracking = block.tracking if block is not None else None
    if tracking is None and len(record.picks) == 1:
        tracking = summary.tracking
    landing = landing_by_station(record.events, record.landing).get(station, 0)
    return _ScopeInputs(picks=picks, landing=landing, tracking=tracking, restarts=len(picks) - 1)


def scope_metrics(record: EpisodeRecord, station: str | None) -> ScopeMetrics:
    """The table's metrics of the line (``station`` None) or of one station, with the
    controllers' ``untargeted`` objects by reason and the drops by reason; a station's block
    adds each reason's share of the objects its controller decided about (``untargeted_share``)
    and its bins' scores (``bins``, scope ``bin``)."""
    from interfaces.metrics import (
        bin_scores,
        considered_objects,
        controller_scores,
        count_events,
        event_scores,
        fault_counts,
        targeted_objects,
        tracking_metrics,
        untargeted_objects,
        untargeted_scores,
    )

    counts = count_events(
        record.events, record.duration_s, station=station, line_exit=record.line_exit
    )
    inputs = _scope_inputs(record, station)
    targeted = targeted_objects(inputs.picks, inputs.landing)
    untargeted = untargeted_objects(inputs.picks)
    allocation = untargeted_scores(untargeted, considered_objects(inputs.picks))
    scores = event_scores(counts)
    values = {
        **scores,
        **controller_scores(counts, targeted),
        **tracking_metrics(inputs.tracking),
        **fault_counts(record.events, station=station),
        **allocation,
        "targeted": targeted,
        "controller_restarts": max(0, inputs.restarts),
        "real_time_factor": record.summary.real_time_factor,
    }
    names = in_scope("line" if station is None else "station")
    if station is None:
        return ScopeMetrics(
            values={name: values[name] for name in names},
            untargeted=untargeted,
            dropped_by_reason=scores["dropped_by_reason"],
        )
    return ScopeMetrics(
        values={name: values[name] for name in names},
        untargeted=untargeted,
        dropped_by_reason=scores["dropped_by_reason"],
        untargeted_share=allocation["untargeted_share"],
        bins=bin_scores(record.events, station=station).get(station, {}),
    )


def read_record(folder: EpisodeFolder, cell: Cell) -> EpisodeRecord:
    """An episode folder's summary, events and controller stats, for the stations of ``cell``."""
    from interfaces.metrics import exit_station

    names = tuple(s.name for s in cell.stations)
    return EpisodeRecord(
        summary=EpisodeSummary.read(folder.summary),
        events=read_events(folder.events),
        picks=controller_stats(folder, names),
        line_exit=exit_station(cell.stations),
    )


def score_episode(
    folder: Path | EpisodeFolder, mode: str, index: int | None = None
) -> EpisodeMetrics:
    """The metrics of one finished episode folder: the line's, per station and per class.

    The stations are those of the run folder's ``cell.yaml`` (:func:`episode_cell`); ``index``
    defaults to the folder's (``ep002``: 2).
    """
    from interfaces.metrics import class_scores

    episode = folder if isinstance(folder, EpisodeFolder) else EpisodeFolder(folder)
    cell = episode_cell(episode)
    record = read_record(episode, cell)
    summary = record.summary
    return EpisodeMetrics(
        episode=index if index is not None else (episode.index or 0),
        seed=summary.seed,
        mode=mode,
        speed_mps=summary.belt_speed_mps,
        line=scope_metrics(record, None),
        stations={s.name: scope_metrics(record, s.name) for s in cell.stations},
        classes=class_scores(record.events, record.duration_s, line_exit=record.line_exit),
        # the camera's scores (perception.source: camera), without the per-class ones
        perception={k: v for k, v in (summary.perception or {}).items() if "/" not in k},
        complete=summary.complete,
    )


# -- tables -------------------------------------------------------------------------------------
def failed_texts(rows: Sequence[EpisodeRow]) -> list[str]:
    """:func:`failure_text` of every failed row."""
    return [failure_text(r.episode, r.seed, r.reason) for r in rows if isinstance(r, FailedEpisode)]


def _means(blocks: Sequence[Metrics], keys: Sequence[str]) -> dict[str, MetricValue]:
    return {k: mean_of([b.get(k) for b in blocks]) for k in keys}


def line_means(rows: Sequence[EpisodeRow]) -> dict[str, MetricValue]:
    """Means over the successful episodes of every numeric line metric (failed ones left out)."""
    good = good_rows(rows)
    keys = [k for k in METRIC_KEYS if k not in ("mode", "seed", "speed_mps")]
    perception = sorted({f"perception_{k}" for r in good for k in r.perception})
    return {
        **{k: mean_of([r.metric(k) for r in good]) for k in keys},
        **{k: mean_of([r.metric(k) for r in good]) for k in perception},
    }


def station_means(rows: Sequence[EpisodeRow]) -> dict[str, dict[str, MetricValue]]:
    """Means over the successful episodes of each station's metrics."""
    good = good_rows(rows)
    names = dict.fromkeys(name for r in good for name in r.stations)
    keys = in_scope("station")
    return {
        name: _means([r.stations[name].values for r in good if name in r.stations], keys)
        for name in names
    }


def class_means(rows: Sequence[EpisodeRow]) -> dict[str, dict[str, MetricValue]]:
    """Means over the successful episodes of each class's metrics."""
    good = good_rows(rows)
    names = dict.fromkeys(name for r in good for name in r.classes)
    keys = in_scope("class")
    return {
        name: _means([r.classes[name] for r in good if name in r.classes], keys) for name in names
    }


def run_means(
    rows: Sequence[EpisodeRow], complete: bool, info: RunInfo, *, also_failed: Sequence[str] = ()
) -> RunMeans:
    """``run.json`` of ``rows``: failed rows counted as ``failed`` with their ``failures`` (and
    ``also_failed``: a reason the run could not finish), never in the means."""
    return RunMeans(
        complete=complete,
        episodes=len(good_rows(rows)),
        failed=len(failed_texts(rows)),
        failures=(*failed_texts(rows), *also_failed),
        info=info,
        mean=line_means(rows),
        mean_by_station=station_means(rows),
        mean_by_class=class_means(rows),
    )


def write_run_tables(
    run: RunFolder, rows: Sequence[EpisodeRow], complete: bool, info: RunInfo
) -> RunMeans:
    """``episodes.json``, ``episodes.csv`` and ``run.json`` (each atomically).

    ``rows`` may hold failed episodes: they are listed in the tables, and counted in
    ``run.json`` as ``failed`` with their ``failures``, never in the means.
    """
    write_rows(run.episodes_json, rows)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(EPISODE_COLUMNS), extrasaction="ignore")
    writer.writeheader()
    writer.writerows(row.to_data() for row in rows)
    write_atomic(run.episodes_csv, buffer.getvalue())
    means = run_means(rows, complete, info)
    means.write(run.run_json)
    return means
