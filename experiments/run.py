"""``cdw-twin run``: closed-loop episodes, the twin node and one controller per station.

Example::

    cdw-twin run --speed 0.4 --seed 1 --json
    cdw-twin run experiments/scenarios/default.yaml --episodes 3 --mode realtime --out runs/a
    cdw-twin run experiments/scenarios/default.yaml --cell two_pandas --duration 20
    cdw-twin run experiments/scenarios/default.yaml --episodes 3 --foxglove

``--foxglove [PORT]`` (after the scenario: a bare ``--foxglove`` takes the next word as its
port) serves every episode live over Foxglove's WebSocket protocol, each in turn on the same
port (:mod:`twin.live_view`); ``--gui`` opens PyBullet's window for each episode. A port in use
or a display that cannot be opened is a one-line error before the run folder is written.

The scenario (with the command-line overrides applied) is validated before anything starts and
written to the run folder as ``scenario.yaml``; every process of the run reads that file. The
scenario's cell (its ``cell`` key, or ``--cell``: a shipped name or a path) is resolved (its bin
slots given the dataset's classes, :func:`twin.scenario.episode_cell`, and the dataset's class
table as its ``materials:``) and written next to it as ``cell.yaml``, the controller's parameter
file (the scenario's ``controller``, checked for every station of that resolved cell) as
``controller.yaml``, and the written scenario names both copies and the dataset's absolute path
(unless it is the built-in one): ``cdw-twin run RUN/scenario.yaml``
reruns it as it ran, from any folder, whatever the shipped files become. Each episode gets its
own ROS domain (claimed with a lock, LOCALHOST discovery) and runs one twin node and one
controller process per station of the cell (``--station NAME``, each under the station's ROS
namespace).

The run folder holds one folder per episode (the twin's episode log ``twin/``: ``events.jsonl``,
``status.json``, ``summary.json``, ``telemetry.json``, see :mod:`twin.episode_log`; the
recording of every topic ``recording.mcap``, written by the twin node itself from the bytes it
sends and receives (``recording.mcap.partial`` while it runs, or after a crash; see
:mod:`twin.recording`); each controller's stats; every process's log), ``episodes.json`` and
``episodes.csv`` with the per-episode metrics, and ``run.json`` with their means, the dataset
and the scenario path. Controller files: with one station ``controller.json`` and
``controller.log`` (a restarted controller's stats ``controller_1.json``, ...); with several,
``controller-<station>.json`` / ``controller-<station>_1.json`` and ``controller-<station>.log``.

``--out`` (default ``runs/<scenario>-<stamp>``) must be new or empty: an existing non-empty
folder is refused (exit 2, before anything is written) unless ``--replace`` is given, and then
only a folder an earlier ``cdw-twin run`` wrote (its ``.cdw-run`` marker file) is replaced, whole
(:mod:`experiments.outdir`); an existing file, or a place that cannot be written (read-only,
under a file), is refused as well. A write that fails while the run goes (a full disk) ends it
as failed: the episode is a failed row naming the file and the error, ``run.json`` says
``"complete": false`` with it among its ``failures`` (rewritten over the old ``run.json``'s own
blocks when no new file can be created), and the command exits 1 without a traceback.

``run.json`` says ``"complete": false`` until every episode has finished successfully. A run
stopped early (Ctrl-C, SIGTERM, a failed episode) keeps the episodes finished so far in
``episodes.json``/``episodes.csv`` (each written atomically), stays ``"complete": false`` and
gains ``"stopped": "<reason>"``; the command then exits non-zero (130 when interrupted, 1 when an
episode failed) and ``--json`` still prints the result of the finished episodes (with
``"complete": false`` and ``"stopped"``). The unfinished episode's folder keeps whatever its
processes wrote (the twin streams its ``events.jsonl`` and writes its ``summary.json`` with
``"complete": false`` when stopped).

An episode fails when its twin or any of its controllers exits before the twin has finished
the episode (a crash, a ``kill -9``; a controller stopped on purpose for a planned restart does
not count), or when the twin leaves no complete ``summary.json``. The run stops at the first
failed episode. A failed episode is a row of ``episodes.json`` (and ``episodes.csv``) with
``"failed": true`` and a one-line ``"reason"`` (``controller exited with signal SIGKILL at sim
12.3 s``; with several stations ``controller 'upstream' exited with ...``; ``twin exited with
signal SIGKILL, no summary.json``) and no metrics; it is left out of the means. ``run.json``
gives ``"episodes"`` (the successful episodes, those averaged), ``"failed"`` (their count) and
``"failures"`` (``episode 0 (seed 5) failed: <reason>``).

No process outlives the runner: the twin and the controllers ask the kernel for SIGTERM when
the runner dies, however it dies (``prctl(PR_SET_PDEATHSIG)``, set by each of them at start
from the ``CDW_TWIN_PARENT_PID`` the runner passes), and they stay in the runner's process
group, so a signal to the group (Ctrl-C in a terminal) reaches every process at once. On that
SIGTERM the twin writes its episode folder (``"complete": false``) and each controller its
counters.

Controller restarts (the scenario's ``faults.controller_restart_at_s``): the runner watches the
twin's ``/clock`` with a tiny best-effort subscriber of its own, in the episode's domain, and
when sim time passes a restart time it stops every station's controller (SIGTERM, so their
counters are saved) and starts new ones. The lockstep twin waits ``--ack-timeout`` (2 s) for a
lost controller, logs a ``controller_timeout`` fault, steps on without it at the wall-clock pace
(so the outage costs about the sim time it lasts) and resynchronises when the new controller
acknowledges ticks (a ``controller_resumed`` event). The restart happens at the first
``/clock`` sample at or after the restart time that the runner sees (it polls every 0.1 s
wall), so its exact sim time is not reproducible; the twin's events record when a controller
was lost and when it came back. The watcher also feeds the progress line when the output is a
terminal.

Metrics per episode: every metric of the table (:data:`interfaces.metrics.METRICS`,
``docs/metrics.md``) for the line at the top level of the row (``picks`` is ``picked`` under
its older name), per station in ``stations`` and per object class in ``classes``; the line's
``targeted`` counts every controller's, less the objects still falling into a bin at the end
(:func:`interfaces.metrics.targeted_objects`), a station's its own controller's, less the
landing objects it released. ``untargeted`` gives the objects never targeted, by reason (a
station's block also each reason's share of the objects its controller decided about,
``untargeted_share``), ``dropped_by_reason`` the drops by reason, and a station's ``bins`` the
purity of each of its bins (the metrics of scope ``bin``).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from collections.abc import Mapping, Sequence
from contextlib import suppress
from dataclasses import dataclass, replace
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Literal

from experiments.episode_processes import (
    EpisodeFailedError,
    run_episode,
)
from experiments.run_types import TRANSPORTS, EpisodeSpec, Progress, RunOptions, Transport
from experiments.scoring import failure_text, run_means, write_run_tables
from interfaces.errors import CdwTwinError, cut, cut_message
from interfaces.fileio import read_text_capped, write_atomic
from interfaces.run_folder import (
    CELL_FILE,
    CONTROLLER_FILE,
    RunFolder,
    episode_dir_name,
)
from interfaces.run_records import (
    EpisodeRow,
    FailedEpisode,
    Metrics,
    RunInfo,
    RunMeans,
)
from interfaces.run_records import succeeded as good_rows

if TYPE_CHECKING:
    from interfaces.cell import Cell
    from twin.scenario import Scenario


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the run options (``--foxglove``, ``--foxglove-host`` and ``--gui`` go to every
    episode's twin node: see :mod:`twin.cmd_node`)."""
    from twin.cmd_node import add_view_options, seed_argument

    parser.add_argument("scenario", type=Path, nargs="?", default=None, help="scenario YAML")
    parser.add_argument("--speed", type=float, default=None, help="belt speed m/s (override)")
    parser.add_argument("--episodes", type=_episodes_argument, default=1, help="episodes (1)")
    parser.add_argument(
        "--seed", type=seed_argument, default=None, help="first seed (override; 0 to 2**64 - 1)"
    )
    parser.add_argument("--duration", type=float, default=None, help="episode seconds")
    parser.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
    add_transport_option(parser)
    parser.add_argument("--dataset", type=Path, default=None, help="meshgen output folder")
    parser.add_argument(
        "--cell", default=None, help="cell file: a shipped name or a path (override)"
    )
    parser.add_argument("--out", type=Path, default=None, help="run folder (default runs/...)")
    add_replace_option(parser, "run")
    parser.add_argument("--json", action="store_true", help="print the run's metrics as JSON")
    parser.add_argument(
        "--no-record",
        dest="record",
        action="store_false",
        help="write no recording.mcap (every message of every topic; about 10 MB a minute)",
    )
    add_view_options(parser)


