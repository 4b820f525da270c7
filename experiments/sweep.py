"""``cdw-twin sweep GRID --workers N``: a grid of scenarios x overrides x seeds, in parallel.

Example grid file (paths relative to the grid file)::

    scenarios: [scenarios/default.yaml, scenarios/dense.yaml]
    seeds: [0, 1, 2]          # or: episodes: 3 (seeds scenario.seed, +1, ...)
    overrides:                # optional, expanded as a product with the scenarios
      speed: [0.2, 0.4, 0.6]
      duration_s: [30.0]
      mode: [lockstep]
    dataset: ../data/meshes   # optional; default: each scenario's own

Each cell (a scenario with one choice of every override) is a run folder with the layout of
``cdw-twin run`` (``scenario.yaml``, ``epNNN/``, ``episodes.json``, ``run.json``). Every
cell x seed is one episode through :func:`experiments.run.run_episode` on its own ROS domain;
``N`` run at once, each driven by a thread. ``sweep.json`` and ``sweep.csv`` hold per-cell
means with 95 % confidence intervals:

- every numeric metric: Student t interval over the cell's episodes,
  ``mean +- t(0.975, n-1) * s / sqrt(n)`` (none for n < 2);
- ``success_rate`` and ``miss_rate`` also as Wilson score intervals over the counts pooled
  across the episodes (placed_correct of targeted; missed of processed), which stay inside
  [0, 1] and are meaningful with few episodes.

A grid's ``seeds`` must be distinct: a seed run twice in a cell would count one sample as two
and narrow the interval for nothing.

An interrupted sweep (Ctrl-C, SIGTERM) stops the running episodes, keeps every finished one in
its cell's tables and writes ``"complete": false`` with ``"stopped"`` (``--json`` prints it,
and the command exits 130); so does a sweep in which an episode failed (the other episodes
still run; exit 1). A failed episode (see :mod:`experiments.run`: its twin or controller died,
or the twin left no complete summary) is a row of its cell's ``episodes.json`` with
``"failed": true`` and its ``"reason"``, is listed in its cell's ``failures`` and counted in
``failed``, and is left out of every mean and interval: a cell's ``episodes`` counts only the
episodes that succeeded.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import csv
import dataclasses
import io
import itertools
import json
import math
import re
import signal
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import yaml

from experiments.stats import wilson_interval
from interfaces.dataclass_io import from_data
from interfaces.fileio import write_atomic
from twin.errors import ConfigError

if TYPE_CHECKING:
    from twin.scenario import Scenario

CI_METRICS = (
    "picks",
    "placed_correct",
    "targeted",
    "untargeted_total",
    "success_rate",
    "miss_rate",
    "throughput_per_min",
    "tracking_time_4mm_mean_s",
    "tracking_time_4mm_p95_s",
    "real_time_factor",
    "faults",
    "controller_restarts",
)
"""Metrics aggregated with Student t intervals."""

WILSON_RATES = {
    "success_rate": ("placed_correct", "targeted"),
    "miss_rate": ("missed", "processed"),
}
"""Rates also given as Wilson intervals: (successes, trials) columns pooled over episodes."""


@dataclass(frozen=True)
class GridOverrides:
    """Values to sweep; each non-empty list multiplies the cells."""

    speed: tuple[float, ...] = ()
    duration_s: tuple[float, ...] = ()
    mode: tuple[Literal["lockstep", "realtime"], ...] = ()

    def __post_init__(self) -> None:
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

    def __post_init__(self) -> None:
        if not self.scenarios:
            msg = "scenarios = []: list at least one scenario file"
            raise ConfigError(msg)
        if self.seeds and self.episodes is not None:
            msg = "seeds and episodes: give one of them, not both"
            raise ConfigError(msg)
        if self.episodes is not None and self.episodes < 1:
            msg = f"episodes = {self.episodes}: must be >= 1"
            raise ConfigError(msg)
        for i, seed in enumerate(self.seeds):
            if seed < 0:
                msg = f"seeds[{i}] = {seed}: must be >= 0"
                raise ConfigError(msg)
        repeated = sorted({seed for seed in self.seeds if self.seeds.count(seed) > 1})
        if repeated:
            msg = (
                f"seeds = {list(self.seeds)}: seed(s) {', '.join(map(str, repeated))} repeated; "
                "every seed of a cell must be distinct (a repeat fakes a narrower interval)"
            )
            raise ConfigError(msg)

    @classmethod
    def load(cls, path: Path) -> Grid:
        """Read a grid file; errors name the file and the key."""
        try:
            data = yaml.safe_load(path.read_text(encoding="utf-8"))
        except OSError as exc:
            msg = f"{path}: cannot read grid: {exc.strerror}"
            raise ConfigError(msg) from None
        except yaml.YAMLError as exc:
            msg = f"{path}: not valid YAML: {exc}"
            raise ConfigError(msg) from None
        if not isinstance(data, dict):
            msg = f"{path}: the top level must be a mapping"
            raise ConfigError(msg)
        try:
            return from_data(cls, data, "")
        except ConfigError as exc:
            msg = f"{path}: {exc}"
            raise ConfigError(msg) from None


@dataclass(frozen=True, kw_only=True)
class Cell:
    """One grid cell: a resolved scenario, its run mode, seeds and folder name."""

    name: str
    scenario: Scenario
    scenario_path: Path
    mode: Literal["lockstep", "realtime"]
    seeds: tuple[int, ...]
    overrides: dict[str, Any]


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "cell"


def expand(grid: Grid, base: Path) -> list[Cell]:
    """The grid's cells in a fixed order (scenarios, then overrides as a product).

    Every scenario is loaded and every override applied (and validated) here, before anything
    runs. ``base`` is the grid file's folder.
    """
    from twin.scenario import Scenario

    axes = [(k, v) for k, v in dataclasses.asdict(grid.overrides).items() if v]
    names = [k for k, _ in axes]
    cells: list[Cell] = []
    for entry in grid.scenarios:
        path = (base / entry).resolve()
        scenario = Scenario.load(path)
        for values in itertools.product(*(v for _, v in axes)):
            chosen = dict(zip(names, values, strict=True))
            resolved = scenario
            if "speed" in chosen:
                system = dataclasses.replace(resolved.system, belt_speed_mps=chosen["speed"])
                resolved = dataclasses.replace(resolved, system=system)
            if "duration_s" in chosen:
                resolved = dataclasses.replace(resolved, duration_s=chosen["duration_s"])
            seeds = grid.seeds or tuple(
                resolved.seed + i for i in range(grid.episodes if grid.episodes else 1)
            )
            suffix = "".join(f"-{k}{v}" for k, v in chosen.items())
            cells.append(
                Cell(
                    name=_slug(f"{scenario.name}{suffix}"),
                    scenario=resolved,
                    scenario_path=path,
                    mode=chosen.get("mode", "lockstep"),
                    seeds=seeds,
                    overrides=chosen,
                )
            )
    seen: dict[str, int] = {}
    unique = []
    for cell in cells:
        n = seen.get(cell.name, 0)
        seen[cell.name] = n + 1
        unique.append(cell if n == 0 else dataclasses.replace(cell, name=f"{cell.name}-{n}"))
    return unique


def _own_dataset(grid: Grid, grid_path: Path, cell: Cell) -> Path | None:
    """The dataset a cell names (the grid's, else its scenario's), None for the built-in one."""
    if grid.dataset is not None:
        return (grid_path.parent / grid.dataset).resolve()
    if cell.scenario.dataset != "builtin":
        return (cell.scenario_path.parent / cell.scenario.dataset).resolve()
    return None


def student_t_interval(values: Sequence[float]) -> tuple[float | None, float | None, float | None]:
    """Mean and 95 % Student t interval of ``values`` (interval None for fewer than 2)."""
    from scipy import stats

    n = len(values)
    if n == 0:
        return None, None, None
    mean = math.fsum(values) / n
    if n < 2:
        return mean, None, None
    sd = math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (n - 1))
    half = float(stats.t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
    return mean, mean - half, mean + half


def aggregate_cell(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Per-metric ``{mean, ci95_low, ci95_high, n}`` and pooled Wilson intervals of the rates.

    ``rows`` are :func:`experiments.run.episode_metrics` dicts; a metric that is None in an
    episode (e.g. no settled pursuit) leaves that episode out of that metric only. Failed
    episodes (``"failed": true``) are counted in ``failed`` and left out of everything else.
    """
    failed = sum(1 for r in rows if r.get("failed"))
    rows = [r for r in rows if not r.get("failed")]
    out: dict[str, Any] = {"episodes": len(rows), "failed": failed, "metrics": {}, "wilson": {}}
    for key in CI_METRICS:
        values = [float(r[key]) for r in rows if r.get(key) is not None]
        mean, low, high = student_t_interval(values)
        out["metrics"][key] = {"mean": mean, "ci95_low": low, "ci95_high": high, "n": len(values)}
    for rate, (num, den) in WILSON_RATES.items():
        successes = sum(int(r.get(num) or 0) for r in rows)
        trials = sum(int(r.get(den) or 0) for r in rows)
        low, high = wilson_interval(successes, trials)
        out["wilson"][rate] = {
            "successes": successes,
            "trials": trials,
            "pooled": successes / trials if trials else None,
            "ci95_low": low,
            "ci95_high": high,
        }
    return out


