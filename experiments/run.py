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
import csv
import io
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from contextlib import ExitStack, suppress
from dataclasses import dataclass, replace
from pathlib import Path
from types import FrameType
from typing import IO, TYPE_CHECKING, Any, Literal

from experiments.stats import mean_of
from interfaces.errors import CdwTwinError, cut, cut_message
from interfaces.fileio import MAX_JSON_BYTES, read_text_capped, write_atomic
from interfaces.lifecycle import PARENT_PID_VARIABLE
from interfaces.metrics import in_scope

if TYPE_CHECKING:
    from interfaces.cell import Cell
    from interfaces.events import Event
    from twin.scenario import Scenario

METRIC_KEYS = ("speed_mps", "seed", "mode", "picks", *in_scope("line"))
"""The metric columns of ``episodes.csv``, in order: the episode's settings, ``picks`` (the
table's ``picked`` under its older name) and every line metric of the table."""

EPISODE_COLUMNS = (*METRIC_KEYS, "failed", "reason")
"""The columns of ``episodes.csv``: the metrics, whether the episode failed and why."""

STOP_GRACE_S = 15.0
POLL_S = 0.1
CONTROLLER_COPY = "controller.yaml"
"""Name of the controller parameter file's copy in a run folder, next to ``scenario.yaml``."""
CELL_COPY = "cell.yaml"
"""Name of the resolved cell's copy in a run folder, next to ``scenario.yaml``."""


class EpisodeFailedError(CdwTwinError):
    """An episode failed: its twin or a controller exited early, or no complete twin summary.

    ``reason`` is the one-line cause (``controller exited with signal SIGKILL at sim 12.3 s``);
    the message names the episode and, for a twin failure, adds the tail of the twin's log.
    """

    def __init__(self, episode: EpisodeSpec, reason: str, log_tail: str = "") -> None:
        self.episode = episode
        self.reason = reason
        msg = failure_text(episode.index, episode.seed, reason)
        if log_tail:
            msg += f"; twin log tail:\n{log_tail}"
        super().__init__(msg)


class EpisodeCancelledError(CdwTwinError):
    """An episode was stopped from outside (Ctrl-C, SIGTERM, a sweep being cancelled)."""


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


TRANSPORTS = ("ros", "inproc")
"""How an episode's twin and controllers talk: ROS 2 between processes, or the in-process
bus (:mod:`experiments.inproc`; lockstep only)."""

Transport = Literal["ros", "inproc"]


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


@dataclass(frozen=True, kw_only=True)
class RunOptions:
    """How to run the episodes of one scenario.

    ``scenario_path`` is the resolved scenario file (overrides applied, validated); ``dataset``
    the meshgen output folder; ``cell_path`` the resolved cell file and ``stations`` its station
    names (one controller process each); ``restart_at_s`` the controller restart times (sim
    seconds); ``controller_params`` the controller's parameter file (None: its default);
    ``transport`` how the twin and the controllers talk (:data:`TRANSPORTS`); ``record``
    whether the twin writes the episode's ``recording.mcap``;
    ``foxglove_port`` (None: no live view), ``foxglove_host`` and ``gui`` are passed to the twin
    node, whose live view serves each episode in turn on the same port.
    """

    scenario_path: Path
    dataset: Path
    cell_path: Path | None = None
    stations: tuple[str, ...] = ()
    controller_params: Path | None = None
    mode: Literal["lockstep", "realtime"] = "lockstep"
    duration_s: float = 60.0
    restart_at_s: tuple[float, ...] = ()
    ack_timeout_s: float = 2.0
    foxglove_port: int | None = None
    foxglove_host: str = "127.0.0.1"
    gui: bool = False
    transport: Transport = "ros"
    record: bool = True


@dataclass(frozen=True)
class EpisodeSpec:
    """One episode to run."""

    index: int
    seed: int
    folder: Path


Progress = Callable[[float, float], None]
"""Called with (sim seconds, wall seconds) while an episode runs."""


