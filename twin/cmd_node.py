"""``cdw-twin twin-node``: the twin as a ROS 2 node, for an external controller.

Example (two shells, same ``ROS_DOMAIN_ID``)::

    cdw-twin twin-node --speed 0.4 --duration 60 --mode realtime --out runs/ep0
    cdw-twin controller

The cell is the scenario's ``cell`` (default: the reference cell) unless ``--cell`` names
another (a shipped cell's name, such as ``two_pandas``, or a path); a cell of several stations
takes one controller per station, each on its station's namespace.

The episode log goes to ``--out`` (see :mod:`twin.episode_log`): the folder and its
``status.json`` exist from the start, ``events.jsonl`` is appended as events happen (flushed at
least every 0.5 s of wall time, so even ``kill -9`` keeps every event up to the last second),
and ``summary.json`` and the node's telemetry (``telemetry.json``: round-trip latency, step
rate, belt setpoint and speed; see :mod:`twin.telemetry`) are written when the episode ends.
Ctrl-C (SIGINT) or SIGTERM ends the episode at the next step: the node writes the folder with
``"complete": false`` in ``summary.json``, closes the recording and exits with status 130.
``--record OUT.mcap`` writes every message the node publishes or receives (every topic of
``docs/interfaces.md``) as the bytes on the wire, from inside the node: no recorder process to
start, match and feed (``cdw-twin run`` records its episodes this way; ``cdw-twin record`` is
the stand-alone recorder for a cell the twin does not run).
"""

from __future__ import annotations

import argparse
import dataclasses
import signal
import time
from contextlib import ExitStack
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

from interfaces.lifecycle import STOP_SIGNALS, die_with_parent

if TYPE_CHECKING:
    from interfaces.cell import Cell
    from twin.episode_log import EventLog
    from twin.recording import McapRecording
    from twin.scenario import Scenario
    from twin.sim import Twin


class EpisodeStopped(Exception):  # noqa: N818 (a request, not an error)
    """A stop signal arrived; raised between two callback passes of the step loop."""


class StoppableExecutor:
    """An executor whose ``spin_once`` raises :class:`EpisodeStopped` once ``stop`` is set.

    The signal handler only records the signal; the step loop is left at its next callback
    pass, never from inside a callback or a physics step, so the twin's state, events and
    recording stay consistent.
    """

    def __init__(self, executor: Any, stop: list[int]) -> None:
        self.executor = executor
        self._stop = stop

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Serve callbacks as the wrapped executor does, unless a stop was requested."""
        if self._stop:
            raise EpisodeStopped
        self.executor.spin_once(timeout_sec=timeout_sec)


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the node's options."""
    parser.add_argument("--scenario", type=Path, default=None, help="scenario YAML")
    parser.add_argument(
        "--cell",
        default=None,
        metavar="PATH_OR_NAME",
        help="cell file, or the name of a shipped cell (default: the scenario's)",
    )
    parser.add_argument(
        "--dataset",
        type=Path,
        default=None,
        help="meshgen output folder (default: the scenario's, or built-in)",
    )
    parser.add_argument("--speed", type=float, default=None, help="belt speed m/s (override)")
    parser.add_argument("--duration", type=float, default=None, help="episode seconds (override)")
    parser.add_argument("--seed", type=int, default=None, help="seed (override)")
    parser.add_argument("--objects", type=int, default=None, help="max objects (override)")
    parser.add_argument("--prefill", type=float, default=None, help="prefill metres (override)")
    parser.add_argument("--mode", choices=("realtime", "lockstep"), default="realtime")
    parser.add_argument("--perception", choices=("default", "zero"), default="default")
    parser.add_argument("--ack-timeout", type=float, default=2.0, help="lockstep wait (s)")
    parser.add_argument("--out", type=Path, default=None, help="episode log folder")
    parser.add_argument(
        "--record",
        type=Path,
        default=None,
        metavar="MCAP",
        help="record every message the node sends or receives to this MCAP file",
    )


def build_scenario(args: argparse.Namespace) -> tuple[Scenario, Path, Cell]:
    """The scenario with command-line overrides, the dataset folder and the cell, checked
    together (:func:`twin.scenario_check.check_scenario`).

    The scenario's ``cell`` and ``dataset`` are relative to its file; ``args.cell`` (when set)
    names the cell instead, relative to the working directory.
    """
    from interfaces.cell import load_cell
    from twin.builtin import builtin_dataset
    from twin.scenario import Scenario, scenario_cell
    from twin.scenario_check import check_scenario

    scenario = Scenario.load(args.scenario) if args.scenario else Scenario()
    system = scenario.system
    objects = scenario.objects
    if args.speed is not None:
        system = dataclasses.replace(system, belt_speed_mps=args.speed)
    if args.prefill is not None:
        system = dataclasses.replace(system, prefill_m=args.prefill)
    if args.objects is not None:
        objects = dataclasses.replace(objects, max_objects=args.objects)
    scenario = dataclasses.replace(
        scenario,
        system=system,
        objects=objects,
        duration_s=scenario.duration_s if args.duration is None else args.duration,
        seed=scenario.seed if args.seed is None else args.seed,
    )
    if args.dataset is not None:
        dataset = args.dataset
    elif scenario.dataset != "builtin":
        dataset = Path(scenario.dataset)
        if not dataset.is_absolute() and args.scenario is not None:
            dataset = (args.scenario.parent / dataset).resolve()
    else:
        dataset = builtin_dataset()
    where = str(args.scenario or "default scenario")
    cell_arg = getattr(args, "cell", None)
    if cell_arg is not None:
        cell = load_cell(cell_arg)
    else:
        base = args.scenario.parent if args.scenario is not None else None
        cell = scenario_cell(scenario, base, where)
    check_scenario(scenario, dataset, where=where, cell=cell)
    return scenario, dataset, cell


