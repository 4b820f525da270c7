"""``cdw-twin controller``: run the controller as a ROS 2 node until SIGINT/SIGTERM or --duration.

Examples::

    cdw-twin controller --lockstep --stats-out out/controller_stats.json
    python -m control --cell two_pandas --station downstream --params-file my_tuning.yaml

The controller drives one station of a cell: ``--cell`` names the cell file (a path, or a
shipped cell such as ``two_pandas``; default: the scenario's, else the reference cell) and
``--station`` the station (default: the cell's first); the station's robot, tool, pick window
and bins, and its topics' namespace, come from there. ``--params-file`` is the controller's
tuning. The cell's bin slots take the classes of the dataset (``--dataset``, a meshgen output,
or the scenario's) as the twin gives them (:func:`twin.scenario.episode_cell`, with the
scenario's ``bins:`` map: ``--scenario``); without either, the cell's own class table's (the
shipped one unless the cell file has ``materials:``). ``cdw-twin run`` hands each controller the
run's resolved ``cell.yaml``, whose bins all name their class::

    cdw-twin twin-node --scenario experiments/scenarios/line.yaml --dataset out/meshes
    cdw-twin controller --scenario experiments/scenarios/line.yaml --dataset out/meshes \
        --station s1 --params-file control/config/line.yaml

The node keeps sim time: ``/clock`` in realtime, the ticks' stamps in lockstep. On shutdown
it writes its counters (pick statistics, rejected detections, skipped commands, control-loop
timing) as JSON to ``--stats-out`` (atomically: a temporary file renamed into place, with the
permissions an ordinary ``open`` gives, 0666 minus the umask). Started by ``cdw-twin run``
(the environment names the runner in ``CDW_TWIN_PARENT_PID``), it gets SIGTERM when the runner
dies.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from control.config import DEFAULT_PARAMS
from interfaces.lifecycle import StopRequests, die_with_parent

if TYPE_CHECKING:
    from interfaces.cell import Cell


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the controller's options to ``parser``."""
    parser.add_argument(
        "--cell",
        help="cell file: a path or a shipped cell's name (default: the reference cell)",
    )
    parser.add_argument("--station", help="the station to drive (default: the cell's first)")
    parser.add_argument(
        "--scenario",
        type=Path,
        help="scenario YAML: its cell, dataset and bins map (the twin's; default: none)",
    )
    parser.add_argument(
        "--dataset",
        type=Path,
        help="meshgen output whose classes the cell's bin slots take (default: the scenario's)",
    )
    add_params_option(parser)
    parser.add_argument(
        "--lockstep",
        action="store_true",
        help="answer the twin's /lockstep/tick with lockstep/ack (deterministic closed loop)",
    )
    parser.add_argument("--stats-out", type=Path, help="write the counters as JSON on shutdown")
    parser.add_argument(
        "--duration", type=float, help="stop once /clock passes this many seconds of sim time"
    )


def add_params_option(parser: argparse.ArgumentParser) -> None:
    """``--params-file``: the controller's tuning (also the in-process episode's)."""
    parser.add_argument(
        "--params-file",
        type=Path,
        default=DEFAULT_PARAMS,
        help="controller tuning, ROS 2 parameter YAML (default: control/config/default.yaml)",
    )


def controller_cell(args: argparse.Namespace) -> Cell:
    """The cell the controller drives a station of, its bin slots resolved as the twin
    resolves them: with ``--scenario``, for the scenario's dataset (or ``--dataset``) and
    ``bins:`` map (:func:`twin.scenario.episode_cell`); with ``--dataset`` alone, for that
    dataset's class table; else as the cell file gives them."""
    from interfaces.cell import load_cell, resolve_cell
    from interfaces.materials import dataset_table

    scenario_path: Path | None = getattr(args, "scenario", None)
    dataset: Path | None = getattr(args, "dataset", None)
    if scenario_path is None:
        cell = load_cell(args.cell)
        return cell if dataset is None else resolve_cell(cell, dataset_table(dataset))
    from twin.scenario import Scenario, episode_cell, scenario_cell, scenario_dataset

    where = str(scenario_path)
    scenario = Scenario.load(scenario_path)
    base = scenario_path.parent
    cell = load_cell(args.cell) if args.cell else scenario_cell(scenario, base, where)
    table = dataset_table(dataset if dataset is not None else scenario_dataset(scenario, base))
    return episode_cell(scenario, cell, table, where)


def run(args: argparse.Namespace) -> int:
    """Run the node; returns 0 on a clean shutdown, 2 on a configuration error."""
    import rclpy
    from rclpy.experimental.events_executor import EventsExecutor
    from rclpy.signals import SignalHandlerOptions
    from rclpy.utilities import try_shutdown

    from control.config import load_config
    from control.node import ControllerNode
    from interfaces.errors import CdwTwinError

    if args.duration is not None and not args.duration > 0.0:
        print(f"--duration: {args.duration!r} must be > 0 s", file=sys.stderr)
        return 2
    try:
        cell = controller_cell(args)
        if args.station:
            cell.station(args.station)  # an unknown name: the cell file's error
        config = load_config(args.params_file, cell=cell, station=args.station or "")
    except CdwTwinError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rclpy.init(args=None, signal_handler_options=SignalHandlerOptions.NO)
    stop = StopRequests()
    node: ControllerNode | None = None
    try:
        die_with_parent()
        try:
            node = ControllerNode(config, lockstep=args.lockstep)
        except CdwTwinError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        executor = EventsExecutor()
        executor.add_node(node)
        node.get_logger().info(
            f"controller up ({'lockstep' if args.lockstep else 'realtime'}, "
            f"{1.0 / config.motion.control_period_s:.0f} Hz, station {config.station.name} "
            f"of {config.cell.source}, params {args.params_file})"
        )
        while not stop:
            executor.spin_once(timeout_sec=0.1)
            if args.duration is not None and node.sim_time_s() >= args.duration:
                break
        return 0
    finally:
        if node is not None:
            if args.stats_out is not None:
                node.summary().write(args.stats_out)
            node.destroy_node()
        try_shutdown()
        stop.restore()


def main(argv: list[str] | None = None) -> int:
    """Entry point for ``python -m control``."""
    parser = argparse.ArgumentParser(prog="python -m control", description=__doc__)
    configure(parser)
    return run(parser.parse_args(argv))