def sweep_csv(cells: Sequence[dict[str, Any]]) -> str:
    """``sweep.csv``: one row per cell, mean and interval of every metric."""
    header = ["cell", "scenario", "mode", "speed_mps", "duration_s", "episodes", "failed"]
    for key in CI_METRICS:
        header += [f"{key}_mean", f"{key}_ci95_low", f"{key}_ci95_high"]
    for rate in WILSON_RATES:
        header += [f"{rate}_pooled", f"{rate}_wilson_low", f"{rate}_wilson_high"]
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow(header)
    for cell in cells:
        agg = cell["aggregate"]
        row: list[Any] = [
            cell["cell"],
            cell["scenario"],
            cell["mode"],
            cell["speed_mps"],
            cell["duration_s"],
            agg["episodes"],
            agg.get("failed", 0),
        ]
        for key in CI_METRICS:
            m = agg["metrics"][key]
            row += [m["mean"], m["ci95_low"], m["ci95_high"]]
        for rate in WILSON_RATES:
            w = agg["wilson"][rate]
            row += [w["pooled"], w["ci95_low"], w["ci95_high"]]
        writer.writerow(["" if v is None else v for v in row])
    return buffer.getvalue()


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the sweep options."""
    parser.add_argument("grid", type=Path, help="grid YAML (scenarios, seeds, overrides)")
    parser.add_argument("--workers", type=int, default=1, help="episodes at once (1)")
    parser.add_argument("--out", type=Path, default=None, help="sweep folder (default runs/...)")
    parser.add_argument("--json", action="store_true", help="print the sweep summary as JSON")


@dataclass
class _CellState:
    cell: Cell
    folder: Path
    extra: dict[str, Any]
    rows: dict[int, dict[str, Any]] = field(default_factory=dict)
    failures: list[str] = field(default_factory=list)


def run_sweep(
    grid_path: Path, out: Path, workers: int, *, quiet: bool = False
) -> tuple[dict[str, Any], int]:
    """Run a grid; returns the ``sweep.json`` content and the exit status."""
    from experiments.run import (
        EpisodeCancelledError,
        EpisodeFailedError,
        EpisodeSpec,
        RunOptions,
        controller_params,
        failed_row,
        failure_text,
        raise_interrupt,
        run_episode,
        write_run_scenario,
        write_tables,
    )
    from twin.builtin import builtin_dataset
    from twin.scenario_check import check_scenario

    if workers < 1:
        msg = f"--workers = {workers}: must be >= 1"
        raise ConfigError(msg)
    grid = Grid.load(grid_path)
    cells = expand(grid, grid_path.parent)
    params = {  # checked before anything starts
        cell.name: controller_params(cell.scenario.controller, cell.scenario_path.parent)
        for cell in cells
    }
    own_datasets = {cell.name: _own_dataset(grid, grid_path, cell) for cell in cells}
    datasets = {name: own or builtin_dataset() for name, own in own_datasets.items()}
    for cell in cells:
        check_scenario(cell.scenario, datasets[cell.name], where=str(cell.scenario_path))
    out.mkdir(parents=True, exist_ok=True)
    states: list[_CellState] = []
    jobs: list[tuple[_CellState, RunOptions, EpisodeSpec]] = []
    for cell in cells:
        own_dataset = own_datasets[cell.name]
        dataset = datasets[cell.name]
        folder = out / cell.name
        scenario_file, cell_params = write_run_scenario(
            cell.scenario, params[cell.name], folder, own_dataset
        )
        options = RunOptions(
            scenario_path=scenario_file.resolve(),
            dataset=dataset,
            controller_params=cell_params.resolve(),
            mode=cell.mode,
            duration_s=cell.scenario.duration_s,
            restart_at_s=cell.scenario.faults.controller_restart_at_s,
        )
        extra = {
            "scenario": cell.scenario.name,
            "scenario_path": str(cell.scenario_path),
            "dataset": str(dataset),
            "mode": cell.mode,
            "speed_mps": cell.scenario.system.belt_speed_mps,
            "duration_s": cell.scenario.duration_s,
            "overrides": cell.overrides,
            "episodes_planned": len(cell.seeds),
        }
        state = _CellState(cell=cell, folder=folder, extra=extra)
        states.append(state)
        write_tables(folder, [], complete=False, extra=extra)
        for i, seed in enumerate(cell.seeds):
            jobs.append(
                (state, options, EpisodeSpec(index=i, seed=seed, folder=folder / f"ep{i:03d}"))
            )
    lock = threading.Lock()
    cancel = threading.Event()
    stopped: list[str] = []
    wall0 = time.monotonic()

    def summary(complete: bool) -> dict[str, Any]:
        rows_out = []
        for st in states:
            rows = [st.rows[k] for k in sorted(st.rows)]
            agg = aggregate_cell(rows)
            rows_out.append(
                {
                    "cell": st.cell.name,
                    "folder": str(st.folder),
                    "scenario": st.cell.scenario.name,
                    "mode": st.cell.mode,
                    "speed_mps": st.cell.scenario.system.belt_speed_mps,
                    "duration_s": st.cell.scenario.duration_s,
                    "overrides": st.cell.overrides,
                    "complete": agg["episodes"] == len(st.cell.seeds),
                    "failed": agg["failed"],
                    "failures": st.failures,
                    "aggregate": agg,
                }
            )
        data: dict[str, Any] = {
            "complete": complete,
            "grid": str(grid_path),
            "workers": workers,
            "episodes_planned": len(jobs),
            "episodes": sum(c["aggregate"]["episodes"] for c in rows_out),
            "failed": sum(c["failed"] for c in rows_out),
            "wall_s": time.monotonic() - wall0,
            "cells": rows_out,
        }
        if stopped:
            data["stopped"] = "; ".join(stopped)
        return data

    def write_all(complete: bool) -> dict[str, Any]:
        data = summary(complete)
        write_atomic(out / "sweep.json", json.dumps(data, indent=2) + "\n")
        write_atomic(out / "sweep.csv", sweep_csv(data["cells"]))
        return data

    def finish_cell(st: _CellState, final: bool) -> None:
        rows = [st.rows[k] for k in sorted(st.rows)]
        done = sum(1 for r in rows if not r.get("failed")) == len(st.cell.seeds)
        extra = dict(st.extra)
        if not done and final and (st.failures or stopped):
            extra["stopped"] = "; ".join(st.failures + stopped)
        write_tables(st.folder, rows, complete=done, extra=extra)

    def job(state: _CellState, options: RunOptions, episode: EpisodeSpec) -> None:
        if cancel.is_set():
            return
        try:
            metrics = run_episode(options, episode, cancel=cancel)
        except EpisodeCancelledError:
            return
        except EpisodeFailedError as exc:
            row = failed_row(episode, options.mode, exc.reason)
            row["speed_mps"] = state.cell.scenario.system.belt_speed_mps
            with lock:
                state.rows[episode.index] = row
                state.failures.append(failure_text(episode.index, episode.seed, exc.reason))
                finish_cell(state, final=False)
                write_all(False)
            if not quiet:
                print(f"FAILED {state.cell.name}: {exc}", file=sys.stderr)
            return
        metrics["speed_mps"] = state.cell.scenario.system.belt_speed_mps
        with lock:
            state.rows[episode.index] = metrics
            finish_cell(state, final=False)
            write_all(False)
            done = sum(len(st.rows) for st in states)  # finished, failed or not
        if not quiet:
            print(
                f"[{done}/{len(jobs)}] {state.cell.name} seed {episode.seed}: "
                f"placed {metrics['placed_correct']}, rtf {metrics['real_time_factor']:.2f}",
                flush=True,
            )

    write_all(False)
    # SIGINT too: a process started in the background inherits SIGINT ignored, and Python then
    # installs no KeyboardInterrupt handler of its own
    previous = {s: signal.signal(s, raise_interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
    pool = concurrent.futures.ThreadPoolExecutor(max_workers=workers)
    try:
        futures = [pool.submit(job, *j) for j in jobs]
        pending = set(futures)
        while pending:
            _, pending = concurrent.futures.wait(pending, timeout=0.5)
        for f in futures:
            f.result()
    except KeyboardInterrupt as exc:
        stopped.append(f"interrupted ({exc.args[0] if exc.args else 'SIGINT'})")
        cancel.set()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    failures = [f for st in states for f in st.failures]
    complete = not stopped and not failures
    if failures and not stopped:
        stopped.append(f"{len(failures)} episode(s) failed")
    with lock:
        for st in states:
            finish_cell(st, final=True)
        data = write_all(complete)
    return data, 0 if complete else (130 if cancel.is_set() else 1)


def run(args: argparse.Namespace) -> int:
    """Run the sweep and print its summary."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out: Path = args.out or Path("runs") / f"sweep-{args.grid.stem}-{stamp}"
    data, code = run_sweep(args.grid, out, args.workers, quiet=args.json)
    if args.json:
        print(json.dumps(data))
    else:
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
