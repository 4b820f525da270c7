"""``cdw-twin run``: closed-loop episodes, the twin node and the controller as two processes.

Example::

    cdw-twin run --speed 0.4 --seed 1 --json
    cdw-twin run experiments/scenarios/default.yaml --episodes 3 --mode realtime --out runs/a

The scenario (with the command-line overrides applied) is validated before anything starts and
written to the run folder as ``scenario.yaml``; every process of the run reads that file. The
controller's parameter file (the scenario's ``controller``) is copied next to it as
``controller.yaml``, and the written scenario names that copy and the dataset's absolute path
(unless it is the built-in one): ``cdw-twin run RUN/scenario.yaml`` reruns it as it ran, from
any folder, whatever the shipped parameter files become. Each
episode gets its own ROS domain (claimed with a lock, LOCALHOST discovery). The run folder holds
one folder per episode (the twin's episode log ``twin/``: ``events.jsonl``, ``status.json``,
``summary.json``, ``telemetry.json``, see :mod:`twin.episode_log`; the recording of every topic
``recording.mcap``, written by the twin node itself from the bytes it sends and receives
(``recording.mcap.partial`` while it runs, or after a crash; see :mod:`experiments.record`); the
controller's stats ``controller.json``; every process's log), ``episodes.json`` and
``episodes.csv`` with the per-episode metrics, and ``run.json`` with their means, the dataset
and the scenario path.

``run.json`` says ``"complete": false`` until every episode has finished successfully. A run
stopped early (Ctrl-C, SIGTERM, a failed episode) keeps the episodes finished so far in
``episodes.json``/``episodes.csv`` (each written atomically), stays ``"complete": false`` and
gains ``"stopped": "<reason>"``; the command then exits non-zero (130 when interrupted, 1 when an
episode failed) and ``--json`` still prints the result of the finished episodes (with
``"complete": false`` and ``"stopped"``). The unfinished episode's folder keeps whatever its
processes wrote (the twin streams its ``events.jsonl`` and writes its ``summary.json`` with
``"complete": false`` when stopped).

An episode fails when its twin or its controller exits before the twin has finished the
episode (a crash, a ``kill -9``; a controller stopped on purpose for a planned restart does not
count), or when the twin leaves no complete ``summary.json``. The run stops at the first failed
episode. A failed episode is a row of ``episodes.json`` (and ``episodes.csv``) with
``"failed": true`` and a one-line ``"reason"`` (``controller exited with signal SIGKILL at sim
12.3 s``, ``twin exited with signal SIGKILL, no summary.json``) and no metrics; it is left out of
the means. ``run.json`` gives ``"episodes"`` (the successful episodes, those averaged),
``"failed"`` (their count) and ``"failures"`` (``episode 0 (seed 5) failed: <reason>``).

No process outlives the runner: the twin and the controller ask the kernel for SIGTERM when
the runner dies, however it dies (``prctl(PR_SET_PDEATHSIG)``, set by each of them at start
from the ``CDW_TWIN_PARENT_PID`` the runner passes), and they stay in the runner's process
group, so a signal to the group (Ctrl-C in a terminal) reaches every process at once. On that
SIGTERM the twin writes its episode folder (``"complete": false``) and the controller its
counters.

Controller restarts (the scenario's ``faults.controller_restart_at_s``): the runner watches the
twin's ``/clock`` with a tiny best-effort subscriber of its own, in the episode's domain, and
when sim time passes a restart time it stops the controller (SIGTERM, so its counters are
saved as ``controller.json``, ``controller_1.json``, ...) and starts a new one. The lockstep twin
waits ``--ack-timeout`` (2 s) for the lost controller, logs a ``controller_timeout`` fault, steps
on without it at the wall-clock pace (so the outage costs about the sim time it lasts) and
resynchronises when the new controller acknowledges ticks (a ``controller_resumed`` event). The
restart happens at the first ``/clock`` sample at or after the restart time that the runner sees
(it polls every 0.1 s wall), so its exact sim time is not reproducible; the twin's events record
when the controller was lost and when it came back. The watcher also feeds the progress line
when the output is a terminal.

Metrics per episode:

- ``picks``: successful picks (``pick_success``), ``placed_correct``: objects in their class bin;
- ``targeted``: objects the controller committed to and finished with (completed or aborted),
  except those it released into a bin so late that they were still falling when the episode
  ended (the twin's ``landing_in_bins``: their fate is undecided);
- ``success_rate`` = placed_correct / targeted; ``untargeted``: objects never targeted, by reason;
- ``miss_rate``: the twin's missed / processed (objects that left the window unpicked);
- ``throughput_per_min`` = placed_correct per simulated minute;
- ``tracking_time_4mm_mean_s`` / ``_p95_s``: the twin's ground-truth tracking time;
- ``faults``: fault events other than injected ones (rejected commands, controller timeouts);
  ``injected_faults``: the scenario's injected-fault window edges.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import IO, TYPE_CHECKING, Any, Literal

from experiments.stats import mean_of
from interfaces.fileio import write_atomic
from interfaces.lifecycle import PARENT_PID_VARIABLE
from twin.errors import CdwTwinError

if TYPE_CHECKING:
    from twin.scenario import Scenario

METRIC_KEYS = (
    "speed_mps",
    "seed",
    "mode",
    "picks",
    "placed_correct",
    "targeted",
    "untargeted_total",
    "processed",
    "missed",
    "success_rate",
    "miss_rate",
    "throughput_per_min",
    "tracking_time_4mm_mean_s",
    "tracking_time_4mm_p95_s",
    "real_time_factor",
    "faults",
    "injected_faults",
    "controller_restarts",
)
"""The metric columns of ``episodes.csv``, in order."""

EPISODE_COLUMNS = (*METRIC_KEYS, "failed", "reason")
"""The columns of ``episodes.csv``: the metrics, whether the episode failed and why."""

STOP_GRACE_S = 15.0
POLL_S = 0.1


class EpisodeFailedError(CdwTwinError):
    """An episode failed: its twin or controller exited early, or no complete twin summary.

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
    """Add the run options."""
    parser.add_argument("scenario", type=Path, nargs="?", default=None, help="scenario YAML")
    parser.add_argument("--speed", type=float, default=None, help="belt speed m/s (override)")
    parser.add_argument("--episodes", type=int, default=1, help="episodes (1)")
    parser.add_argument("--seed", type=int, default=None, help="first seed (override)")
    parser.add_argument("--duration", type=float, default=None, help="episode seconds")
    parser.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
    parser.add_argument("--dataset", type=Path, default=None, help="meshgen output folder")
    parser.add_argument("--out", type=Path, default=None, help="run folder (default runs/...)")
    parser.add_argument("--json", action="store_true", help="print the run's metrics as JSON")


