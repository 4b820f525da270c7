"""One closed-loop episode's processes: start the twin node and one controller per station (or
the twin alone, in process), watch them, restart controllers at the scenario's restart times,
stop them, and judge how the episode ended (:func:`run_episode`: its metrics, scored once,
or :class:`EpisodeFailedError` saying which process ended it early and when).

Every process asks the kernel for SIGTERM when the runner dies (``CDW_TWIN_PARENT_PID``) and
stays in the runner's process group; see :mod:`experiments.run` for the run folder they write.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from experiments.run_types import EpisodeSpec, Progress, RunOptions
from experiments.scoring import failure_text, score_episode
from interfaces.errors import CdwTwinError
from interfaces.lifecycle import PARENT_PID_VARIABLE
from interfaces.run_folder import SUMMARY_FILE, EpisodeFolder
from interfaces.run_records import EpisodeMetrics, EpisodeSummary

STOP_GRACE_S = 15.0


POLL_S = 0.1


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


def exit_text(returncode: int) -> str:
    """A process's exit status in words: ``code 1`` or ``signal SIGKILL``."""
    if returncode < 0:
        try:
            return f"signal {signal.Signals(-returncode).name}"
        except ValueError:
            return f"signal {-returncode}"
    return f"code {returncode}"


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
            stats = EpisodeFolder(episode.folder).controller_stats(station, options.stations, 0)
            extra += ["--controller-stats", f"{station}={stats}"]
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
        str(EpisodeFolder(episode.folder).twin),
        *(["--record", str(EpisodeFolder(episode.folder).recording)] if options.record else []),
        *view_arguments(options),
    ]


def view_arguments(options: RunOptions) -> list[str]:
    """The twin node's live view, window and image-recording options."""
    args = []
    if options.foxglove_port is not None:
        args += ["--foxglove", str(options.foxglove_port), "--foxglove-host", options.foxglove_host]
    if options.gui:
        args.append("--gui")
    if options.record_images_hz is not None:
        args += ["--record-images", str(options.record_images_hz)]
    return args


def controller_command(
    options: RunOptions, episode: EpisodeSpec, station: str | None = None, instance: int = 0
) -> list[str]:
    """The command line of ``station``'s controller (None: the cell's first station);
    ``instance`` > 0 for a restarted controller."""
    stats = EpisodeFolder(episode.folder).controller_stats(station, options.stations, instance)
    cmd = [*_cli(), "controller", "--stats-out", str(stats)]
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
    """The twin's last sim time from its ``summary.json``, None without a readable one."""
    try:
        summary_s: float = EpisodeSummary.read(summary).sim_seconds
    except (OSError, CdwTwinError):
        return None
    return summary_s


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
        log = EpisodeFolder(self.episode.folder).twin_log
        self.twin = self._start(log, twin_command(self.options, self.episode))
        if self.options.transport == "ros":
            self._start_controllers()
        return self.twin

    def _start(self, log_path: Path, cmd: list[str]) -> subprocess.Popen[bytes]:
        log: IO[bytes] = self._stack.enter_context(log_path.open("ab"))
        proc = subprocess.Popen(cmd, env=self._env, stdout=log, stderr=subprocess.STDOUT)
        self.started.append(proc)
        return proc

    def _start_controllers(self) -> None:
        stations: Sequence[str | None] = self.options.stations or (None,)
        for station in stations:
            log = EpisodeFolder(self.episode.folder).controller_log(station, self.options.stations)
            cmd = controller_command(self.options, self.episode, station, self.instance)
            self.controllers[station] = self._start(log, cmd)

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
    folder = EpisodeFolder(episode.folder)
    summary = folder.summary
    if exited is not None:
        if len(options.stations) <= 1:
            exited = ControllerExit(None, exited.returncode)
        # the twin stops within a step of its SIGTERM, a poll period after the controller died
        lost_s = _sim_seconds(summary)
        raise EpisodeFailedError(
            episode, _controller_reason(exited, watch_s if lost_s is None else lost_s)
        )
    if twin_code != 0 or not summary.is_file():
        log = folder.twin_log.read_text(errors="replace")[-2000:]
        reason = f"twin exited with {exit_text(twin_code)}"
        if not summary.is_file():
            reason += f", no {SUMMARY_FILE}"
        raise EpisodeFailedError(episode, reason, log)


def run_episode(
    options: RunOptions,
    episode: EpisodeSpec,
    *,
    cancel: threading.Event | None = None,
    progress: Progress | None = None,
) -> EpisodeMetrics:
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
        metrics = score_episode(episode.folder, options.mode, episode.index)
    except CdwTwinError as exc:
        raise EpisodeFailedError(episode, f"unreadable episode files: {exc}") from None
    if not metrics.complete:
        summary = EpisodeFolder(episode.folder).summary
        reason = (
            f"the twin stopped before the end, at sim {_sim_seconds(summary) or 0.0:.1f} "
            f"of {options.duration_s:.1f} s"
        )
        raise EpisodeFailedError(episode, reason)
    return metrics