def failure_text(index: int, seed: int, reason: str) -> str:
    """How ``run.json`` and ``sweep.json`` list a failed episode."""
    return f"episode {index} (seed {seed}) failed: {reason}"


def exit_text(returncode: int) -> str:
    """A process's exit status in words: ``code 1`` or ``signal SIGKILL``."""
    if returncode < 0:
        try:
            return f"signal {signal.Signals(-returncode).name}"
        except ValueError:
            return f"signal {-returncode}"
    return f"code {returncode}"


def failed_row(episode: EpisodeSpec, mode: str, reason: str) -> dict[str, Any]:
    """The ``episodes.json`` row of a failed episode: no metrics, ``failed`` and ``reason``."""
    return {
        "episode": episode.index,
        "seed": episode.seed,
        "mode": mode,
        "complete": False,
        "failed": True,
        "reason": reason,
    }


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
    params_copy = folder / CONTROLLER_COPY
    write_atomic(params_copy, params.read_text(encoding="utf-8"))
    cell_copy = folder / CELL_COPY
    cell.save(cell_copy)
    scenario = replace(scenario, controller=CONTROLLER_COPY, cell=CELL_COPY)
    if dataset is not None:
        scenario = replace(scenario, dataset=str(dataset.resolve()))
    scenario_path = folder / "scenario.yaml"
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


# -- processes ----------------------------------------------------------------------------------
def _cli() -> list[str]:
    return [sys.executable, "-m", "twin.cli"]


def twin_command(options: RunOptions, episode: EpisodeSpec) -> list[str]:
    """The twin node's command line for one episode; with the in-process transport, the
    episode process's (:mod:`experiments.inproc`), which runs every station's controller
    too."""
    extra: list[str] = []
    if options.controller_params is not None:  # the controllers', and the twin's spawn judge
        extra += ["--params-file", str(options.controller_params)]
    if options.transport == "inproc":
        for station in options.stations:
            name = stats_name(controller_stem(station, options.stations), 0)
            extra += ["--controller-stats", f"{station}={episode.folder / name}"]
    return [
        *_cli(),
        "twin-node" if options.transport == "ros" else "episode",
        *extra,
        "--scenario",
        str(options.scenario_path),
        "--dataset",
        str(options.dataset),
        "--mode",
        options.mode,
        "--seed",
        str(episode.seed),
        "--ack-timeout",
        str(options.ack_timeout_s),
        "--out",
        str(episode.folder / "twin"),
        *(["--record", str(episode.folder / "recording.mcap")] if options.record else []),
        *view_arguments(options),
    ]


def view_arguments(options: RunOptions) -> list[str]:
    """The twin node's live view and window options."""
    args = []
    if options.foxglove_port is not None:
        args += ["--foxglove", str(options.foxglove_port), "--foxglove-host", options.foxglove_host]
    if options.gui:
        args.append("--gui")
    return args


def controller_stem(station: str | None, stations: Sequence[str]) -> str:
    """The stem of a station's controller files: ``controller`` in a one-station cell (or for
    ``station`` None), ``controller-<station>`` otherwise."""
    return "controller" if station is None or len(stations) <= 1 else f"controller-{station}"


def stats_name(stem: str, instance: int) -> str:
    """The stats file of controller ``instance`` (0 first, > 0 after restarts)."""
    return f"{stem}.json" if instance == 0 else f"{stem}_{instance}.json"


def controller_command(
    options: RunOptions, episode: EpisodeSpec, station: str | None = None, instance: int = 0
) -> list[str]:
    """The command line of ``station``'s controller (None: the cell's first station);
    ``instance`` > 0 for a restarted controller."""
    name = stats_name(controller_stem(station, options.stations), instance)
    cmd = [*_cli(), "controller", "--stats-out", str(episode.folder / name)]
    if options.cell_path is not None:
        cmd += ["--cell", str(options.cell_path)]
    if station is not None:
        cmd += ["--station", station]
    if options.controller_params is not None:
        cmd += ["--params-file", str(options.controller_params)]
    if options.mode == "lockstep":
        cmd.append("--lockstep")
    return cmd