@dataclass(frozen=True, kw_only=True)
class RunOptions:
    """How to run the episodes of one scenario.

    ``scenario_path`` is the resolved scenario file (overrides applied, validated); ``dataset``
    the meshgen output folder; ``restart_at_s`` the controller restart times (sim seconds);
    ``controller_params`` the controller's parameter file (None: its default).
    """

    scenario_path: Path
    dataset: Path
    controller_params: Path | None = None
    mode: Literal["lockstep", "realtime"] = "lockstep"
    duration_s: float = 60.0
    restart_at_s: tuple[float, ...] = ()
    ack_timeout_s: float = 2.0


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


def controller_params(value: str, scenario_dir: Path | None) -> Path:
    """The controller parameter file a scenario's ``controller`` names, loaded once to check it.

    A bare name is a file shipped in ``control/config/``; anything else is a path, relative to
    the scenario's folder. Errors name the ``controller`` key and what is wrong.
    """
    from control.cmd_controller import DEFAULT_PARAMS
    from control.config import load_config
    from control.errors import ControlConfigError

    if "/" not in value and not value.endswith((".yaml", ".yml")):
        path = DEFAULT_PARAMS.parent / f"{value}.yaml"
        if not path.is_file():
            known = ", ".join(sorted(p.stem for p in DEFAULT_PARAMS.parent.glob("*.yaml")))
            msg = f"controller = {value!r}: no parameter file of that name (shipped: {known})"
            raise CdwTwinError(msg)
    else:
        path = Path(value).expanduser()
        if not path.is_absolute() and scenario_dir is not None:
            path = scenario_dir / path
    try:
        load_config(path)
    except ControlConfigError as exc:
        msg = f"controller = {value!r}: {exc}"
        raise CdwTwinError(msg) from None
    return path.resolve()


CONTROLLER_COPY = "controller.yaml"
"""Name of the controller parameter file's copy in a run folder, next to ``scenario.yaml``."""


