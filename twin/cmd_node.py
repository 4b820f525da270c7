"""``cdw-twin twin-node``: the twin as a ROS 2 node, for an external controller.

Example (two shells, same ``ROS_DOMAIN_ID``)::

    cdw-twin twin-node --speed 0.4 --duration 60 --mode realtime --out runs/ep0
    cdw-twin controller

The episode log (``events.jsonl``, ``summary.json``) and the node's telemetry
(``telemetry.json``: round-trip latency, step rate, belt setpoint and speed; see
:mod:`twin.telemetry`) go to ``--out`` when the episode ends, also when it is interrupted.
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
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from experiments.record import McapRecording
    from twin.scenario import Scenario
    from twin.sim import Twin


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the node's options."""
    parser.add_argument("--scenario", type=Path, default=None, help="scenario YAML")
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


def build_scenario(args: argparse.Namespace) -> tuple[Scenario, Path]:
    """The scenario with command-line overrides, and the dataset folder."""
    from twin.builtin import builtin_dataset
    from twin.scenario import Scenario

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
    return scenario, dataset


def _final_state(twin: Twin) -> dict[str, object]:
    """Exact end state (for determinism checks): joints and every object's pose."""
    obs = twin.observe()
    return {
        "step": obs.step,
        "joint_positions": list(obs.joint_positions),
        "belt_position_m": obs.belt.belt_position_m,
        "objects": {str(o.id): [*o.position_m, *o.orientation_xyzw] for o in obs.objects},
    }


def _open_recording(out: Path | None) -> McapRecording | None:
    """The episode's MCAP of every topic, written as ``OUT.partial`` until it is closed.

    Chunks are flushed every 0.5 s, so a killed twin leaves a readable ``OUT.partial`` (see
    :mod:`experiments.record`).
    """
    if out is None:
        return None
    from experiments.record import DEFAULT_FLUSH_INTERVAL_S, TOPICS, McapRecording

    return McapRecording(out, TOPICS, flush_interval_s=DEFAULT_FLUSH_INTERVAL_S)


def run(args: argparse.Namespace) -> int:
    """Run one episode as a ROS 2 node."""
    import rclpy
    from rclpy.utilities import try_shutdown

    from twin.episode_log import tracking_summary, write_episode
    from twin.fileio import write_atomic
    from twin.perception import PerceptionConfig
    from twin.ros_isolation import clean_stale_fastdds_shm, local_ros_defaults
    from twin.ros_node import TwinNode, make_executor, run_loop
    from twin.sim import Twin

    scenario, dataset = build_scenario(args)
    perception = PerceptionConfig.zero_noise() if args.perception == "zero" else None
    local_ros_defaults()
    clean_stale_fastdds_shm()
    stop = {"requested": False}

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop["requested"] = True
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_signal)
    with Twin(scenario, dataset_dir=dataset, perception=perception) as twin:
        twin.reset()
        recording = _open_recording(args.record)
        rclpy.init()
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
            run_loop(node, executor, ack_timeout_s=args.ack_timeout)
        except KeyboardInterrupt:
            interrupted = True
        wall = time.perf_counter() - wall0
        if recording is not None:
            recording.close()
        twin.targets.finish(twin.time_s)
        scores = twin.scores()
        summary = {
            "scenario": scenario.name,
            "seed": scenario.seed,
            "mode": args.mode,
            "belt_speed_mps": scenario.system.belt_speed_mps,
            "complete": not interrupted,
            "sim_seconds": twin.time_s,
            "wall_seconds": wall,
            "real_time_factor": twin.time_s / wall if wall > 0 else 0.0,
            "scores": dataclasses.asdict(scores),
            "landing_in_bins": twin.landing_in_bins(),
            "tracking": tracking_summary(twin.targets.results),
            "published": dict(node.counters.published),
            "received_commands": node.counters.received_commands,
            "rejected_commands": dict(node.counters.rejected or {}),
            "lockstep_timeouts": node.counters.lockstep_timeouts,
            "priorities": list(node.priorities),
            "final_state": _final_state(twin),
            **node.telemetry.summary(),
        }
        if args.out is not None:
            write_atomic(args.out / "telemetry.json", node.telemetry.to_json())
            write_episode(args.out, twin.events, summary)
        node.destroy_node()
        try_shutdown()  # a SIGTERM may have shut the context down already
    return 130 if interrupted and stop["requested"] else 0
