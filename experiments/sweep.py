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
import concurrent.futures
import contextlib
import dataclasses
import json
import signal
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from experiments.sweep_grid import (
    CheckedCell,
    GridCell,
    check_sweep,
)
from experiments.sweep_pooling import CellPool
from experiments.sweep_summary import (
    BackendNote,
    CellSummary,
    SweepSummary,
    headline,
    sweep_csv,
)
from interfaces.errors import ConfigError
from interfaces.fileio import overwrite_in_place, write_atomic
from interfaces.run_folder import RunFolder
from interfaces.run_records import EpisodeMetrics, EpisodeRow, RunInfo
from interfaces.run_records import succeeded as good_rows

if TYPE_CHECKING:
    from experiments.run_types import EpisodeSpec, RunOptions, Transport


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

    def summary(self) -> CellSummary:
        """The cell's entry of ``sweep.json``, pooled from its rows as written."""
        agg = CellPool.of(self.ordered_rows())
        scenario = self.cell.scenario
        return CellSummary(
            cell=self.cell.name,
            folder=str(self.folder),
            scenario=scenario.name,
            stations=tuple(self.options.stations),
            mode=self.cell.mode,
            speed_mps=scenario.system.belt_speed_mps,
            duration_s=scenario.duration_s,
            overrides=self.cell.overrides,
            complete=agg.episodes == len(self.cell.seeds),
            failures=tuple(self.failures),
            aggregate=agg,
        )


def write_sweep(
    checked: Sequence[CheckedCell], out: Path, *, transport: Transport = "ros", record: bool = False
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
        self.backend = BackendNote()
        self.quiet = quiet
        self._wall0 = time.monotonic()

    def summary(self, complete: bool) -> SweepSummary:
        """The content of ``sweep.json`` (never complete once a table could not be written)."""
        cells = tuple(r.summary() for r in self.runs)
        stopped = [*self.stopped, *self.write_errors]
        return SweepSummary(
            complete=complete and not self.write_errors,
            grid=str(self.grid_path),
            workers=self.workers,
            episodes_planned=len(self.jobs),
            episodes=sum(c.aggregate.episodes for c in cells),
            failed=sum(c.failed for c in cells),
            wall_s=time.monotonic() - self._wall0,
            headline=tuple(row for c in cells for row in headline(c, self.headline)),
            cells=cells,
            backend=self.backend,
            retried=tuple(self.retried),
            stopped="; ".join(stopped) if stopped else None,
        )

    def write_all(self, complete: bool) -> SweepSummary:
        """Write ``sweep.json`` and ``sweep.csv``; returns the summary."""
        data = self.summary(complete)
        write_atomic(self.out / "sweep.json", json.dumps(data.to_data(), indent=2) + "\n")
        write_atomic(self.out / "sweep.csv", sweep_csv(data.cells))
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

    def finish(self) -> tuple[SweepSummary, int]:
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
                note = json.dumps(data.stop_note()) + "\n"
                with contextlib.suppress(OSError):
                    overwrite_in_place(self.out / "sweep.json", note)
        if data.complete:
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
) -> tuple[SweepSummary, int]:
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
            sweep.backend = BackendNote(name="ray", address=backend.address or "local")
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
        print(json.dumps(data.to_data()))
    else:
        for row in data.headline:
            i = row.interval
            print(
                f"{row.cell:>32}: {row.scope} {row.metric} {_fmt(i.mean)} "
                f"[{_fmt(i.ci95_low)}, {_fmt(i.ci95_high)}] over {i.n} seeds"
            )
        for cell in data.cells:
            line = cell.aggregate.line
            sr = line.metrics["success_rate"]
            w = line.wilson["success_rate"]
            print(
                f"{cell.cell:>32}: {line.episodes} ep, success "
                f"{_fmt(sr.mean)} [{_fmt(sr.ci95_low)}, {_fmt(sr.ci95_high)}] "
                f"(Wilson [{_fmt(w.ci95_low)}, {_fmt(w.ci95_high)}])"
            )
        print(f"out: {out}  wall {data.wall_s:.1f} s  complete: {data.complete}")
    if not data.complete:
        print(f"cdw-twin sweep: incomplete: {data.stopped}", file=sys.stderr)
    return code


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"