MAX_EPISODES = 100_000
"""Most episodes one run may plan."""


def _episodes_argument(text: str) -> int:
    """``--episodes``: an integer in ``[1, MAX_EPISODES]`` (argparse's one-line error else)."""
    try:
        value = int(text)
    except ValueError:
        msg = f"invalid int value: {text[:40]!r}"
        raise argparse.ArgumentTypeError(msg) from None
    if not 1 <= value <= MAX_EPISODES:
        msg = f"must be in [1, {MAX_EPISODES}], not {value}"
        raise argparse.ArgumentTypeError(msg)
    return value


def add_replace_option(parser: argparse.ArgumentParser, command: str) -> None:
    """``--replace``: replace an existing ``--out`` whole (run, sweep, report;
    :mod:`experiments.outdir`)."""
    parser.add_argument(
        "--replace",
        action="store_true",
        help=f"replace an existing non-empty --out whole (only a folder `cdw-twin {command}` "
        "wrote; without it such an --out is refused)",
    )


def add_transport_option(parser: argparse.ArgumentParser) -> None:
    """``--transport ros|inproc`` (run, sweep, bench sweep)."""
    parser.add_argument(
        "--transport",
        choices=TRANSPORTS,
        default="ros",
        help="ros: a twin node and a controller process per station over ROS 2 (default); "
        "inproc: lockstep in one process, the same events and metrics, cheaper",
    )


