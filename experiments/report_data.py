"""The report's data: the run folders it reads and what it reads from each episode.

Each run folder's ``run.json`` (its dataset, cell and stations), and for each episode folder the
twin's summary and telemetry and the episode's row of the run's ``episodes.json`` (its metrics,
written once by the run: the report never scores an episode again). Paths through
:mod:`interfaces.run_folder`.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from experiments import stats
from interfaces.errors import CdwTwinError
from interfaces.fileio import MAX_JSON_BYTES, read_text_capped
from interfaces.run_folder import EpisodeFolder, RunFolder
from interfaces.run_records import EpisodeMetrics, read_rows


class ReportError(CdwTwinError):
    """A report input (run folder, its files) is missing or malformed."""


class Unavailable(Exception):  # noqa: N818 - reads as "figure unavailable: reason"
    """A figure's data is missing; the message says why."""


@dataclass(frozen=True)
class Episode:
    """One episode folder of a run, with whatever files it has (None when missing)."""

    run_dir: Path
    folder: Path
    speed_mps: float | None
    seed: int | None
    summary: dict[str, Any] | None
    telemetry: dict[str, Any] | None
    metrics: dict[str, Any] | None
    """The episode's row of the run's ``episodes.json`` (None when there is none)."""
    cell: str = ""
    """The name of the cell the run used (``run.json``'s ``cell``)."""
    stations: tuple[str, ...] = ()
    """The stations of that cell (``run.json``'s ``stations``, else the episode's metrics)."""

    @property
    def name(self) -> str:
        """``<run folder>/<episode folder>``."""
        return f"{self.run_dir.name}/{self.folder.name}"

    @property
    def n_stations(self) -> int:
        """How many stations the episode's cell has."""
        return len(self.stations) or len((self.metrics or {}).get("stations") or {}) or 1


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
            seen.update(dict.fromkeys((ep.metrics or {}).get("stations") or {}))
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


# -- statistics -------------------------------------------------------------------------------
def wilson_interval(successes: int, trials: int) -> tuple[float, float]:
    """95 % Wilson score interval of a binomial proportion; ``(0, 1)`` when ``trials`` is 0."""
    low, high = stats.wilson_interval(successes, trials)
    return (0.0, 1.0) if low is None or high is None else (low, high)


def percentile(values: Sequence[float], q: float) -> float | None:
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
    text = read_text_capped(path, max_bytes=MAX_JSON_BYTES, what="JSON file", error=ReportError)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        msg = f"{path}: not valid JSON (line {exc.lineno}): {exc.msg}"
        raise ReportError(msg) from None
    except RecursionError:
        msg = f"{path}: not valid JSON: nested too deeply"
        raise ReportError(msg) from None


def _optional_json(path: Path, notes: list[str]) -> dict[str, Any] | None:
    if not path.is_file():
        return None
    try:
        data = read_json(path)
    except ReportError as exc:
        notes.append(str(exc))
        return None
    return data if isinstance(data, dict) else None


def _dataset_of(run_dir: Path, run: dict[str, Any], notes: list[str]) -> Path:
    if isinstance(run.get("dataset"), str):
        return Path(run["dataset"])
    scenario = run_dir / "scenario.yaml"
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
    folder: EpisodeFolder, run: dict[str, Any], written: dict[int, EpisodeMetrics], notes: list[str]
) -> Episode:
    summary = _optional_json(folder.summary, notes)
    speed = summary.get("belt_speed_mps") if summary else None
    if speed is None:
        speed = run.get("speed_mps")
    seed = summary.get("seed") if summary else None
    complete = summary is not None and summary.get("complete") is not False
    row = written.get(folder.index if folder.index is not None else -1)
    if complete and row is None:
        notes.append(f"{folder.path}: no metrics (no row of episodes.json)")
    metrics = row.to_data() if complete and row is not None else None
    stations = run.get("stations") or (list(row.stations) if row is not None else [])
    return Episode(
        run_dir=folder.run.path,
        folder=folder.path,
        speed_mps=None if speed is None else float(speed),
        seed=None if seed is None else int(seed),
        summary=summary,
        telemetry=_optional_json(folder.telemetry, notes),
        metrics=metrics,
        cell=str(run.get("cell") or "cell"),
        stations=tuple(str(s) for s in stations),
    )


def load_runs(paths: Sequence[Path]) -> RunData:
    """Read every run folder (see :func:`find_run_dirs`); raises :class:`ReportError`."""
    run_dirs = find_run_dirs([Path(p) for p in paths])
    notes: list[str] = []
    episodes: list[Episode] = []
    datasets: list[Path] = []
    for run_dir in run_dirs:
        run = read_json(RunFolder(run_dir).run_json)
        if not isinstance(run, dict):
            msg = f"{RunFolder(run_dir).run_json}: expected a JSON object"
            raise ReportError(msg)
        dataset = _dataset_of(run_dir, run, notes)
        if dataset not in datasets:
            datasets.append(dataset)
        written = _written_metrics(run_dir, notes)
        for folder in RunFolder(run_dir).episodes():
            episode = _episode(folder, run, written, notes)
            if episode.summary is not None and episode.summary.get("complete") is False:
                notes.append(
                    f"{folder.path}: the episode did not finish (failed or stopped); left out"
                )
                continue
            episodes.append(episode)
    return RunData(tuple(run_dirs), tuple(episodes), tuple(datasets), tuple(notes))


def episode_rtt_ms(ep: Episode) -> list[float]:
    return [float(v) for v in ((ep.telemetry or {}).get("rtt") or {}).get("rtt_ms", [])]


def episode_tracking_times(ep: Episode) -> list[float]:
    tracking = (ep.summary or {}).get("tracking") or {}
    times = tracking.get("tracking_times_s")
    if times is None and tracking.get("tracking_time_4mm_mean_s") is not None:
        times = [tracking["tracking_time_4mm_mean_s"]]
    return [float(t) for t in times or []]
