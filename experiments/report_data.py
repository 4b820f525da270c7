"""The report's data: the run folders it reads and what it reads from each episode.

Each run folder's ``run.json`` (its dataset, cell and stations), and for each episode folder the
twin's summary (:class:`interfaces.run_records.EpisodeSummary`), its telemetry series and the
episode's row of the run's ``episodes.json`` (:class:`interfaces.run_records.EpisodeMetrics`,
written once by the run: the report never scores an episode again). Paths through
:mod:`interfaces.run_folder`; :func:`load_runs` is the one loader.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from interfaces.errors import CdwTwinError
from interfaces.fileio import MAX_JSON_BYTES, read_text_capped
from interfaces.run_folder import EpisodeFolder, RunFolder
from interfaces.run_records import EpisodeMetrics, EpisodeSummary, read_rows


class ReportError(CdwTwinError):
    """A report input (run folder, its files) is missing or malformed."""


class Unavailable(Exception):  # noqa: N818 - reads as "figure unavailable: reason"
    """A figure's data is missing; the message says why."""


# -- telemetry --------------------------------------------------------------------------------
@dataclass(frozen=True)
class StepRateSeries:
    """Steps per wall second, one row per wall-clock window (``telemetry.json``'s
    ``step_rate``)."""

    wall_s: tuple[float, ...] = ()
    steps_per_s: tuple[float, ...] = ()


@dataclass(frozen=True)
class BeltSeries:
    """The belt's setpoint and measured speed over sim time (``telemetry.json``'s ``belt``)."""

    sim_s: tuple[float, ...] = ()
    setpoint_mps: tuple[float, ...] = ()
    speed_mps: tuple[float, ...] = ()


@dataclass(frozen=True)
class RttSeries:
    """Every command's round-trip latency over wall time (``telemetry.json``'s ``rtt``)."""

    wall_s: tuple[float, ...] = ()
    rtt_ms: tuple[float, ...] = ()


@dataclass(frozen=True)
class Telemetry:
    """The series of an episode's ``twin/telemetry.json`` the figures draw (empty when the file
    has none of a kind; see :mod:`twin.telemetry`)."""

    step_rate: StepRateSeries = field(default_factory=StepRateSeries)
    belt: BeltSeries = field(default_factory=BeltSeries)
    rtt: RttSeries = field(default_factory=RttSeries)

    @classmethod
    def from_data(cls, data: Mapping[str, object], where: Path) -> Telemetry:
        """The series of a parsed ``telemetry.json``; :class:`ReportError` naming the file and
        the key when one is not a list of numbers."""

        def series(block: str, key: str) -> tuple[float, ...]:
            values = data.get(block)
            values = values.get(key) if isinstance(values, dict) else None
            if values is None:
                return ()
            if not isinstance(values, list) or not all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in values
            ):
                msg = f"{where}: {block}.{key} is not a list of numbers"
                raise ReportError(msg)
            return tuple(float(v) for v in values)

        return cls(
            step_rate=StepRateSeries(
                series("step_rate", "wall_s"), series("step_rate", "steps_per_s")
            ),
            belt=BeltSeries(
                series("belt", "sim_s"), series("belt", "setpoint_mps"), series("belt", "speed_mps")
            ),
            rtt=RttSeries(series("rtt", "wall_s"), series("rtt", "rtt_ms")),
        )


# -- the episodes -----------------------------------------------------------------------------
@dataclass(frozen=True)
class RunFacts:
    """What the report takes from a run's ``run.json``: the dataset it used (None when it does
    not say), its belt speed, its cell and that cell's stations."""

    dataset: str | None = None
    speed_mps: float | None = None
    cell: str = "cell"
    stations: tuple[str, ...] = ()

    @classmethod
    def from_data(cls, data: Mapping[str, object], where: Path) -> RunFacts:
        """The facts of a parsed ``run.json``; :class:`ReportError` naming the file and the key
        when one has the wrong type."""
        dataset = data.get("dataset")
        speed = data.get("speed_mps")
        stations = data.get("stations") or []
        if speed is not None and (not isinstance(speed, int | float) or isinstance(speed, bool)):
            msg = f"{where}: speed_mps = {speed!r} is not a number"
            raise ReportError(msg)
        if not isinstance(stations, list):
            msg = f"{where}: stations = {stations!r} is not a list"
            raise ReportError(msg)
        return cls(
            dataset=dataset if isinstance(dataset, str) else None,
            speed_mps=None if speed is None else float(speed),
            cell=str(data.get("cell") or "cell"),
            stations=tuple(str(s) for s in stations),
        )


CAMERA_SUFFIX = " (camera)"
"""Appended to the cell name of an episode whose perception was the camera: its groups are
never pooled with the oracle's episodes of the same cell and speed."""


