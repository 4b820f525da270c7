"""``cdw-twin sweep GRID --workers N``: a grid of scenarios x overrides x seeds, in parallel.

Example grid file (paths relative to the grid file)::

    scenarios: [scenarios/default.yaml, scenarios/dense.yaml]
    seeds: [0, 1, 2]          # or: episodes: 3 (seeds scenario.seed, +1, ...)
    overrides:                # optional, expanded as a product with the scenarios
      speed: [0.2, 0.4, 0.6]
      duration_s: [30.0]
      mode: [lockstep]
      cell: [suction]         # run the scenarios on this cell (a shipped name or a path)
      stations: [1, 2, 3, 4]  # run only the first k stations of the scenario's cell
    dataset: ../data/meshes   # optional; default: each scenario's own; --dataset overrides it
    headline: [recovery_rate] # optional: the metrics sweep.json lists first

Each grid cell (a scenario with one choice of every override) is a run folder with the layout
of ``cdw-twin run`` (``scenario.yaml``, ``cell.yaml``, ``controller.yaml``, ``epNNN/``,
``episodes.json``, ``run.json``): its scenario's cell (or the ``cell`` override; with
``stations: k`` its first k stations, in the cell file's order) runs one controller per station,
and ``cell.yaml`` is the cell it ran. Every grid cell x seed is one episode through
:func:`experiments.episode_processes.run_episode` on its own ROS domain; ``N`` run at once,
each driven by a thread. ``sweep.json`` and ``sweep.csv`` hold per grid cell the means with
95 % confidence intervals, for the line and (``sweep.json`` ``aggregate.stations``;
``sweep.csv`` rows with a ``station``, for a cell of several stations) per station, and in
``sweep.json`` per object class (``aggregate.classes``):

- every metric of the table (``docs/metrics.md``): Student t interval over the cell's
  episodes, ``mean +- t(0.975, n-1) * s / sqrt(n)`` (none for n < 2);
- every rate of the table (a ratio of two counts, such as ``success_rate``, sorted of
  targeted, and ``miss_rate``, missed of processed) also as a Wilson score interval over the
  counts pooled across the episodes, which stays inside [0, 1] and is meaningful with few
  episodes;
- per reason, the controllers' untargeted objects (``untargeted``), their share of the objects
  a station's controller decided about (``untargeted_share``, per station) and the drops
  (``dropped_by_reason``), each with a Student t interval.

``sweep.json``'s ``headline`` lists the grid's ``headline`` metrics first, one row per grid
cell and metric (the line's, or each station's for a per-station metric such as
``unfit_share``) with mean, interval and, for a rate, the pooled value and its Wilson
interval: the figures a benchmark grid (``experiments/grids/``) exists to measure.

A grid's ``seeds`` must be distinct: a seed run twice in a cell would count one sample as two
and narrow the interval for nothing; each is in ``[0, 2**64 - 1]``.

``--out`` is refused when it exists and is not empty, unless ``--replace`` is given and it is a
sweep's folder (its ``.cdw-sweep`` marker), which is then replaced whole
(:mod:`experiments.outdir`). With ``--backend ray`` the driver connects to Ray before it writes
anything, within ``--connect-timeout`` seconds (:mod:`experiments.ray_backend`), so a sweep that
cannot reach Ray leaves no folder and ``sweep.json`` names ``ray`` only when its episodes ran
there. A table that cannot be written (a full disk) stops the sweep: the running episodes are
cancelled, ``sweep.json`` says ``"complete": false`` and why in ``stopped`` (rewritten in place
when no new file can be created), and the command exits 1.

An interrupted sweep (Ctrl-C, SIGTERM) stops the running episodes, keeps every finished one in
its cell's tables and writes ``"complete": false`` with ``"stopped"`` (``--json`` prints it,
and the command exits 130); so does a sweep in which an episode failed (the other episodes
still run; exit 1). A failed episode (see :mod:`experiments.run`: its twin or a controller died,
or the twin left no complete summary) is a row of its cell's ``episodes.json`` with
``"failed": true`` and its ``"reason"``, is listed in its cell's ``failures`` and counted in
``failed``, and is left out of every mean and interval: a cell's ``episodes`` counts only the
episodes that succeeded.
"""

from __future__ import annotations

import argparse
import collections
import concurrent.futures
import contextlib
import csv
import dataclasses
import io
import itertools
import json
import re
import signal
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from experiments.stats import student_t_interval, wilson_interval
from interfaces.dataclass_io import from_data
from interfaces.errors import CdwTwinError, ConfigError, cut, cut_message
from interfaces.fileio import overwrite_in_place, write_atomic
from interfaces.metrics import BY_NAME, METRICS, RATES, Scope, in_scope
from interfaces.run_folder import RunFolder
from interfaces.run_records import EpisodeMetrics, EpisodeRow, RunInfo
from interfaces.run_records import succeeded as good_rows
from interfaces.yamlio import load_yaml_file

if TYPE_CHECKING:
    from experiments.run_types import EpisodeSpec, RunOptions, Transport
    from interfaces.cell import Cell
    from twin.scenario import Scenario


def _pooled_rates(scope: Scope) -> dict[str, tuple[str, str]]:
    return {m.name: m.ratio_of for m in RATES if scope in m.scopes and m.ratio_of is not None}


CI_METRICS = in_scope("line")
"""Metrics aggregated with Student t intervals: every line metric of the table."""