class ClockWatch:
    """The latest ``/clock`` of one ROS domain, read by polling (no thread of its own)."""

    def __init__(self, domain_id: int) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        from interfaces.contract import CLOCK_TOPIC
        from interfaces.ros import message_class, qos_profile
        from twin.ros_isolation import local_ros_defaults

        local_ros_defaults()
        self.time_s = 0.0
        self._context = Context()
        rclpy.init(
            context=self._context,
            domain_id=domain_id,
            signal_handler_options=SignalHandlerOptions.NO,
        )
        self._node = rclpy.create_node("cdw_run_clock", context=self._context)
        self._node.create_subscription(
            message_class(CLOCK_TOPIC),
            CLOCK_TOPIC.name,
            self._on_clock,
            qos_profile(CLOCK_TOPIC.qos),
        )
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self._node)

    def _on_clock(self, msg: Any) -> None:
        from interfaces.ros import msg_stamp_s

        self.time_s = msg_stamp_s(msg.clock)

    def poll(self) -> float:
        """Take the newest ``/clock`` sample, if any; returns sim seconds."""
        self._executor.spin_once(timeout_sec=0.0)
        return self.time_s

    def close(self) -> None:
        """Leave the domain."""
        self._executor.shutdown()
        self._node.destroy_node()
        self._context.try_shutdown()