def _final_state(twin: Twin) -> dict[str, object]:
    """Exact end state (for determinism checks): every station's arm joints (in station order)
    and every object's pose."""
    obs = twin.observe()
    return {
        "step": obs.step,
        "joint_positions": [q for arm in obs.arms for q in arm.joint_positions],
        "belt_position_m": obs.belt.belt_position_m,
        "objects": {str(o.id): [*o.position_m, *o.orientation_xyzw] for o in obs.objects},
    }


def _open_recording(out: Path | None, cell: Cell) -> McapRecording | None:
    """The episode's MCAP of every topic of the cell (every station's under its namespace),
    written as ``OUT.partial`` until it is closed.

    Chunks are flushed every 0.5 s, so a killed twin leaves a readable ``OUT.partial`` (see
    :mod:`twin.recording`).
    """
    if out is None:
        return None
    from interfaces.contract import resolved_topics
    from twin.recording import DEFAULT_FLUSH_INTERVAL_S, McapRecording

    topics = resolved_topics(tuple(s.namespace for s in cell.stations))
    return McapRecording(out, topics, flush_interval_s=DEFAULT_FLUSH_INTERVAL_S)


def run(args: argparse.Namespace) -> int:
    """Run one episode as a ROS 2 node; 130 when SIGINT or SIGTERM ended it early."""
    stop: list[int] = []

    def on_signal(signum: int, frame: FrameType | None) -> None:
        del frame
        stop.append(signum)

    previous = {s: signal.signal(s, on_signal) for s in STOP_SIGNALS}
    try:
        die_with_parent()
        interrupted = _run_episode(args, stop)
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    return 130 if interrupted else 0


def _run_episode(args: argparse.Namespace, stop: list[int]) -> bool:
    """The episode; True when a stop signal ended it before its duration."""
    from twin.episode_log import start_episode_folder, write_status
    from twin.perception import PerceptionConfig
    from twin.ros_isolation import clean_stale_fastdds_shm, local_ros_defaults
    from twin.sim import Twin

    scenario, dataset, cell = build_scenario(args)
    perception = PerceptionConfig.zero_noise() if args.perception == "zero" else None
    local_ros_defaults()
    clean_stale_fastdds_shm()
    out: Path | None = args.out
    log = None
    if out is not None:
        log = start_episode_folder(out, scenario=scenario.name, seed=scenario.seed)
    try:
        with ExitStack() as stack:
            if log is not None:
                stack.enter_context(log)
            twin = stack.enter_context(
                Twin(
                    scenario,
                    dataset_dir=dataset,
                    cell=cell,
                    perception=perception,
                    event_sink=None if log is None else log.append,
                )
            )
            return _serve(args, twin, stop, log)
    except BaseException as exc:
        if out is not None:
            write_status(out, "failed", error=f"{type(exc).__name__}: {exc}")
        raise


def _serve(args: argparse.Namespace, twin: Twin, stop: list[int], log: EventLog | None) -> bool:
    """Run the twin node until the episode ends or a stop signal; write the episode folder."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    from rclpy.utilities import try_shutdown

    from interfaces.fileio import write_atomic
    from twin.episode_log import tracking_summary, write_status, write_summary
    from twin.ros_node import TwinNode, make_executor, run_loop

    scenario = twin.scenario
    twin.reset()
    recording = _open_recording(args.record, twin.cell)
    # rclpy's own SIGINT handler would shut the context down under the step loop
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = TwinNode(
        twin,
        lockstep=args.mode == "lockstep",
        tap=None if recording is None else recording.write,
    )
    executor = make_executor()
    executor.add_node(node)
    wall0 = time.perf_counter()
    interrupted = False
    try:
        run_loop(node, StoppableExecutor(executor, stop), ack_timeout_s=args.ack_timeout)
    except EpisodeStopped:
        interrupted = True
    wall = time.perf_counter() - wall0
    if recording is not None:
        recording.close()
    if log is not None:
        log.close()
    twin.finish_pursuits()
    summary = {
        "scenario": scenario.name,
        "seed": scenario.seed,
        "mode": args.mode,
        "belt_speed_mps": scenario.system.belt_speed_mps,
        "complete": not interrupted,
        "sim_seconds": twin.time_s,
        "wall_seconds": wall,
        "real_time_factor": twin.time_s / wall if wall > 0 else 0.0,
        "cell": twin.cell.name,
        "scores": twin.scores(),
        "stations": {
            link.name: {
                "scores": twin.scores(link.name),
                "tracking": tracking_summary(twin.tracking_results(link.name)),
                "latency": link.telemetry.summary()["latency"],
            }
            for link in node.links
        },
        "landing_in_bins": twin.landing_in_bins(),
        "tracking": tracking_summary(twin.tracking_results()),
        "published": dict(node.counters.published),
        "received_commands": node.counters.received_commands,
        "rejected_commands": dict(node.counters.rejected),
        "lockstep_timeouts": node.counters.lockstep_timeouts,
        "priorities": list(node.priorities),
        "final_state": _final_state(twin),
        **node.telemetry.summary(),
    }
    if interrupted:
        summary["stopped_by"] = signal.Signals(stop[0]).name
    out: Path | None = args.out
    if out is not None:
        write_atomic(out / "telemetry.json", node.telemetry.to_json())
        write_summary(out, summary)
        write_status(
            out,
            "interrupted" if interrupted else "finished",
            scenario=scenario.name,
            seed=scenario.seed,
            sim_seconds=twin.time_s,
        )
    node.destroy_node()
    try_shutdown()
    return interrupted