WILSON_RATES = _pooled_rates("line")
"""Rates also given as Wilson intervals: (successes, trials) counts pooled over episodes, the
table's ``ratio_of`` of every line rate."""

STATION_CI_METRICS = in_scope("station")
"""The per-station metrics aggregated with Student t intervals."""

STATION_WILSON_RATES = _pooled_rates("station")
"""The per-station rates also given as Wilson intervals."""

CLASS_CI_METRICS = in_scope("class")
"""The per-class metrics aggregated with Student t intervals."""

CLASS_WILSON_RATES = _pooled_rates("class")
"""The per-class rates also given as Wilson intervals."""

MAX_GRID_EPISODES = 100_000
"""Most seeds (or episodes) of one grid cell."""

MAX_SEED = 2**64 - 1
"""Largest seed (:data:`twin.scenario.MAX_SEED`)."""

REASON_BLOCKS = ("untargeted", "untargeted_share", "dropped_by_reason")
"""The per-reason blocks of an episode's metrics (the controllers' untargeted objects, their
share of the objects that entered a station's window, drops), each reason aggregated with a
Student t interval (a reason missing from an episode counts 0 there)."""


@dataclass(frozen=True)
class GridOverrides:
    """Values to sweep; each non-empty list multiplies the cells.

    ``cell``: the cell the scenario runs on (a shipped cell's name or a path relative to the
    grid file) instead of its own. ``stations``: run only the first k stations of the
    scenario's cell (in the cell file's order: a line lists its stations upstream first), so
    one grid gives a figure against the number of stations; the truncated cell is what the grid
    cell's run folder keeps as ``cell.yaml``.
    """

    speed: tuple[float, ...] = ()
    duration_s: tuple[float, ...] = ()
    mode: tuple[Literal["lockstep", "realtime"], ...] = ()
    cell: tuple[str, ...] = ()
    stations: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        for i, k in enumerate(self.stations):
            if k < 1:
                msg = f"overrides.stations[{i}] = {k!r}: must be >= 1 (the first k stations)"
                raise ConfigError(msg)
        for i, name in enumerate(self.cell):
            if not name:
                msg = f"overrides.cell[{i}] = {name!r}: name a shipped cell or a cell file"
                raise ConfigError(msg)
        for i, v in enumerate(self.speed):
            if not 0.0 <= v <= 2.0:
                msg = f"overrides.speed[{i}] = {v!r}: must be in [0, 2] m/s"
                raise ConfigError(msg)
        for i, v in enumerate(self.duration_s):
            if not 0.0 < v <= 86400.0:
                msg = f"overrides.duration_s[{i}] = {v!r}: must be in (0, 86400] s"
                raise ConfigError(msg)


@dataclass(frozen=True)
class Grid:
    """A sweep: scenario files, seeds (or an episode count) and overrides."""

    scenarios: tuple[str, ...] = ()
    seeds: tuple[int, ...] = ()
    episodes: int | None = None
    overrides: GridOverrides = field(default_factory=GridOverrides)
    dataset: str | None = None
    headline: tuple[str, ...] = ()
    """Metrics of the table that ``sweep.json`` lists first, per grid cell (``headline``):
    the figures the grid exists to measure."""

    def __post_init__(self) -> None:
        for i, name in enumerate(self.headline):
            if name not in BY_NAME:
                msg = f"headline[{i}] = {name!r}: not a metric of the table (docs/metrics.md)"
                raise ConfigError(msg)
        if not self.scenarios:
            msg = "scenarios = []: list at least one scenario file"
            raise ConfigError(msg)
        if self.seeds and self.episodes is not None:
            msg = "seeds and episodes: give one of them, not both"
            raise ConfigError(msg)
        if self.episodes is not None and self.episodes < 1:
            msg = f"episodes = {self.episodes}: must be >= 1"
            raise ConfigError(msg)
        if self.episodes is not None and self.episodes > MAX_GRID_EPISODES:
            msg = f"episodes = {self.episodes}: at most {MAX_GRID_EPISODES}"
            raise ConfigError(msg)
        if len(self.seeds) > MAX_GRID_EPISODES:
            msg = f"seeds: {len(self.seeds)} seeds, at most {MAX_GRID_EPISODES}"
            raise ConfigError(msg)
        for i, seed in enumerate(self.seeds):
            if not 0 <= seed <= MAX_SEED:
                msg = f"seeds[{i}] = {cut(seed)}: must be in [0, 2**64 - 1]"
                raise ConfigError(msg)
        counts = collections.Counter(self.seeds)
        repeated = sorted(seed for seed, n in counts.items() if n > 1)
        if repeated:
            shown = ", ".join(map(str, repeated[:8])) + (", ..." if len(repeated) > 8 else "")
            msg = (
                f"seeds = {cut(list(self.seeds))}: seed(s) {shown} repeated; "
                "every seed of a cell must be distinct (a repeat fakes a narrower interval)"
            )
            raise ConfigError(msg)

    @classmethod
    def load(cls, path: Path) -> Grid:
        """Read a grid file (:func:`interfaces.yamlio.load_yaml_file`: size-capped, UTF-8, a key
        given twice refused, alias bombs refused); errors name the file and the key."""
        data = load_yaml_file(path, what="grid")
        if not isinstance(data, dict):
            msg = f"{path}: the top level must be a mapping"
            raise ConfigError(msg)
        try:
            return from_data(cls, data, "")
        except ConfigError as exc:
            msg = cut_message(f"{path}: {exc}")
            raise ConfigError(msg) from None