def check_transport(transport: str, mode: str, restart_at_s: Sequence[float]) -> None:
    """The in-process transport runs lockstep episodes without controller restarts (there is
    no controller process to restart); raises ``CdwTwinError`` naming what does not fit."""
    if transport != "inproc":
        return
    if mode != "lockstep":
        msg = f"--transport inproc runs lockstep only, not --mode {mode}"
        raise CdwTwinError(msg)
    if restart_at_s:
        msg = (
            "--transport inproc: the scenario restarts controllers "
            f"(faults.controller_restart_at_s {list(restart_at_s)}), which needs controller "
            "processes: use --transport ros"
        )
        raise CdwTwinError(msg)


def failed_row(
    episode: EpisodeSpec, mode: str, reason: str, speed_mps: float | None = None
) -> FailedEpisode:
    """The ``episodes.json`` row of a failed episode: no metrics, ``failed`` and ``reason``."""
    return FailedEpisode(
        episode=episode.index, seed=episode.seed, mode=mode, reason=reason, speed_mps=speed_mps
    )


def controller_params(value: str, scenario_dir: Path | None, cell: Cell) -> Path:
    """The controller parameter file a scenario's ``controller`` names, checked against the
    scenario's own (resolved) cell: loaded once for every station of ``cell``
    (:func:`control.config.station_configs`), so a key naming a class, station, robot or tool
    the cell lacks is refused before anything starts.

    A bare name is a file shipped in ``control/config/``; anything else is a path, relative to
    the scenario's folder (:func:`control.config.params_path`). Errors name the
    ``controller`` key and what is wrong.
    """
    from control.config import params_path, station_configs
    from control.errors import ControlConfigError

    try:
        path = params_path(value, scenario_dir)
    except ControlConfigError as exc:
        msg = f"controller = {cut(value)}: {exc}"
        raise CdwTwinError(msg) from None
    try:  # bounded, UTF-8 and without NUL before the controller's own loader reads it
        read_text_capped(path, what="controller parameter file", error=CdwTwinError)
    except CdwTwinError as exc:
        msg = f"controller = {cut(value)}: {exc}"
        raise CdwTwinError(msg) from None
    try:
        station_configs(path, cell)
    except ControlConfigError as exc:
        msg = cut_message(f"controller = {cut(value)}: {exc}")
        raise CdwTwinError(msg) from None
    return path.resolve()