def write_run_scenario(
    scenario: Scenario, params: Path, folder: Path, dataset: Path | None
) -> tuple[Path, Path]:
    """Write ``scenario`` to ``folder/scenario.yaml`` naming a copy of ``params`` beside it.

    ``dataset``, when given, replaces the scenario's ``dataset`` by its absolute path (None: the
    built-in dataset). Returns the paths of the written scenario and of the parameter file's copy.
    """
    from dataclasses import replace

    copy = folder / CONTROLLER_COPY
    write_atomic(copy, params.read_text(encoding="utf-8"))
    scenario = replace(scenario, controller=CONTROLLER_COPY)
    if dataset is not None:
        scenario = replace(scenario, dataset=str(dataset.resolve()))
    scenario_path = folder / "scenario.yaml"
    write_atomic(scenario_path, scenario.to_yaml())
    return scenario_path, copy


def _cli() -> list[str]:
    return [sys.executable, "-m", "twin.cli"]


def twin_command(options: RunOptions, episode: EpisodeSpec) -> list[str]:
    """The twin node's command line for one episode."""
    return [
        *_cli(),
        "twin-node",
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
        "--record",
        str(episode.folder / "recording.mcap"),
    ]


def controller_command(options: RunOptions, episode: EpisodeSpec, instance: int = 0) -> list[str]:
    """The controller's command line; ``instance`` > 0 for a restarted controller."""
    name = "controller.json" if instance == 0 else f"controller_{instance}.json"
    cmd = [*_cli(), "controller", "--stats-out", str(episode.folder / name)]
    if options.controller_params is not None:
        cmd += ["--params-file", str(options.controller_params)]
    if options.mode == "lockstep":
        cmd.append("--lockstep")
    return cmd


def _controller_stats(folder: Path) -> list[dict[str, Any]]:
    paths = sorted(folder.glob("controller*.json"), key=lambda p: (len(p.name), p.name))
    return [json.loads(p.read_text(encoding="utf-8")) for p in paths]


def _pick_counts(stats: list[dict[str, Any]]) -> tuple[int, dict[str, int]]:
    """Targeted objects and untargeted ones by reason, summed over controller instances."""
    targeted = 0
    untargeted: dict[str, int] = {}
    for ctl in stats:
        pick = ctl.get("pick") or {}
        targeted += int(pick.get("completed", 0))
        targeted += sum(int(v) for v in (pick.get("aborted") or {}).values())
        for key, value in (pick.get("untargeted") or {}).items():
            untargeted[str(key)] = untargeted.get(str(key), 0) + int(value)
    return targeted, untargeted


def episode_metrics(folder: Path, mode: str) -> dict[str, Any]:
    """The metrics of one finished episode folder."""
    twin = json.loads((folder / "twin" / "summary.json").read_text(encoding="utf-8"))
    stats = _controller_stats(folder)
    targeted, untargeted = _pick_counts(stats)
    # released into a bin just before the end, still falling: undecided, so not counted
    targeted = max(0, targeted - len(twin.get("landing_in_bins", [])))
    scores = twin["scores"]
    placed_correct = int(scores["placed_correct"])
    minutes = float(twin["sim_seconds"]) / 60.0
    tracking = twin["tracking"]
    kinds = [
        str(event.get("data", {}).get("kind", ""))
        for event in map(json.loads, (folder / "twin" / "events.jsonl").read_text().splitlines())
        if event.get("type") == "fault"
    ]
    injected = sum(1 for k in kinds if k.startswith("injected_"))
    return {
        "speed_mps": twin.get("belt_speed_mps"),
        "seed": twin["seed"],
        "mode": mode,
        "picks": int(scores["picked"]),
        "placed_correct": placed_correct,
        "targeted": targeted,
        "untargeted": untargeted,
        "untargeted_total": sum(untargeted.values()),
        "processed": int(scores["processed"]),
        "missed": int(scores["missed"]),
        "success_rate": placed_correct / targeted if targeted else 0.0,
        "miss_rate": float(scores["miss_rate"]),
        "throughput_per_min": placed_correct / minutes if minutes > 0 else 0.0,
        "tracking_time_4mm_mean_s": tracking["tracking_time_4mm_mean_s"],
        "tracking_time_4mm_p95_s": tracking["tracking_time_4mm_p95_s"],
        "tracking_pursuits": tracking["pursuits"],
        "tracking_unsettled": tracking["unsettled"],
        "real_time_factor": twin["real_time_factor"],
        "faults": len(kinds) - injected,
        "injected_faults": injected,
        "controller_restarts": max(0, len(stats) - 1),
        "complete": bool(twin["complete"]),
        "failed": False,
    }