@dataclass(frozen=True, kw_only=True)
class GridCell:
    """One grid cell: a resolved scenario, its run mode, seeds and folder name."""

    name: str
    scenario: Scenario
    scenario_path: Path
    mode: Literal["lockstep", "realtime"]
    seeds: tuple[int, ...]
    overrides: dict[str, Any]
    stations: int | None = None
    """Run only the first ``stations`` stations of the scenario's cell (None: all of them)."""


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "cell"


def _override_cell(value: str, base: Path) -> str:
    """A grid's ``cell`` override as a scenario's ``cell``: a shipped name as it is, a path
    made absolute from the grid file's folder."""
    if "/" in value or value.endswith((".yaml", ".yml")):
        path = Path(value).expanduser()
        return str(path if path.is_absolute() else (base / path).resolve())
    return value


def _apply(scenario: Scenario, chosen: dict[str, Any], base: Path) -> Scenario:
    """``scenario`` with the overrides of one grid cell applied (validated by the dataclass)."""
    resolved = scenario
    if "speed" in chosen:
        system = dataclasses.replace(resolved.system, belt_speed_mps=chosen["speed"])
        resolved = dataclasses.replace(resolved, system=system)
    if "duration_s" in chosen:
        resolved = dataclasses.replace(resolved, duration_s=chosen["duration_s"])
    if "cell" in chosen:
        resolved = dataclasses.replace(resolved, cell=_override_cell(chosen["cell"], base))
    return resolved


def expand(grid: Grid, base: Path) -> list[GridCell]:
    """The grid's cells in a fixed order (scenarios, then overrides as a product).

    Every scenario is loaded and every override applied (and validated) here, before anything
    runs. ``base`` is the grid file's folder.
    """
    from twin.scenario import Scenario

    axes = [(k, v) for k, v in dataclasses.asdict(grid.overrides).items() if v]
    names = [k for k, _ in axes]
    cells: list[GridCell] = []
    for entry in grid.scenarios:
        path = (base / entry).resolve()
        scenario = Scenario.load(path)
        for values in itertools.product(*(v for _, v in axes)):
            chosen = dict(zip(names, values, strict=True))
            resolved = _apply(scenario, chosen, base)
            seeds = grid.seeds or tuple(
                resolved.seed + i for i in range(grid.episodes if grid.episodes else 1)
            )
            suffix = "".join(f"-{k}{Path(v).stem if k == 'cell' else v}" for k, v in chosen.items())
            cells.append(
                GridCell(
                    name=_slug(f"{scenario.name}{suffix}"),
                    scenario=resolved,
                    scenario_path=path,
                    mode=chosen.get("mode", "lockstep"),
                    seeds=seeds,
                    overrides=chosen,
                    stations=chosen.get("stations"),
                )
            )
    seen: dict[str, int] = {}
    unique = []
    for cell in cells:
        n = seen.get(cell.name, 0)
        seen[cell.name] = n + 1
        unique.append(cell if n == 0 else dataclasses.replace(cell, name=f"{cell.name}-{n}"))
    return unique


def _own_dataset(grid: Grid, grid_path: Path, cell: GridCell) -> Path | None:
    """The dataset a cell names (the grid's, else its scenario's), None for the built-in one."""
    if grid.dataset is not None:
        return (grid_path.parent / grid.dataset).resolve()
    if cell.scenario.dataset != "builtin":
        return (cell.scenario_path.parent / cell.scenario.dataset).resolve()
    return None


def _interval(values: Sequence[float]) -> dict[str, Any]:
    mean, low, high = student_t_interval(values)
    return {"mean": mean, "ci95_low": low, "ci95_high": high, "n": len(values)}


def _pooled(rows: Sequence[dict[str, Any]], num: str, den: str) -> dict[str, Any]:
    successes = sum(int(r.get(num) or 0) for r in rows)
    trials = sum(int(r.get(den) or 0) for r in rows)
    low, high = wilson_interval(successes, trials)
    return {
        "successes": successes,
        "trials": trials,
        "pooled": successes / trials if trials else None,
        "ci95_low": low,
        "ci95_high": high,
    }


def aggregate_reasons(rows: Sequence[dict[str, Any]], block: str) -> dict[str, dict[str, Any]]:
    """Per reason of the episodes' ``block`` (:data:`REASON_BLOCKS`), its mean with a Student t
    interval over the episodes that have the block (a reason one of them lacks counts 0 there);
    reasons sorted."""
    blocks = [r[block] for r in rows if isinstance(r.get(block), dict)]
    reasons = sorted({str(k) for b in blocks for k in b})
    return {reason: _interval([float(b.get(reason) or 0.0) for b in blocks]) for reason in reasons}


def aggregate_cell(
    rows: Sequence[dict[str, Any]],
    metrics: Sequence[str] = CI_METRICS,
    rates: dict[str, tuple[str, str]] | None = None,
) -> dict[str, Any]:
    """Per-metric ``{mean, ci95_low, ci95_high, n}``, pooled Wilson intervals of the rates and,
    per reason, the untargeted objects and the drops (:data:`REASON_BLOCKS`, those the rows
    have).

    ``rows`` are rows of ``episodes.json`` as written (:meth:`EpisodeMetrics.to_data`; or their
    ``stations`` or ``classes`` blocks, with ``metrics`` and ``rates`` of that scope); a metric
    that is None in an episode (e.g. no settled pursuit) leaves that episode out of that metric
    only. Failed episodes (``"failed": true``) are counted in ``failed`` and left out of
    everything else.
    """
    rates = WILSON_RATES if rates is None else rates
    failed = sum(1 for r in rows if r.get("failed"))
    rows = [r for r in rows if not r.get("failed")]
    out: dict[str, Any] = {"episodes": len(rows), "failed": failed, "metrics": {}, "wilson": {}}
    for key in metrics:
        out["metrics"][key] = _interval([float(r[key]) for r in rows if r.get(key) is not None])
    for rate, (num, den) in rates.items():
        out["wilson"][rate] = _pooled(rows, num, den)
    for block in REASON_BLOCKS:
        if any(block in r for r in rows):
            out[block] = aggregate_reasons(rows, block)
    return out