@dataclass(frozen=True, kw_only=True)
class RunFiles:
    """What :func:`write_run_scenario` wrote into a run folder."""

    scenario: Path
    controller: Path
    cell: Path


def write_run_scenario(
    scenario: Scenario, params: Path, cell: Cell, folder: Path, dataset: Path | None
) -> RunFiles:
    """Write ``scenario`` to ``folder/scenario.yaml`` naming copies of ``params`` and ``cell``
    beside it (``controller.yaml``, ``cell.yaml``).

    ``dataset``, when given, replaces the scenario's ``dataset`` by its absolute path (None: the
    built-in dataset). Returns the paths written.
    """
    folder.mkdir(parents=True, exist_ok=True)
    run = RunFolder(folder)
    params_copy = run.controller
    write_atomic(params_copy, params.read_text(encoding="utf-8"))
    cell_copy = run.cell
    cell.save(cell_copy)
    scenario = replace(scenario, controller=CONTROLLER_FILE, cell=CELL_FILE)
    if dataset is not None:
        scenario = replace(scenario, dataset=str(dataset.resolve()))
    scenario_path = run.scenario
    write_atomic(scenario_path, scenario.to_yaml())
    return RunFiles(scenario=scenario_path, controller=params_copy, cell=cell_copy)


def run_options(
    files: RunFiles,
    cell: Cell,
    scenario: Scenario,
    dataset: Path,
    mode: Literal["lockstep", "realtime"],
) -> RunOptions:
    """The options of a run folder written by :func:`write_run_scenario`."""
    return RunOptions(
        scenario_path=files.scenario.resolve(),
        dataset=dataset.resolve(),
        cell_path=files.cell.resolve(),
        stations=tuple(s.name for s in cell.stations),
        controller_params=files.controller.resolve(),
        mode=mode,
        duration_s=scenario.duration_s,
        restart_at_s=scenario.faults.controller_restart_at_s,
    )


# -- the command --------------------------------------------------------------------------------
def raise_interrupt(signum: int, frame: FrameType | None) -> None:
    """Signal handler: a ``KeyboardInterrupt`` carrying the signal's name."""
    del frame
    raise KeyboardInterrupt(signal.Signals(signum).name)


def _terminal_progress(index: int, total: int, duration_s: float) -> Progress:
    last = [0.0]

    def show(sim_s: float, wall_s: float) -> None:
        if wall_s - last[0] >= 0.5:
            last[0] = wall_s
            print(
                f"\r  episode {index}/{total}: sim {sim_s:6.1f}/{duration_s:.1f} s, "
                f"wall {wall_s:6.1f} s",
                end="",
                flush=True,
            )

    return show


@dataclass(frozen=True, kw_only=True)
class PreparedRun:
    """A validated run: its scenario, options, folder and the ``run.json`` header."""

    scenario: Scenario
    options: RunOptions
    out: Path
    info: RunInfo