@dataclass(frozen=True)
class Episode:
    """One episode folder of a run, with whatever files it has (None when missing)."""

    run_dir: Path
    folder: Path
    speed_mps: float | None
    seed: int | None
    summary: EpisodeSummary | None
    telemetry: Telemetry | None
    metrics: EpisodeMetrics | None
    """The episode's row of the run's ``episodes.json`` (None when there is none)."""
    cell: str = ""
    """The name of the cell the run used (``run.json``'s ``cell``), with
    :data:`CAMERA_SUFFIX` when its perception was the camera."""
    stations: tuple[str, ...] = ()
    """The stations of that cell (``run.json``'s ``stations``, else the episode's metrics)."""

    @property
    def name(self) -> str:
        """``<run folder>/<episode folder>``."""
        return f"{self.run_dir.name}/{self.folder.name}"

    @property
    def n_stations(self) -> int:
        """How many stations the episode's cell has."""
        metrics = len(self.metrics.stations) if self.metrics is not None else 0
        return len(self.stations) or metrics or 1

    @property
    def rtt_ms(self) -> tuple[float, ...]:
        """Every round-trip latency of the episode's telemetry (ms; empty without it)."""
        return self.telemetry.rtt.rtt_ms if self.telemetry is not None else ()

    @property
    def tracking_times_s(self) -> tuple[float, ...]:
        """The tracking time to 4 mm of each settled pursuit (the summary's mean alone when the
        summary lists no times)."""
        tracking = self.summary.tracking if self.summary is not None else None
        if tracking is None:
            return ()
        if not tracking.tracking_times_s and tracking.tracking_time_4mm_mean_s is not None:
            return (tracking.tracking_time_4mm_mean_s,)
        return tracking.tracking_times_s


@dataclass(frozen=True)
class RunData:
    """Everything the report reads: episodes of every run and the datasets they used."""

    run_dirs: tuple[Path, ...]
    episodes: tuple[Episode, ...]
    datasets: tuple[Path, ...]
    notes: tuple[str, ...] = field(default=())

    def speeds(self) -> list[float]:
        """Distinct belt speeds, ascending (episodes without a speed are left out)."""
        return sorted({e.speed_mps for e in self.episodes if e.speed_mps is not None})

    def at_speed(self, speed: float) -> list[Episode]:
        """Episodes at belt speed ``speed``."""
        return [e for e in self.episodes if e.speed_mps == speed]

    def stations(self, episodes: Sequence[Episode] | None = None) -> list[str]:
        """Every station some episode (of ``episodes``, default all) has metrics for, in order
        of first appearance."""
        seen: dict[str, None] = {}
        for ep in self.episodes if episodes is None else episodes:
            if ep.metrics is not None:
                seen.update(dict.fromkeys(ep.metrics.stations))
        return list(seen)

    def groups(self) -> list[tuple[str, float]]:
        """The distinct (cell, belt speed) of the episodes, by number of stations, cell and
        speed: the runs the tables pool (episodes without a speed are left out)."""
        keys: set[tuple[int, str, float]] = set()
        for e in self.episodes:
            if e.speed_mps is not None:
                keys.add((e.n_stations, e.cell, e.speed_mps))
        return [(cell, speed) for _, cell, speed in sorted(keys)]

    def in_group(self, cell: str, speed: float) -> list[Episode]:
        """Episodes of cell ``cell`` at belt speed ``speed``."""
        return [e for e in self.episodes if e.cell == cell and e.speed_mps == speed]


def percentile(values: Sequence[float], q: float) -> float | None:
    """The ``q`` th percentile of ``values`` (numpy's linear one); None when there are none."""
    if not values:
        return None
    import numpy as np

    return float(np.percentile(values, q))


# -- loading ----------------------------------------------------------------------------------
def find_run_dirs(paths: Sequence[Path]) -> list[Path]:
    """Run folders among ``paths``: each one holding ``run.json``, or a folder of such folders."""
    found: list[Path] = []
    for path in paths:
        if RunFolder(path).run_json.is_file():
            found.append(path)
            continue
        children = (
            sorted(p for p in path.iterdir() if RunFolder(p).run_json.is_file())
            if (path.is_dir())
            else []
        )
        if not children:
            what = "does not exist" if not path.exists() else "has no run.json"
            msg = (
                f"{path}: {what} (expected a folder written by `cdw-twin run`, "
                "or a folder of such folders)"
            )
            raise ReportError(msg)
        found.extend(children)
    return found


def read_json(path: Path) -> Any:
    """A JSON file the report reads (at most :data:`interfaces.fileio.MAX_JSON_BYTES`);
    :class:`ReportError` naming it when it cannot be read or parsed."""
    text = read_text_capped(path, max_bytes=MAX_JSON_BYTES, what="JSON file", error=ReportError)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        msg = f"{path}: not valid JSON (line {exc.lineno}): {exc.msg}"
        raise ReportError(msg) from None
    except RecursionError:
        msg = f"{path}: not valid JSON: nested too deeply"
        raise ReportError(msg) from None