def _stop(procs: Sequence[subprocess.Popen[bytes]]) -> None:
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    for proc in procs:
        try:
            proc.wait(timeout=STOP_GRACE_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _sim_seconds(summary: Path) -> float | None:
    """The twin's last sim time from its ``summary.json``, None without one."""
    try:
        return float(json.loads(summary.read_text(encoding="utf-8"))["sim_seconds"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


@dataclass(frozen=True)
class ControllerExit:
    """A controller that exited by itself while the twin ran: its station and exit status."""

    station: str | None
    returncode: int


class EpisodeProcesses:
    """The processes of one episode: the twin and one controller per station, each with its
    log in the episode folder, all stopped by :meth:`close`."""

    def __init__(
        self, options: RunOptions, episode: EpisodeSpec, env: dict[str, str], stack: ExitStack
    ) -> None:
        self.options = options
        self.episode = episode
        self._env = env
        self._stack = stack
        self.started: list[subprocess.Popen[bytes]] = []
        self.twin: subprocess.Popen[bytes] | None = None
        self.instance = 0
        self.controllers: dict[str | None, subprocess.Popen[bytes]] = {}

    def start(self) -> subprocess.Popen[bytes]:
        """Start the twin, then every station's controller (in the twin's process with the
        in-process transport); returns the twin."""
        self.twin = self._start("twin", twin_command(self.options, self.episode))
        if self.options.transport == "ros":
            self._start_controllers()
        return self.twin

    def _start(self, log_name: str, cmd: list[str]) -> subprocess.Popen[bytes]:
        log: IO[bytes] = self._stack.enter_context(
            (self.episode.folder / f"{log_name}.log").open("ab")
        )
        proc = subprocess.Popen(cmd, env=self._env, stdout=log, stderr=subprocess.STDOUT)
        self.started.append(proc)
        return proc

    def _start_controllers(self) -> None:
        stations: Sequence[str | None] = self.options.stations or (None,)
        for station in stations:
            stem = controller_stem(station, self.options.stations)
            cmd = controller_command(self.options, self.episode, station, self.instance)
            self.controllers[station] = self._start(stem, cmd)

    def restart_controllers(self) -> None:
        """Stop every station's controller (SIGTERM: each saves its stats) and start new ones."""
        _stop(list(self.controllers.values()))
        self.instance += 1
        self._start_controllers()

    def exited_controller(self) -> ControllerExit | None:
        """The first controller that has exited (by itself: the runner stops them only in
        :meth:`restart_controllers` and :meth:`close`), if any."""
        for station, proc in self.controllers.items():
            code = proc.poll()
            if code is not None:
                return ControllerExit(station, code)
        return None

    def close(self) -> None:
        """Stop every process still running."""
        _stop(self.started)


def _supervise(
    procs: EpisodeProcesses,
    twin: subprocess.Popen[bytes],
    watch: ClockWatch | None,
    cancel: threading.Event | None,
    progress: Progress | None,
) -> ControllerExit | None:
    """Wait for the twin to end; restart the controllers on schedule; returns the controller
    that exited by itself, if one did (the twin is then still running)."""
    episode = procs.episode
    restarts = sorted(procs.options.restart_at_s)
    wall0 = time.monotonic()
    while twin.poll() is None:
        if cancel is not None and cancel.wait(POLL_S):
            msg = f"episode {episode.index} (seed {episode.seed}) cancelled"
            raise EpisodeCancelledError(msg)
        if cancel is None:
            time.sleep(POLL_S)
        exited = procs.exited_controller()
        if exited is not None:
            return exited
        if watch is None:
            continue
        sim_s = watch.poll()
        if progress is not None:
            progress(sim_s, time.monotonic() - wall0)
        if restarts and sim_s >= restarts[0]:
            restarts.pop(0)
            procs.restart_controllers()
    # the twin ended: a controller that exited meanwhile exited by itself, whenever it was
    return procs.exited_controller()


def _controller_reason(exited: ControllerExit, lost_s: float | None) -> str:
    who = "controller" if exited.station is None else f"controller {exited.station!r}"
    reason = f"{who} exited with {exit_text(exited.returncode)}"
    if lost_s is not None:
        reason += f" at sim {lost_s:.1f} s"
    return reason


def _check_outcome(
    options: RunOptions,
    episode: EpisodeSpec,
    twin_code: int,
    exited: ControllerExit | None,
    watch_s: float | None,
) -> None:
    """Raise :class:`EpisodeFailedError` when a process ended the episode early."""
    summary = episode.folder / "twin" / "summary.json"
    if exited is not None:
        if len(options.stations) <= 1:
            exited = ControllerExit(None, exited.returncode)
        # the twin stops within a step of its SIGTERM, a poll period after the controller died
        lost_s = _sim_seconds(summary)
        raise EpisodeFailedError(
            episode, _controller_reason(exited, watch_s if lost_s is None else lost_s)
        )
    if twin_code != 0 or not summary.is_file():
        log = (episode.folder / "twin.log").read_text(errors="replace")[-2000:]
        reason = f"twin exited with {exit_text(twin_code)}"
        if not summary.is_file():
            reason += ", no summary.json"
        raise EpisodeFailedError(episode, reason, log)


def run_episode(
    options: RunOptions,
    episode: EpisodeSpec,
    *,
    cancel: threading.Event | None = None,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Run one closed-loop episode in its own ROS domain; returns its metrics.

    Raises :class:`EpisodeFailedError` when a controller exits while the twin still runs
    (other than for a planned restart), or the twin ends without a complete summary, and
    :class:`EpisodeCancelledError` when ``cancel`` is set; every process is stopped either way.

    The calling thread starts the processes and waits for them to end before it returns: each
    process gets SIGTERM when the thread that started it exits (``PR_SET_PDEATHSIG``), so the
    processes must not outlive it (a sweep's worker threads run one episode after another).
    """
    from twin.ros_isolation import clean_stale_fastdds_shm, ros_domain

    episode.folder.mkdir(parents=True, exist_ok=True)
    clean_stale_fastdds_shm()
    watch: ClockWatch | None = None
    with ros_domain() as domain, ExitStack() as stack:
        env = {**os.environ, **domain.env, PARENT_PID_VARIABLE: str(os.getpid())}
        procs = EpisodeProcesses(options, episode, env, stack)
        try:
            twin = procs.start()
            if options.transport == "ros" and (options.restart_at_s or progress):
                watch = ClockWatch(domain.domain_id)  # nothing on DDS with inproc
            exited = _supervise(procs, twin, watch, cancel, progress)
        finally:
            if watch is not None:
                watch.close()
            procs.close()
    code = twin.returncode
    if (exited is not None or code != 0) and cancel is not None and cancel.is_set():
        # a Ctrl-C reaches the whole process group: the processes may have stopped first
        msg = f"episode {episode.index} (seed {episode.seed}) cancelled"
        raise EpisodeCancelledError(msg)
    _check_outcome(options, episode, code, exited, None if watch is None else watch.time_s)
    try:
        metrics = episode_metrics(episode.folder, options.mode)
    except CdwTwinError as exc:
        raise EpisodeFailedError(episode, f"unreadable episode files: {exc}") from None
    if not metrics["complete"]:
        summary = episode.folder / "twin" / "summary.json"
        reason = (
            f"the twin stopped before the end, at sim {_sim_seconds(summary) or 0.0:.1f} "
            f"of {options.duration_s:.1f} s"
        )
        raise EpisodeFailedError(episode, reason)
    return {"episode": episode.index, **metrics}


# -- metrics ------------------------------------------------------------------------------------
def _instance_of(path: Path, stem: str) -> int | None:
    match = re.fullmatch(rf"{re.escape(stem)}(?:_(\d+))?\.json", path.name)
    if match is None:
        return None
    return int(match.group(1) or 0)


def controller_stats(folder: Path, stations: Sequence[str]) -> dict[str, list[dict[str, Any]]]:
    """Every controller's stats in an episode folder, per station, in instance order."""
    out: dict[str, list[dict[str, Any]]] = {}
    for station in stations:
        stem = controller_stem(station, stations)
        found = []
        for path in folder.glob(f"{stem}*.json"):
            instance = _instance_of(path, stem)
            if instance is not None:
                found.append((instance, read_json(path)))
        out[station] = [stats for _, stats in sorted(found, key=lambda pair: pair[0])]
    return out


MAX_EVENTS_BYTES = 1_000_000_000
"""The largest ``events.jsonl`` read (a day-long episode's is a few hundred MB)."""


def read_json(path: Path) -> Any:
    """A JSON result file of an episode (at most :data:`interfaces.fileio.MAX_JSON_BYTES`);
    :class:`CdwTwinError` naming it when it cannot be read or parsed."""
    text = read_text_capped(path, max_bytes=MAX_JSON_BYTES, what="JSON file", error=CdwTwinError)
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        msg = f"{path}: not valid JSON: {cut(str(exc), 200)}"
        raise CdwTwinError(msg) from None


def read_events(path: Path) -> list[Event]:
    """The events of an ``events.jsonl``."""
    from interfaces.events import Event

    text = read_text_capped(path, max_bytes=MAX_EVENTS_BYTES, what="event log", error=CdwTwinError)
    return [Event.from_json(line) for line in text.splitlines()]


def episode_cell(folder: Path) -> Cell:
    """The cell an episode folder ran: its run folder's ``cell.yaml``, else the default cell
    (a run folder written before cells were data)."""
    from interfaces.cell import load_cell

    copy = folder.parent / CELL_COPY
    return load_cell(copy if copy.is_file() else None)


@dataclass(frozen=True, kw_only=True)
class EpisodeRecord:
    """What an episode folder holds that the metrics are computed from."""

    summary: dict[str, Any]
    events: list[Event]
    stats: dict[str, list[dict[str, Any]]]
    line_exit: str | None = None
    """The station whose window ends the line (:func:`interfaces.metrics.exit_station`)."""

    @property
    def duration_s(self) -> float:
        """The episode's simulated seconds."""
        return float(self.summary["sim_seconds"])

    @property
    def landing(self) -> list[int]:
        """Objects still falling into a bin when the episode ended."""
        return [int(i) for i in self.summary.get("landing_in_bins", [])]


def _scope_inputs(
    record: EpisodeRecord, station: str | None
) -> tuple[list[dict[str, Any]], int, Any, int]:
    """The controller stats, landing objects, tracking block and restarts of the line
    (``station`` None) or of one station."""
    from interfaces.metrics import landing_by_station

    if station is None:
        stats = [s for instances in record.stats.values() for s in instances]
        landing = len(record.landing)
        tracking = record.summary.get("tracking")
        restarts = max((len(s) for s in record.stats.values()), default=1) - 1
        return stats, landing, tracking, restarts
    stats = record.stats.get(station, [])
    landing = landing_by_station(record.events, record.landing).get(station, 0)
    tracking = ((record.summary.get("stations") or {}).get(station) or {}).get("tracking")
    if tracking is None and len(record.stats) == 1:
        tracking = record.summary.get("tracking")
    return stats, landing, tracking, len(stats) - 1


def scope_metrics(record: EpisodeRecord, station: str | None) -> dict[str, Any]:
    """The table's metrics of the line (``station`` None) or of one station, with the
    controllers' ``untargeted`` objects by reason and the drops by reason
    (``dropped_by_reason``); a station's block adds each reason's share of the objects its
    controller decided about (``untargeted_share``) and its bins' scores (``bins``, scope
    ``bin``)."""
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
    stats, landing, tracking, restarts = _scope_inputs(record, station)
    targeted = targeted_objects(stats, landing)
    untargeted = untargeted_objects(stats)
    allocation = untargeted_scores(untargeted, considered_objects(stats))
    scores = event_scores(counts)
    values: dict[str, Any] = {
        **scores,
        **controller_scores(counts, targeted),
        **tracking_metrics(tracking),
        **fault_counts(record.events, station=station),
        **allocation,
        "targeted": targeted,
        "controller_restarts": max(0, restarts),
        "real_time_factor": record.summary.get("real_time_factor"),
    }
    names = in_scope("line" if station is None else "station")
    out = {
        **{name: values[name] for name in names},
        "untargeted": untargeted,
        "dropped_by_reason": scores["dropped_by_reason"],
    }
    if station is not None:
        out["untargeted_share"] = allocation["untargeted_share"]
        out["bins"] = bin_scores(record.events, station=station).get(station, {})
    return out


def episode_metrics(folder: Path, mode: str) -> dict[str, Any]:
    """The metrics of one finished episode folder: the line's, per station and per class.

    The stations are those of the run folder's ``cell.yaml`` (:func:`episode_cell`).
    """
    from interfaces.metrics import class_scores, exit_station

    summary = read_json(folder / "twin" / "summary.json")
    cell = episode_cell(folder)
    names = tuple(s.name for s in cell.stations)
    record = EpisodeRecord(
        summary=summary,
        events=read_events(folder / "twin" / "events.jsonl"),
        stats=controller_stats(folder, names),
        line_exit=exit_station(cell.stations),
    )
    line = scope_metrics(record, None)
    perception = summary.get("perception")  # the camera's scores (perception.source: camera)
    scored = (
        {f"perception_{k}": v for k, v in perception.items() if "/" not in k}
        if isinstance(perception, dict)
        else {}
    )
    return {
        **scored,
        "speed_mps": summary.get("belt_speed_mps"),
        "seed": summary["seed"],
        "mode": mode,
        "picks": line["picked"],
        **line,
        "stations": {name: scope_metrics(record, name) for name in names},
        "classes": class_scores(record.events, record.duration_s, line_exit=record.line_exit),
        "complete": bool(summary["complete"]),
        "failed": False,
    }


# -- tables -------------------------------------------------------------------------------------
def succeeded(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of episodes that did not fail (the ones metrics are aggregated over)."""
    return [r for r in rows if not r.get("failed")]


def failures(rows: list[dict[str, Any]]) -> list[str]:
    """:func:`failure_text` of every failed row."""
    return [
        failure_text(int(r.get("episode", -1)), int(r["seed"]), str(r.get("reason")))
        for r in rows
        if r.get("failed")
    ]


def _means(blocks: Sequence[dict[str, Any]], keys: Sequence[str]) -> dict[str, Any]:
    return {k: mean_of([b.get(k) for b in blocks]) for k in keys}


def aggregate(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Means over the successful episodes of every numeric line metric (failed ones left out)."""
    keys = [k for k in METRIC_KEYS if k not in ("mode", "seed", "speed_mps")]
    keys += sorted({k for r in rows for k in r if k.startswith("perception_")})
    return _means(succeeded(rows), keys)


def aggregate_blocks(rows: list[dict[str, Any]], block: str) -> dict[str, dict[str, Any]]:
    """Means over the successful episodes of each entry of a per-episode ``block``
    (``stations``: the station metrics; ``classes``: the class metrics)."""
    keys = in_scope("station" if block == "stations" else "class")
    names: dict[str, None] = {}
    for row in succeeded(rows):
        names.update(dict.fromkeys(row.get(block) or {}))
    return {
        name: _means([r[block][name] for r in succeeded(rows) if name in r.get(block, {})], keys)
        for name in names
    }


def write_tables(
    out: Path, rows: list[dict[str, Any]], complete: bool, extra: dict[str, Any]
) -> dict[str, Any]:
    """``episodes.json``, ``episodes.csv`` and ``run.json`` (atomically).

    ``rows`` may hold failed episodes (:func:`failed_row`): they are listed in the tables, and
    counted in ``run.json`` as ``failed`` with their ``failures``, never in the means.
    ``run.json`` gives the line's means (``mean``) and each station's and class's
    (``mean_by_station``, ``mean_by_class``).
    """
    write_atomic(out / "episodes.json", json.dumps(rows, indent=2) + "\n")
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(EPISODE_COLUMNS), extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    write_atomic(out / "episodes.csv", buffer.getvalue())
    failed = failures(rows)
    summary = {
        "complete": complete,
        "episodes": len(succeeded(rows)),
        "failed": len(failed),
        "failures": failed,
        **extra,
        "mean": aggregate(rows),
        "mean_by_station": aggregate_blocks(rows, "stations"),
        "mean_by_class": aggregate_blocks(rows, "classes"),
    }
    write_atomic(out / "run.json", json.dumps(summary, indent=2) + "\n")
    return summary


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
    extra: dict[str, Any]


def prepare_run(args: argparse.Namespace) -> PreparedRun:
    """Validate the scenario, its cell and its controller parameters, the display (``--gui``)
    and the live view's port (``--foxglove``); write the run folder's ``scenario.yaml``,
    ``cell.yaml`` and ``controller.yaml``."""
    from experiments.outdir import RUN, OutputError, check_output, fresh_output, reason
    from twin.cmd_node import build_scenario, check_display
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
    )
    extra: dict[str, Any] = {
        "scenario": scenario.name,
        "scenario_path": str(args.scenario) if args.scenario is not None else None,
        "dataset": str(options.dataset),
        "cell": cell.name,
        "stations": list(options.stations),
        "mode": args.mode,
        "transport": transport,
        "speed_mps": scenario.system.belt_speed_mps,
        "episodes_planned": args.episodes,
    }
    return PreparedRun(scenario=scenario, options=options, out=out, extra=extra)


def _run_episodes(
    run: PreparedRun, episodes: int, *, quiet: bool, tty: bool
) -> tuple[list[dict[str, Any]], str | None, int]:
    """Run the episodes one after another; returns the rows, why the run stopped early (None
    when it did not) and the exit status."""
    from experiments.outdir import reason

    rows: list[dict[str, Any]] = []
    speed = run.scenario.system.belt_speed_mps
    # SIGINT too: a process started in the background inherits SIGINT ignored, and Python then
    # installs no KeyboardInterrupt handler of its own
    previous = {s: signal.signal(s, raise_interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        for i in range(episodes):
            episode = EpisodeSpec(
                index=i, seed=run.scenario.seed + i, folder=run.out / f"ep{i:03d}"
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
                rows.append({**metrics, "speed_mps": speed})
                try:
                    write_tables(run.out, rows, complete=False, extra=run.extra)
                except OSError as exc:
                    why = f"cannot write the run's tables: {reason(exc)}"
                    print(f"cdw-twin run: {failure_text(i, episode.seed, why)}", file=sys.stderr)
                    rows.pop()
            if why is not None:
                rows.append({**failed_row(episode, run.options.mode, why), "speed_mps": speed})
                return rows, failure_text(i, episode.seed, why), 1
    except KeyboardInterrupt as exc:
        return rows, f"interrupted ({exc.args[0] if exc.args else 'SIGINT'})", 130
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    return rows, None, 0


def note_failure(
    out: Path, rows: list[dict[str, Any]], extra: dict[str, Any], why: str
) -> dict[str, Any]:
    """The run's tables could not be written (``why``: a full disk, a read-only folder): the
    ``run.json`` of the rows, ``complete`` false, with ``why`` among its ``failures``, written
    whole if it can be, else over the old ``run.json``'s own blocks without the means
    (:func:`interfaces.fileio.overwrite_in_place`), else not at all. Returns it."""
    from interfaces.fileio import overwrite_in_place

    failed = failures(rows)
    note = {
        "complete": False,
        "episodes": len(succeeded(rows)),
        "failed": len(failed),
        "failures": [*failed, why],
        **extra,
    }
    summary = {
        **note,
        "mean": aggregate(rows),
        "mean_by_station": aggregate_blocks(rows, "stations"),
        "mean_by_class": aggregate_blocks(rows, "classes"),
    }
    path = out / "run.json"
    try:
        write_atomic(path, json.dumps(summary, indent=2) + "\n")
    except OSError:
        with suppress(OSError):
            overwrite_in_place(path, json.dumps(note) + "\n")
    return summary


def run(args: argparse.Namespace) -> int:
    """Run the episodes and summarise them."""
    from experiments.outdir import OutputError, reason

    prepared = prepare_run(args)
    out = prepared.out
    try:
        write_tables(out, [], complete=False, extra=prepared.extra)
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
    extra = prepared.extra if stopped is None else {**prepared.extra, "stopped": stopped}
    try:
        summary = write_tables(out, rows, complete=stopped is None, extra=extra)
    except OSError as exc:
        why = f"cannot write the run's tables: {reason(exc)}"
        stopped = why if stopped is None else f"{stopped}; {why}"
        code = code or 1
        summary = note_failure(out, rows, {**prepared.extra, "stopped": stopped}, why)
    good = succeeded(rows)
    result = {
        **summary["mean"],
        "speed_mps": prepared.scenario.system.belt_speed_mps,
        "mode": args.mode,
        "complete": summary["complete"],
        "episodes": summary["episodes"],
        "failed": summary["failed"],
        "out": str(out),
        "untargeted": good[-1]["untargeted"] if good else {},
        "mean_by_station": summary["mean_by_station"],
    }
    if stopped is not None:
        result["stopped"] = stopped
        result["failures"] = summary["failures"]
        print(
            f"cdw-twin run: stopped after {len(good)}/{args.episodes} episodes: {stopped}\n"
            f"cdw-twin run: the finished episodes are in {out / 'episodes.json'} "
            "(run.json says complete: false)",
            file=sys.stderr,
        )
    if args.json:
        print(json.dumps(result))
    elif stopped is None:
        _print_result(result)
    return code


def _print_result(result: dict[str, Any]) -> None:
    for key, value in result.items():
        if key != "mean_by_station":
            print(f"{key:>28}: {value}")
    stations = result["mean_by_station"]
    if len(stations) > 1:
        for name, means in stations.items():
            print(f"{'station ' + name:>28}: " + ", ".join(f"{k} {v}" for k, v in means.items()))