def prepare_run(args: argparse.Namespace) -> PreparedRun:
    """Validate the scenario, its cell and its controller parameters, the display (``--gui``)
    and the live view's port (``--foxglove``); write the run folder's ``scenario.yaml``,
    ``cell.yaml`` and ``controller.yaml``."""
    from experiments.outdir import RUN, OutputError, check_output, fresh_output, reason
    from twin.cmd_node import build_scenario
    from twin.gui_window import check_display
    from twin.live_view import DEFAULT_HOST, check_port
    from twin.scenario import MAX_SEED

    if args.episodes < 1:
        msg = f"--episodes = {args.episodes}: must be >= 1"
        raise CdwTwinError(msg)
    replace_out = bool(getattr(args, "replace", False))
    if args.out is not None:
        check_output(args.out, RUN, replace=replace_out)
    transport: Transport = getattr(args, "transport", "ros")
    gui = bool(getattr(args, "gui", False))
    if gui:
        check_display()
    foxglove: int | None = getattr(args, "foxglove", None)
    host: str = getattr(args, "foxglove_host", DEFAULT_HOST)
    if foxglove is not None:
        check_port(host, foxglove)
    node_args = argparse.Namespace(
        scenario=args.scenario,
        dataset=args.dataset,
        cell=args.cell,
        speed=args.speed,
        duration=args.duration,
        seed=args.seed,
        objects=None,
        prefill=None,
    )
    scenario, dataset, cell = build_scenario(node_args)
    check_transport(transport, args.mode, scenario.faults.controller_restart_at_s)
    last_seed = scenario.seed + args.episodes - 1
    if last_seed > MAX_SEED:
        msg = (
            f"--seed {scenario.seed} with --episodes {args.episodes}: the last episode's seed "
            f"{last_seed} exceeds 2**64 - 1"
        )
        raise CdwTwinError(msg)
    scenario_dir = args.scenario.parent if args.scenario is not None else None
    params = controller_params(scenario.controller, scenario_dir, cell)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out: Path = args.out or Path("runs") / f"{scenario.name}-{stamp}"
    own_dataset = args.dataset is not None or scenario.dataset != "builtin"
    fresh_output(out, RUN, replace=replace_out)
    try:
        files = write_run_scenario(
            scenario, params, cell, out, Path(dataset) if own_dataset else None
        )
    except OSError as exc:
        msg = f"--out {out}: cannot write the run folder: {reason(exc)}"
        raise OutputError(msg) from None
    options = replace(
        run_options(files, cell, scenario, Path(dataset), args.mode),
        foxglove_port=foxglove,
        foxglove_host=host,
        gui=gui,
        transport=transport,
        record=getattr(args, "record", True),
        record_images_hz=getattr(args, "record_images", None),
    )
    info = RunInfo(
        scenario=scenario.name,
        scenario_path=str(args.scenario) if args.scenario is not None else None,
        dataset=str(options.dataset),
        cell=cell.name,
        stations=tuple(options.stations),
        mode=args.mode,
        transport=transport,
        speed_mps=scenario.system.belt_speed_mps,
        episodes_planned=args.episodes,
    )
    return PreparedRun(scenario=scenario, options=options, out=out, info=info)