def _summary(folder: EpisodeFolder, notes: list[str]) -> EpisodeSummary | None:
    """The twin's summary of an episode; None (with a note when it is unreadable) without."""
    if not folder.summary.is_file():
        return None
    try:
        return EpisodeSummary.read(folder.summary)
    except CdwTwinError as exc:
        notes.append(str(exc))
        return None


def _telemetry(folder: EpisodeFolder, notes: list[str]) -> Telemetry | None:
    """The episode's telemetry series; None (with a note when it is unreadable) without."""
    if not folder.telemetry.is_file():
        return None
    try:
        data = read_json(folder.telemetry)
        return Telemetry.from_data(data, folder.telemetry) if isinstance(data, dict) else None
    except ReportError as exc:
        notes.append(str(exc))
        return None


def _dataset_of(run_dir: Path, run: RunFacts, notes: list[str]) -> Path:
    if run.dataset is not None:
        return Path(run.dataset)
    scenario = RunFolder(run_dir).scenario
    if scenario.is_file():
        from interfaces.errors import ConfigError
        from interfaces.yamlio import load_yaml_file

        try:
            data = load_yaml_file(scenario, what="scenario") or {}
        except ConfigError as exc:
            notes.append(f"{exc}; the built-in sample used")
            data = {}
        name = data.get("dataset") if isinstance(data, dict) else None
        if isinstance(name, str) and name != "builtin":
            path = Path(name)
            return path if path.is_absolute() else (run_dir / path).resolve()
    from twin.builtin import builtin_dataset

    notes.append(f"{run_dir}: no dataset in run.json or scenario.yaml; the built-in sample used")
    return builtin_dataset()


def _written_metrics(run_dir: Path, notes: list[str]) -> dict[int, EpisodeMetrics]:
    """The metrics the run wrote for its finished episodes (``episodes.json``), by episode
    index: the report reads them, it never scores an episode again. Empty (with a note) when
    the file cannot be read as episode rows."""
    try:
        rows = read_rows(RunFolder(run_dir).episodes_json)
    except (OSError, CdwTwinError) as exc:
        notes.append(f"{run_dir}: no metrics ({type(exc).__name__}: {exc})")
        return {}
    return {row.episode: row for row in rows if isinstance(row, EpisodeMetrics)}


def _episode(
    folder: EpisodeFolder, run: RunFacts, written: dict[int, EpisodeMetrics], notes: list[str]
) -> Episode:
    summary = _summary(folder, notes)
    speed = summary.belt_speed_mps if summary is not None else None
    if speed is None:
        speed = run.speed_mps
    complete = summary is not None and summary.complete
    row = written.get(folder.index if folder.index is not None else -1)
    if complete and row is None:
        notes.append(f"{folder.path}: no metrics (no row of episodes.json)")
    return Episode(
        run_dir=folder.run.path,
        folder=folder.path,
        speed_mps=speed,
        seed=summary.seed if summary is not None else None,
        summary=summary,
        telemetry=_telemetry(folder, notes),
        metrics=row if complete else None,
        cell=f"{run.cell}{CAMERA_SUFFIX}"
        if summary is not None and summary.perception
        else run.cell,
        stations=run.stations or (tuple(row.stations) if row is not None else ()),
    )


def _run_facts(run_dir: Path) -> RunFacts:
    path = RunFolder(run_dir).run_json
    data = read_json(path)
    if not isinstance(data, dict):
        msg = f"{path}: expected a JSON object"
        raise ReportError(msg)
    return RunFacts.from_data(data, path)


def load_runs(paths: Sequence[Path]) -> RunData:
    """Read every run folder (see :func:`find_run_dirs`): its facts, its episodes' summaries
    and telemetry and the rows the run wrote; raises :class:`ReportError`.

    An episode that did not finish is left out with a note; an unreadable file, or an episode
    without its row of ``episodes.json``, is a note and the episode has no numbers.
    """
    run_dirs = find_run_dirs([Path(p) for p in paths])
    notes: list[str] = []
    episodes: list[Episode] = []
    datasets: list[Path] = []
    for run_dir in run_dirs:
        run = _run_facts(run_dir)
        dataset = _dataset_of(run_dir, run, notes)
        if dataset not in datasets:
            datasets.append(dataset)
        written = _written_metrics(run_dir, notes)
        for folder in RunFolder(run_dir).episodes():
            episode = _episode(folder, run, written, notes)
            if episode.summary is not None and not episode.summary.complete:
                notes.append(
                    f"{folder.path}: the episode did not finish (failed or stopped); left out"
                )
                continue
            episodes.append(episode)
    return RunData(tuple(run_dirs), tuple(episodes), tuple(datasets), tuple(notes))