def _aggregate_entries(
    rows: Sequence[dict[str, Any]],
    block: str,
    metrics: Sequence[str],
    rates: dict[str, tuple[str, str]],
) -> dict[str, dict[str, Any]]:
    good = [r for r in rows if not r.get("failed")]
    names: dict[str, None] = {}
    for row in good:
        names.update(dict.fromkeys(row.get(block) or {}))
    return {
        name: aggregate_cell(
            [r[block][name] for r in good if name in (r.get(block) or {})], metrics, rates
        )
        for name in names
    }


def aggregate_stations(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """:func:`aggregate_cell` of each station's block over the successful episodes."""
    return _aggregate_entries(rows, "stations", STATION_CI_METRICS, STATION_WILSON_RATES)


def aggregate_classes(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """:func:`aggregate_cell` of each object class's block (the line's, per class: recovery,
    purity, ...) over the successful episodes; classes sorted."""
    out = _aggregate_entries(rows, "classes", CLASS_CI_METRICS, CLASS_WILSON_RATES)
    return dict(sorted(out.items()))


def headline(cell: dict[str, Any], names: Sequence[str]) -> list[dict[str, Any]]:
    """The grid's ``headline`` metrics of one grid cell's entry of ``sweep.json``: one row per
    metric and scope (the line's when the table gives the metric for the line, else each
    station's), with the mean, its 95 % Student t interval over the seeds and, for a rate, the
    pooled value with its Wilson interval."""
    agg = cell["aggregate"]
    rows = []
    for name in names:
        scopes = (
            [("line", agg)]
            if "line" in BY_NAME[name].scopes
            else [(f"station {s}", a) for s, a in (agg.get("stations") or {}).items()]
        )
        for scope, block in scopes:
            row: dict[str, Any] = {
                "cell": cell["cell"],
                "stations": len(cell["stations"]),
                "speed_mps": cell["speed_mps"],
                "metric": name,
                "scope": scope,
                **block["metrics"].get(name, _interval([])),
            }
            wilson = block["wilson"].get(name)
            if wilson is not None:
                row["pooled"] = wilson["pooled"]
                row["wilson_low"] = wilson["ci95_low"]
                row["wilson_high"] = wilson["ci95_high"]
            rows.append(row)
    return rows


CSV_HEADER = (
    "cell",
    "station",
    "scenario",
    "mode",
    "speed_mps",
    "duration_s",
    "episodes",
    "failed",
)
"""The leading columns of ``sweep.csv``; then mean and interval of every metric and rate."""

CSV_METRICS = tuple(m.name for m in METRICS if {"line", "station"} & set(m.scopes))
"""The metric columns of ``sweep.csv``: every metric given for the line or per station."""

CSV_RATES = {**WILSON_RATES, **STATION_WILSON_RATES}
"""The pooled-rate columns of ``sweep.csv``."""


def _csv_row(cell: dict[str, Any], station: str, agg: dict[str, Any]) -> list[Any]:
    row: list[Any] = [
        cell["cell"],
        station,
        cell["scenario"],
        cell["mode"],
        cell["speed_mps"],
        cell["duration_s"],
        agg["episodes"],
        agg.get("failed", 0),
    ]
    for key in CSV_METRICS:
        m = agg["metrics"].get(key)
        row += [None, None, None] if m is None else [m["mean"], m["ci95_low"], m["ci95_high"]]
    for rate in CSV_RATES:
        w = agg["wilson"].get(rate)
        row += [None, None, None] if w is None else [w["pooled"], w["ci95_low"], w["ci95_high"]]
    return ["" if v is None else v for v in row]


def sweep_csv(cells: Sequence[dict[str, Any]]) -> str:
    """``sweep.csv``: one row per grid cell (``station`` empty: the line), mean and interval of
    every metric, and for a cell of several stations one more row per station (a metric not
    given per station, or not for the line, is left empty; in a cell of one station the line
    is the station, so its row also gives the per-station metrics, such as ``unfit_share``)."""
    header = list(CSV_HEADER)
    for key in CSV_METRICS:
        header += [f"{key}_mean", f"{key}_ci95_low", f"{key}_ci95_high"]
    for rate in CSV_RATES:
        header += [f"{rate}_pooled", f"{rate}_wilson_low", f"{rate}_wilson_high"]
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow(header)
    for cell in cells:
        agg = cell["aggregate"]
        stations = agg.get("stations") or {}
        if len(stations) == 1:
            (only,) = stations.values()
            agg = {
                **agg,
                "metrics": {**only["metrics"], **agg["metrics"]},
                "wilson": {**only["wilson"], **agg["wilson"]},
            }
        writer.writerow(_csv_row(cell, "", agg))
        if len(stations) > 1:
            for name, station_agg in stations.items():
                writer.writerow(_csv_row(cell, name, station_agg))
    return buffer.getvalue()


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the sweep options."""
    from experiments.run import add_replace_option, add_transport_option

    parser.add_argument("grid", type=Path, help="grid YAML (scenarios, seeds, overrides)")
    parser.add_argument("--workers", type=_workers_argument, default=1, help="episodes at once (1)")
    parser.add_argument("--out", type=Path, default=None, help="sweep folder (default runs/...)")
    add_replace_option(parser, "sweep")
    parser.add_argument(
        "--dataset", type=Path, default=None, help="meshgen output folder (overrides the grid's)"
    )
    parser.add_argument("--json", action="store_true", help="print the sweep summary as JSON")
    add_transport_option(parser)
    parser.add_argument(
        "--record",
        action="store_true",
        help="write each episode's recording.mcap (off: a grid of thousands of episodes would "
        "write about 10 MB a minute each)",
    )
    parser.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="local: a pool of --workers threads (default); ray: one Ray task per episode",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="Ray cluster address (ray backend; default: start Ray here with --workers CPUs)",
    )
    parser.add_argument(
        "--cpus-per-episode",
        type=float,
        default=None,
        help="CPUs a Ray task declares (default: the measured 1.0 of a lockstep episode)",
    )
    parser.add_argument(
        "--connect-timeout",
        type=float,
        default=None,
        metavar="SECONDS",
        help="longest wait for Ray to connect or start (ray backend; default 120)",
    )


MAX_WORKERS = 256
"""Most episodes a sweep runs at once on this machine."""


def _workers_argument(text: str) -> int:
    """``--workers``: an integer in ``[1, MAX_WORKERS]`` (argparse's one-line error else)."""
    try:
        value = int(text)
    except ValueError:
        msg = f"invalid int value: {text[:40]!r}"
        raise argparse.ArgumentTypeError(msg) from None
    if not 1 <= value <= MAX_WORKERS:
        msg = f"must be in [1, {MAX_WORKERS}], not {value}"
        raise argparse.ArgumentTypeError(msg)
    return value


@dataclass
class CellRun:
    """One grid cell being run: its run folder, options, finished rows and failures."""

    cell: GridCell
    folder: Path
    options: RunOptions
    info: RunInfo
    rows: dict[int, EpisodeRow] = field(default_factory=dict)
    failures: list[str] = field(default_factory=list)

    def ordered_rows(self) -> list[EpisodeRow]:
        """The finished rows in episode order."""
        return [self.rows[k] for k in sorted(self.rows)]

    def episodes(self) -> list[EpisodeSpec]:
        """One episode per seed of the grid cell."""
        from experiments.run_types import EpisodeSpec

        return [
            EpisodeSpec(index=i, seed=seed, folder=RunFolder(self.folder).episode(i).path)
            for i, seed in enumerate(self.cell.seeds)
        ]

    def summary(self) -> dict[str, Any]:
        """The cell's entry of ``sweep.json``."""
        rows = [row.to_data() for row in self.ordered_rows()]  # pooled as written
        agg = aggregate_cell(rows)
        agg["stations"] = aggregate_stations(rows)
        agg["classes"] = aggregate_classes(rows)
        scenario = self.cell.scenario
        return {
            "cell": self.cell.name,
            "folder": str(self.folder),
            "scenario": scenario.name,
            "stations": list(self.options.stations),
            "mode": self.cell.mode,
            "speed_mps": scenario.system.belt_speed_mps,
            "duration_s": scenario.duration_s,
            "overrides": self.cell.overrides,
            "complete": agg["episodes"] == len(self.cell.seeds),
            "failed": agg["failed"],
            "failures": self.failures,
            "aggregate": agg,
        }


@dataclass(frozen=True, kw_only=True)
class _Checked:
    """A grid cell validated before anything is written: its cell, parameters and dataset."""

    cell: GridCell
    params: Path
    station_cell: Cell
    dataset: Path
    own_dataset: Path | None


def first_stations(cell: Cell, k: int, where: str) -> Cell:
    """``cell`` with only its first ``k`` stations (named ``<name>_first<k>``); errors name
    ``where`` (the grid file) and the cell file when it has fewer."""
    n = len(cell.stations)
    if k > n:
        msg = (
            f"{where}: overrides.stations = {k}: the cell {cell.source or cell.name} has "
            f"{n} station(s)"
        )
        raise ConfigError(msg)
    if k == n:
        return cell
    return dataclasses.replace(cell, name=f"{cell.name}_first{k}", stations=cell.stations[:k])


def _check_cells(grid: Grid, grid_path: Path) -> list[_Checked]:
    """Every grid cell's scenario, cell file, controller parameters and dataset, checked."""
    from experiments.run import controller_params
    from twin.builtin import builtin_dataset
    from twin.scenario import scenario_cell
    from twin.scenario_check import check_scenario

    checked = []
    for cell in expand(grid, grid_path.parent):
        where = str(cell.scenario_path)
        station_cell = scenario_cell(cell.scenario, cell.scenario_path.parent, where)
        if cell.stations is not None:
            station_cell = first_stations(station_cell, cell.stations, str(grid_path))
        own = _own_dataset(grid, grid_path, cell)
        dataset = own or builtin_dataset()
        selection = check_scenario(cell.scenario, dataset, where=where, cell=station_cell)
        station_cell = selection.cell or station_cell
        params = controller_params(
            cell.scenario.controller, cell.scenario_path.parent, station_cell
        )
        checked.append(
            _Checked(
                cell=cell,
                params=params,
                station_cell=station_cell,
                dataset=dataset,
                own_dataset=own,
            )
        )
    return checked


def load_grid(grid_path: Path, dataset: Path | None = None) -> Grid:
    """The grid file, its ``dataset`` replaced by ``dataset`` (a path from the command line,
    relative to the working directory) when given."""
    grid = Grid.load(grid_path)
    if dataset is not None:
        grid = dataclasses.replace(grid, dataset=str(dataset.expanduser().resolve()))
    return grid


def check_sweep(
    grid_path: Path, *, dataset: Path | None = None, transport: Transport = "ros"
) -> tuple[Grid, list[_Checked]]:
    """Load the grid (its dataset replaced by ``dataset``, :func:`load_grid`) and check every
    grid cell's scenario, cell, controller parameters, dataset and transport; nothing is
    written."""
    from experiments.run import check_transport

    grid = load_grid(grid_path, dataset)
    checked = _check_cells(grid, grid_path)
    for c in checked:
        try:
            check_transport(transport, c.cell.mode, c.cell.scenario.faults.controller_restart_at_s)
        except CdwTwinError as exc:
            msg = f"{grid_path}: grid cell {c.cell.name}: {exc}"
            raise ConfigError(msg) from exc
    return grid, checked


def write_sweep(
    checked: Sequence[_Checked], out: Path, *, transport: Transport = "ros", record: bool = False
) -> list[CellRun]:
    """Write each checked grid cell's run folder under ``out`` (``scenario.yaml``,
    ``cell.yaml``, ``controller.yaml``, empty tables); an ``OSError`` becomes an
    :class:`experiments.outdir.OutputError` naming ``out``."""
    from experiments.outdir import OutputError, reason
    from experiments.run import run_options, write_run_scenario
    from experiments.scoring import write_run_tables

    runs = []
    try:
        for c in checked:
            folder = out / c.cell.name
            files = write_run_scenario(
                c.cell.scenario, c.params, c.station_cell, folder, c.own_dataset
            )
            options = dataclasses.replace(
                run_options(files, c.station_cell, c.cell.scenario, c.dataset, c.cell.mode),
                transport=transport,
                record=record,
            )
            info = RunInfo(
                scenario=c.cell.scenario.name,
                scenario_path=str(c.cell.scenario_path),
                dataset=str(options.dataset),
                cell=c.station_cell.name,
                stations=tuple(options.stations),
                mode=c.cell.mode,
                transport=transport,
                record=record,
                speed_mps=c.cell.scenario.system.belt_speed_mps,
                duration_s=c.cell.scenario.duration_s,
                overrides=c.cell.overrides,
                episodes_planned=len(c.cell.seeds),
            )
            runs.append(CellRun(cell=c.cell, folder=folder, options=options, info=info))
            write_run_tables(RunFolder(folder), [], complete=False, info=info)
    except OSError as exc:
        msg = f"--out {out}: cannot write the sweep folder: {reason(exc)}"
        raise OutputError(msg) from None
    return runs


def prepare_sweep(
    grid_path: Path,
    out: Path,
    *,
    dataset: Path | None = None,
    transport: Transport = "ros",
    record: bool = False,
    replace: bool = False,
) -> list[CellRun]:
    """Check every grid cell (before anything is written, :func:`check_sweep`), make ``out``
    a fresh sweep folder (an existing non-empty one is refused unless ``replace`` and it is a
    sweep's: :func:`experiments.outdir.fresh_output`), then write each grid cell's run folder
    (:func:`write_sweep`). ``dataset`` overrides the grid's (:func:`load_grid`); every episode
    runs on ``transport``, recorded when ``record``."""
    from experiments.outdir import SWEEP, check_output, fresh_output

    check_output(out, SWEEP, replace=replace)
    _, checked = check_sweep(grid_path, dataset=dataset, transport=transport)
    fresh_output(out, SWEEP, replace=replace)
    return write_sweep(checked, out, transport=transport, record=record)


class Sweep:
    """The state of a running sweep: every grid cell's rows, shared by the worker threads
    under one lock, written to ``sweep.json``/``sweep.csv`` and the cells' tables as episodes
    finish."""

    def __init__(
        self,
        grid_path: Path,
        out: Path,
        workers: int,
        runs: list[CellRun],
        *,
        quiet: bool = False,
        headline: Sequence[str] = (),
    ) -> None:
        self.grid_path = grid_path
        self.headline = tuple(headline)
        self.out = out
        self.workers = workers
        self.runs = runs
        self.jobs = [(r, e) for r in runs for e in r.episodes()]
        self.lock = threading.Lock()
        self.cancel = threading.Event()
        self.stopped: list[str] = []
        self.write_errors: list[str] = []
        self.retried: list[str] = []
        self.backend: dict[str, Any] = {"name": "local"}
        self.quiet = quiet
        self._wall0 = time.monotonic()

    def summary(self, complete: bool) -> dict[str, Any]:
        """The content of ``sweep.json``."""
        cells = [r.summary() for r in self.runs]
        data: dict[str, Any] = {
            "complete": complete,
            "grid": str(self.grid_path),
            "workers": self.workers,
            "episodes_planned": len(self.jobs),
            "episodes": sum(c["aggregate"]["episodes"] for c in cells),
            "failed": sum(c["failed"] for c in cells),
            "wall_s": time.monotonic() - self._wall0,
            "headline": [row for c in cells for row in headline(c, self.headline)],
            "cells": cells,
        }
        data["backend"] = self.backend
        if self.retried:
            data["retried"] = list(self.retried)
        stopped = [*self.stopped, *self.write_errors]
        if stopped:
            data["stopped"] = "; ".join(stopped)
        if self.write_errors:
            data["complete"] = False
        return data

    def write_all(self, complete: bool) -> dict[str, Any]:
        """Write ``sweep.json`` and ``sweep.csv``; returns the summary."""
        data = self.summary(complete)
        write_atomic(self.out / "sweep.json", json.dumps(data, indent=2) + "\n")
        write_atomic(self.out / "sweep.csv", sweep_csv(data["cells"]))
        return data

    def finish_cell(self, run: CellRun, final: bool) -> None:
        """Write one grid cell's run tables (``stopped`` on the final write of a cell that did
        not finish)."""
        from experiments.scoring import write_run_tables

        rows = run.ordered_rows()
        done = len(good_rows(rows)) == len(run.cell.seeds)
        info = run.info
        stopped = [*self.stopped, *self.write_errors]
        if not done and final and (run.failures or stopped):
            info = dataclasses.replace(info, stopped="; ".join(run.failures + stopped))
        write_run_tables(RunFolder(run.folder), rows, complete=done, info=info)

    def record(self, run: CellRun, index: int, row: EpisodeRow, failure: str = "") -> int:
        """Keep one finished (or failed) episode's row and write the tables; returns how many
        episodes have finished. A table that cannot be written stops the sweep
        (:meth:`write_failed`)."""
        with self.lock:
            run.rows[index] = row
            if failure:
                run.failures.append(failure)
            try:
                self.finish_cell(run, final=False)
                self.write_all(False)
            except OSError as exc:
                self.write_failed(exc)
            return sum(len(r.rows) for r in self.runs)

    def write_failed(self, exc: OSError) -> None:
        """A table could not be written (a full disk): the sweep stops (the running episodes
        are cancelled), ``stopped`` says why and the sweep ends as failed."""
        from experiments.outdir import reason

        why = f"cannot write the sweep's tables: {reason(exc)}"
        if why not in self.write_errors:
            self.write_errors.append(why)
            if not self.quiet:
                print(f"cdw-twin sweep: {why}; stopping", file=sys.stderr)
        self.cancel.set()

    def job(self, run: CellRun, episode: EpisodeSpec) -> None:
        """Run one episode (a worker thread's task) and record its row."""
        from experiments.episode_processes import (
            EpisodeCancelledError,
            EpisodeFailedError,
            run_episode,
        )
        from experiments.outdir import reason

        if self.cancel.is_set():
            return
        try:
            metrics = run_episode(run.options, episode, cancel=self.cancel)
        except EpisodeCancelledError:
            return
        except EpisodeFailedError as exc:
            self.finished(run, episode, None, exc.reason)
            return
        except OSError as exc:
            with self.lock:
                self.write_failed(exc)
            self.finished(run, episode, None, f"cannot write the episode folder: {reason(exc)}")
            return
        self.finished(run, episode, metrics, "")

    def finished(
        self, run: CellRun, episode: EpisodeSpec, metrics: EpisodeMetrics | None, reason: str
    ) -> None:
        """Record an episode that ran to its end (``metrics``) or failed (``reason``), whatever
        ran it."""
        from experiments.run import failed_row
        from experiments.scoring import failure_text

        speed = run.cell.scenario.system.belt_speed_mps
        if metrics is None:
            row = failed_row(episode, run.options.mode, reason, speed)
            self.record(run, episode.index, row, failure_text(episode.index, episode.seed, reason))
            if not self.quiet:
                print(
                    f"FAILED {run.cell.name}: episode {episode.index} (seed {episode.seed}): "
                    f"{reason}",
                    file=sys.stderr,
                )
            return
        done = self.record(run, episode.index, dataclasses.replace(metrics, speed_mps=speed))
        if not self.quiet:
            print(
                f"[{done}/{len(self.jobs)}] {run.cell.name} seed {episode.seed}: "
                f"placed {metrics.line['placed_correct']}, "
                f"rtf {metrics.line['real_time_factor'] or 0.0:.2f}",
                flush=True,
            )

    def execute(self) -> None:
        """Run every job on ``workers`` threads; Ctrl-C or SIGTERM cancels the running ones."""
        from experiments.run import raise_interrupt

        # SIGINT too: a process started in the background inherits SIGINT ignored, and Python
        # then installs no KeyboardInterrupt handler of its own
        previous = {s: signal.signal(s, raise_interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
        pool = concurrent.futures.ThreadPoolExecutor(max_workers=self.workers)
        try:
            futures = [pool.submit(self.job, *j) for j in self.jobs]
            pending = set(futures)
            while pending:
                _, pending = concurrent.futures.wait(pending, timeout=0.5)
            for f in futures:
                f.result()
        except KeyboardInterrupt as exc:
            self.stopped.append(f"interrupted ({exc.args[0] if exc.args else 'SIGINT'})")
            self.cancel.set()
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
            for signum, handler in previous.items():
                signal.signal(signum, handler)

    def finish(self) -> tuple[dict[str, Any], int]:
        """The final tables; returns the ``sweep.json`` content and the exit status (1 when
        an episode failed or a table could not be written, 130 when interrupted). When the
        tables cannot be written, ``sweep.json`` is rewritten in place saying so, if even
        that can be done (:func:`interfaces.fileio.overwrite_in_place`)."""
        failures = [f for r in self.runs for f in r.failures]
        if failures and not self.stopped:
            self.stopped.append(f"{len(failures)} episode(s) failed")
        with self.lock:
            try:
                for run in self.runs:
                    self.finish_cell(run, final=True)
                data = self.write_all(not self.stopped and not self.write_errors)
            except OSError as exc:
                self.write_failed(exc)
                data = self.summary(False)
                note = {k: data[k] for k in ("complete", "grid", "episodes", "failed", "stopped")}
                with contextlib.suppress(OSError):
                    overwrite_in_place(self.out / "sweep.json", json.dumps(note) + "\n")
        if data["complete"]:
            return data, 0
        interrupted = self.cancel.is_set() and not self.write_errors
        return data, 130 if interrupted else 1


@dataclass(frozen=True)
class Backend:
    """Where a sweep's episodes run: ``local`` (threads on this machine) or ``ray`` (tasks on
    the Ray cluster at ``address``, or on one started here; see :mod:`experiments.ray_backend`),
    each episode on ``transport`` (ROS 2 processes, or one process: ``inproc``), with its
    ``recording.mcap`` when ``record``."""

    name: Literal["local", "ray"] = "local"
    address: str | None = None
    cpus_per_episode: float | None = None
    transport: Transport = "ros"
    record: bool = False


def run_sweep(
    grid_path: Path,
    out: Path,
    workers: int,
    *,
    quiet: bool = False,
    dataset: Path | None = None,
    backend: Backend | None = None,
    replace: bool = False,
    connect_timeout_s: float | None = None,
) -> tuple[dict[str, Any], int]:
    """Run a grid (its dataset replaced by ``dataset`` when given) on ``backend`` (default: the
    local pool) into ``out``; returns the ``sweep.json`` content and the exit status.

    Before anything is written: ``out`` is checked (:func:`experiments.outdir.check_output`:
    an existing non-empty folder only with ``replace``, and only a sweep's), every grid cell
    (:func:`check_sweep`) and, with the Ray backend, the connection to Ray is made
    (:func:`experiments.ray_backend.connect`, bounded by ``connect_timeout_s``)."""
    from experiments.outdir import SWEEP, check_output, fresh_output

    if workers < 1:
        msg = f"--workers = {workers}: must be >= 1"
        raise ConfigError(msg)
    backend = backend or Backend()
    check_output(out, SWEEP, replace=replace)
    grid, checked = check_sweep(grid_path, dataset=dataset, transport=backend.transport)
    session = None
    if backend.name == "ray":
        from experiments.ray_backend import CONNECT_TIMEOUT_S, connect

        timeout_s = CONNECT_TIMEOUT_S if connect_timeout_s is None else connect_timeout_s
        session = connect(backend.address, workers, backend.cpus_per_episode, timeout_s=timeout_s)
    try:
        fresh_output(out, SWEEP, replace=replace)
        runs = write_sweep(checked, out, transport=backend.transport, record=backend.record)
        sweep = Sweep(grid_path, out, workers, runs, quiet=quiet, headline=grid.headline)
        if session is not None:
            sweep.backend = {"name": "ray", "address": backend.address or "local"}
        try:
            sweep.write_all(False)
        except OSError as exc:
            sweep.write_failed(exc)
        if not sweep.write_errors:  # nothing runs that could not be recorded
            if session is not None:
                session.execute(sweep)
            else:
                sweep.execute()
        return sweep.finish()
    finally:
        if session is not None:
            session.close()


def run(args: argparse.Namespace) -> int:
    """Run the sweep and print its summary."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out: Path = args.out or Path("runs") / f"sweep-{args.grid.stem}-{stamp}"
    connect_timeout_s = getattr(args, "connect_timeout", None)
    if args.backend != "ray" and (args.address or args.cpus_per_episode is not None):
        msg = "--address and --cpus-per-episode need --backend ray"
        raise ConfigError(msg)
    if args.backend != "ray" and connect_timeout_s is not None:
        msg = "--connect-timeout needs --backend ray"
        raise ConfigError(msg)
    backend = Backend(
        args.backend, args.address, args.cpus_per_episode, args.transport, args.record
    )
    data, code = run_sweep(
        args.grid,
        out,
        args.workers,
        quiet=args.json,
        dataset=args.dataset,
        backend=backend,
        replace=bool(getattr(args, "replace", False)),
        connect_timeout_s=connect_timeout_s,
    )
    if args.json:
        print(json.dumps(data))
    else:
        for row in data["headline"]:
            print(
                f"{row['cell']:>32}: {row['scope']} {row['metric']} {_fmt(row['mean'])} "
                f"[{_fmt(row['ci95_low'])}, {_fmt(row['ci95_high'])}] over {row['n']} seeds"
            )
        for cell in data["cells"]:
            agg = cell["aggregate"]
            sr = agg["metrics"]["success_rate"]
            w = agg["wilson"]["success_rate"]
            print(
                f"{cell['cell']:>32}: {agg['episodes']} ep, success "
                f"{_fmt(sr['mean'])} [{_fmt(sr['ci95_low'])}, {_fmt(sr['ci95_high'])}] "
                f"(Wilson [{_fmt(w['ci95_low'])}, {_fmt(w['ci95_high'])}])"
            )
        print(f"out: {out}  wall {data['wall_s']:.1f} s  complete: {data['complete']}")
    if not data["complete"]:
        print(f"cdw-twin sweep: incomplete: {data.get('stopped')}", file=sys.stderr)
    return code


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"