class ClockWatch:
    """The latest ``/clock`` of one ROS domain, read by polling (no thread of its own)."""

    def __init__(self, domain_id: int) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions
        from rosgraph_msgs.msg import Clock

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
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT
        )
        self._node.create_subscription(Clock, "/clock", self._on_clock, qos)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self._node)

    def _on_clock(self, msg: Any) -> None:
        self.time_s = msg.clock.sec + 1e-9 * msg.clock.nanosec

    def poll(self) -> float:
        """Take the newest ``/clock`` sample, if any; returns sim seconds."""
        self._executor.spin_once(timeout_sec=0.0)
        return self.time_s

    def close(self) -> None:
        """Leave the domain."""
        self._executor.shutdown()
        self._node.destroy_node()
        self._context.try_shutdown()


def _stop(procs: list[subprocess.Popen[bytes]]) -> None:
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


def run_episode(
    options: RunOptions,
    episode: EpisodeSpec,
    *,
    cancel: threading.Event | None = None,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Run one closed-loop episode in its own ROS domain; returns its metrics.

    Raises :class:`EpisodeFailedError` when the controller exits while the twin still runs
    (other than for a planned restart), or the twin ends without a complete summary, and
    :class:`EpisodeCancelledError` when ``cancel`` is set; every process is stopped either way.

    The calling thread starts the processes and waits for them to end before it returns: each
    process gets SIGTERM when the thread that started it exits (``PR_SET_PDEATHSIG``), so the
    processes must not outlive it (a sweep's worker threads run one episode after another).
    """
    from twin.ros_isolation import clean_stale_fastdds_shm, ros_domain

    episode.folder.mkdir(parents=True, exist_ok=True)
    clean_stale_fastdds_shm()
    restarts = sorted(options.restart_at_s)
    controller_exit: int | None = None
    watch: ClockWatch | None = None
    with ros_domain() as domain, ExitStack() as stack:
        env = {**os.environ, **domain.env, PARENT_PID_VARIABLE: str(os.getpid())}
        started: list[subprocess.Popen[bytes]] = []

        def start(name: str, cmd: list[str]) -> subprocess.Popen[bytes]:
            log: IO[bytes] = stack.enter_context((episode.folder / f"{name}.log").open("ab"))
            proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
            started.append(proc)
            return proc

        try:
            twin = start("twin", twin_command(options, episode))
            controller = start("controller", controller_command(options, episode))
            watch = ClockWatch(domain.domain_id) if restarts or progress else None
            wall0 = time.monotonic()
            while twin.poll() is None:
                if cancel is not None and cancel.wait(POLL_S):
                    msg = f"episode {episode.index} (seed {episode.seed}) cancelled"
                    raise EpisodeCancelledError(msg)
                if cancel is None:
                    time.sleep(POLL_S)
                if controller.poll() is not None:
                    break
                if watch is None:
                    continue
                sim_s = watch.poll()
                if progress is not None:
                    progress(sim_s, time.monotonic() - wall0)
                if restarts and sim_s >= restarts[0]:
                    restarts.pop(0)
                    _stop([controller])
                    instance = len(options.restart_at_s) - len(restarts)
                    controller = start("controller", controller_command(options, episode, instance))
            # exited by itself (the runner stops it only below): unplanned, whenever it was
            controller_exit = controller.poll()
        finally:
            if watch is not None:
                watch.close()
            _stop(started)
    code = twin.returncode
    summary = episode.folder / "twin" / "summary.json"
    if (controller_exit is not None or code != 0) and cancel is not None and cancel.is_set():
        # a Ctrl-C reaches the whole process group: the processes may have stopped first
        msg = f"episode {episode.index} (seed {episode.seed}) cancelled"
        raise EpisodeCancelledError(msg)
    if controller_exit is not None:
        # the twin stops within a step of its SIGTERM, a poll period after the controller died
        lost_s = _sim_seconds(summary)
        if lost_s is None and watch is not None:
            lost_s = watch.time_s
        reason = f"controller exited with {exit_text(controller_exit)}"
        if lost_s is not None:
            reason += f" at sim {lost_s:.1f} s"
        raise EpisodeFailedError(episode, reason)
    if code != 0 or not summary.is_file():
        log = (episode.folder / "twin.log").read_text(errors="replace")[-2000:]
        reason = f"twin exited with {exit_text(code)}"
        if not summary.is_file():
            reason += ", no summary.json"
        raise EpisodeFailedError(episode, reason, log)
    metrics = episode_metrics(episode.folder, options.mode)
    if not metrics["complete"]:
        reason = (
            f"the twin stopped before the end, at sim {_sim_seconds(summary) or 0.0:.1f} "
            f"of {options.duration_s:.1f} s"
        )
        raise EpisodeFailedError(episode, reason)
    return {"episode": episode.index, **metrics}


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


def aggregate(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Means over the successful episodes of every numeric metric (failed ones left out)."""
    keys = [k for k in METRIC_KEYS if k not in ("mode", "seed", "speed_mps")]
    good = succeeded(rows)
    return {k: mean_of([r.get(k) for r in good]) for k in keys}


def write_tables(
    out: Path, rows: list[dict[str, Any]], complete: bool, extra: dict[str, Any]
) -> dict[str, Any]:
    """``episodes.json``, ``episodes.csv`` and ``run.json`` (atomically).

    ``rows`` may hold failed episodes (:func:`failed_row`): they are listed in the tables, and
    counted in ``run.json`` as ``failed`` with their ``failures``, never in the means.
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
    }
    write_atomic(out / "run.json", json.dumps(summary, indent=2) + "\n")
    return summary


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


def run(args: argparse.Namespace) -> int:
    """Run the episodes and summarise them."""
    from twin.cmd_node import build_scenario

    if args.episodes < 1:
        msg = f"--episodes = {args.episodes}: must be >= 1"
        raise CdwTwinError(msg)
    node_args = argparse.Namespace(
        scenario=args.scenario,
        dataset=args.dataset,
        speed=args.speed,
        duration=args.duration,
        seed=args.seed,
        objects=None,
        prefill=None,
    )
    scenario, dataset = build_scenario(node_args)
    params = controller_params(
        scenario.controller, args.scenario.parent if args.scenario is not None else None
    )
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out: Path = args.out or Path("runs") / f"{scenario.name}-{stamp}"
    out.mkdir(parents=True, exist_ok=True)
    own_dataset = args.dataset is not None or scenario.dataset != "builtin"
    scenario_path, params = write_run_scenario(
        scenario, params, out, Path(dataset) if own_dataset else None
    )
    options = RunOptions(
        scenario_path=scenario_path.resolve(),
        dataset=Path(dataset).resolve(),
        controller_params=params.resolve(),
        mode=args.mode,
        duration_s=scenario.duration_s,
        restart_at_s=scenario.faults.controller_restart_at_s,
    )
    extra: dict[str, Any] = {
        "scenario": scenario.name,
        "scenario_path": str(args.scenario) if args.scenario is not None else None,
        "dataset": str(options.dataset),
        "mode": args.mode,
        "speed_mps": scenario.system.belt_speed_mps,
        "episodes_planned": args.episodes,
    }
    rows: list[dict[str, Any]] = []
    write_tables(out, rows, complete=False, extra=extra)
    stopped: str | None = None
    code = 0
    # SIGINT too: a process started in the background inherits SIGINT ignored, and Python then
    # installs no KeyboardInterrupt handler of its own
    previous = {s: signal.signal(s, raise_interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
    tty = sys.stdout.isatty() and not args.json
    try:
        for i in range(args.episodes):
            episode = EpisodeSpec(index=i, seed=scenario.seed + i, folder=out / f"ep{i:03d}")
            if not args.json:
                print(f"episode {i + 1}/{args.episodes} (seed {episode.seed}) ...", flush=True)
            progress = (
                _terminal_progress(i + 1, args.episodes, scenario.duration_s) if tty else None
            )
            try:
                metrics = run_episode(options, episode, progress=progress)
            except EpisodeFailedError as exc:
                row = failed_row(episode, args.mode, exc.reason)
                row["speed_mps"] = scenario.system.belt_speed_mps
                rows.append(row)
                stopped, code = failure_text(i, episode.seed, exc.reason), 1
                print(f"cdw-twin run: {exc}", file=sys.stderr)
                break
            finally:
                if tty:
                    print()
            metrics["speed_mps"] = scenario.system.belt_speed_mps
            rows.append(metrics)
            write_tables(out, rows, complete=False, extra=extra)
    except KeyboardInterrupt as exc:
        stopped, code = f"interrupted ({exc.args[0] if exc.args else 'SIGINT'})", 130
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    if stopped is not None:
        extra = {**extra, "stopped": stopped}
    summary = write_tables(out, rows, complete=stopped is None, extra=extra)
    good = succeeded(rows)
    result = {
        **summary["mean"],
        "speed_mps": scenario.system.belt_speed_mps,
        "mode": args.mode,
        "complete": summary["complete"],
        "episodes": summary["episodes"],
        "failed": summary["failed"],
        "out": str(out),
        "untargeted": good[-1]["untargeted"] if good else {},
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
        for key, value in result.items():
            print(f"{key:>28}: {value}")
    return code