def _run_episodes(
    run: PreparedRun, episodes: int, *, quiet: bool, tty: bool
) -> tuple[list[EpisodeRow], str | None, int]:
    """Run the episodes one after another; returns the rows, why the run stopped early (None
    when it did not) and the exit status."""
    from experiments.outdir import reason

    rows: list[EpisodeRow] = []
    speed = run.scenario.system.belt_speed_mps
    # SIGINT too: a process started in the background inherits SIGINT ignored, and Python then
    # installs no KeyboardInterrupt handler of its own
    previous = {s: signal.signal(s, raise_interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        for i in range(episodes):
            episode = EpisodeSpec(
                index=i, seed=run.scenario.seed + i, folder=run.out / episode_dir_name(i)
            )
            if not quiet:
                print(f"episode {i + 1}/{episodes} (seed {episode.seed}) ...", flush=True)
            progress = _terminal_progress(i + 1, episodes, run.scenario.duration_s) if tty else None
            why: str | None = None
            try:
                metrics = run_episode(run.options, episode, progress=progress)
            except EpisodeFailedError as exc:
                why = exc.reason
                print(f"cdw-twin run: {exc}", file=sys.stderr)
            except OSError as exc:
                why = f"cannot write the episode folder: {reason(exc)}"
                print(f"cdw-twin run: {failure_text(i, episode.seed, why)}", file=sys.stderr)
            finally:
                if tty:
                    print()
            if why is None:
                rows.append(replace(metrics, speed_mps=speed))
                try:
                    write_run_tables(RunFolder(run.out), rows, complete=False, info=run.info)
                except OSError as exc:
                    why = f"cannot write the run's tables: {reason(exc)}"
                    print(f"cdw-twin run: {failure_text(i, episode.seed, why)}", file=sys.stderr)
                    rows.pop()
            if why is not None:
                rows.append(failed_row(episode, run.options.mode, why, speed))
                return rows, failure_text(i, episode.seed, why), 1
    except KeyboardInterrupt as exc:
        return rows, f"interrupted ({exc.args[0] if exc.args else 'SIGINT'})", 130
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    return rows, None, 0


def note_failure(out: Path, rows: Sequence[EpisodeRow], info: RunInfo, why: str) -> RunMeans:
    """The run's tables could not be written (``why``: a full disk, a read-only folder): the
    ``run.json`` of the rows, ``complete`` false, with ``why`` among its ``failures``, written
    whole if it can be, else over the old ``run.json``'s own blocks without the means
    (:func:`interfaces.fileio.overwrite_in_place`), else not at all. Returns it."""
    from interfaces.fileio import overwrite_in_place

    means = run_means(rows, complete=False, info=info, also_failed=[why])
    path = RunFolder(out).run_json
    try:
        means.write(path)
    except OSError:
        note = {k: v for k, v in means.to_data().items() if not k.startswith("mean")}
        with suppress(OSError):
            overwrite_in_place(path, json.dumps(note) + "\n")
    return means


def run(args: argparse.Namespace) -> int:
    """Run the episodes and summarise them."""
    from experiments.outdir import OutputError, reason

    prepared = prepare_run(args)
    out = prepared.out
    try:
        write_run_tables(RunFolder(out), [], complete=False, info=prepared.info)
    except OSError as exc:
        msg = f"--out {out}: cannot write the run's tables: {reason(exc)}"
        raise OutputError(msg) from None
    tty = sys.stdout.isatty() and not args.json
    port = prepared.options.foxglove_port
    if port is not None and not args.json:
        print(
            f"live view on ws://{prepared.options.foxglove_host}:{port} "
            "(Foxglove: Open connection; each episode in turn)",
            flush=True,
        )
    rows, stopped, code = _run_episodes(prepared, args.episodes, quiet=args.json, tty=tty)
    info = replace(prepared.info, stopped=stopped)
    try:
        means = write_run_tables(RunFolder(out), rows, complete=stopped is None, info=info)
    except OSError as exc:
        why = f"cannot write the run's tables: {reason(exc)}"
        stopped = why if stopped is None else f"{stopped}; {why}"
        code = code or 1
        means = note_failure(out, rows, replace(prepared.info, stopped=stopped), why)
    good = good_rows(rows)
    result: dict[str, object] = {
        **means.mean,
        "speed_mps": prepared.scenario.system.belt_speed_mps,
        "mode": args.mode,
        "complete": means.complete,
        "episodes": means.episodes,
        "failed": means.failed,
        "out": str(out),
        "untargeted": dict(good[-1].line.untargeted) if good else {},
        "mean_by_station": {k: dict(v) for k, v in means.mean_by_station.items()},
    }
    if stopped is not None:
        result["stopped"] = stopped
        result["failures"] = list(means.failures)
        print(
            f"cdw-twin run: stopped after {len(good)}/{args.episodes} episodes: {stopped}\n"
            f"cdw-twin run: the finished episodes are in {RunFolder(out).episodes_json} "
            "(run.json says complete: false)",
            file=sys.stderr,
        )
    if args.json:
        print(json.dumps(result))
    elif stopped is None:
        _print_result(result, means.mean_by_station)
    return code


def _print_result(result: Mapping[str, object], by_station: Mapping[str, Metrics]) -> None:
    """The result a line a key (each station's means too, with several stations)."""
    for key, value in result.items():
        if key != "mean_by_station":
            print(f"{key:>28}: {value}")
    if len(by_station) > 1:
        for name, means in by_station.items():
            print(f"{'station ' + name:>28}: " + ", ".join(f"{k} {v}" for k, v in means.items()))
