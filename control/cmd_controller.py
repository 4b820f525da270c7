"""``cdw-twin controller``: run the controller as a ROS 2 node until SIGINT/SIGTERM or --duration.

Examples::

    cdw-twin controller --lockstep --stats-out out/controller_stats.json
    python -m control --cell two_pandas --station downstream --params-file my_tuning.yaml

The controller drives one station of a cell: ``--cell`` names the cell file (a path, or a
shipped cell such as ``two_pandas``; default: the reference cell) and ``--station`` the station
(default: the cell's first); the station's robot, tool, pick window and bins, and its topics'
namespace, come from there. ``--params-file`` is the controller's tuning.

The node keeps sim time: ``/clock`` in realtime, the ticks' stamps in lockstep. On shutdown
it writes its counters (pick statistics, rejected detections, skipped commands, control-loop
timing) as JSON to ``--stats-out`` (atomically: a temporary file renamed into place, with the
permissions an ordinary ``open`` gives, 0666 minus the umask). Started by ``cdw-twin run``
(the environment names the runner in ``CDW_TWIN_PARENT_PID``), it gets SIGTERM when the runner
dies.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from pathlib import Path
from types import FrameType
from typing import Any

from interfaces.fileio import write_atomic
from interfaces.lifecycle import die_with_parent

DEFAULT_PARAMS = Path(__file__).resolve().parent / "config" / "default.yaml"
"""The reference cell's parameter file."""


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the controller's options to ``parser``."""
    parser.add_argument(
        "--cell",
        help="cell file: a path or a shipped cell's name (default: the reference cell)",
    )
    parser.add_argument("--station", help="the station to drive (default: the cell's first)")
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


def write_json_atomic(path: Path, data: Any) -> None:
    """Write ``data`` as JSON to ``path`` atomically (:func:`interfaces.fileio.write_atomic`)."""
    text = json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n"
    write_atomic(path, text)


def run(args: argparse.Namespace) -> int:
    """Run the node; returns 0 on a clean shutdown, 2 on a configuration error."""
    import rclpy
    from rclpy.experimental.events_executor import EventsExecutor
    from rclpy.signals import SignalHandlerOptions
    from rclpy.utilities import try_shutdown

    from control.config import load_config
    from control.node import ControllerNode
    from interfaces.cell import load_cell
    from interfaces.errors import CdwTwinError

    if args.duration is not None and not args.duration > 0.0:
        print(f"--duration: {args.duration!r} must be > 0 s", file=sys.stderr)
        return 2
    try:
        cell = load_cell(args.cell)
        if args.station:
            cell.station(args.station)  # an unknown name: the cell file's error
        config = load_config(args.params_file, cell=cell, station=args.station or "")
    except CdwTwinError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stop: list[int] = []

    def _request_stop(signum: int, frame: FrameType | None) -> None:
        del frame
        stop.append(signum)

    rclpy.init(args=None, signal_handler_options=SignalHandlerOptions.NO)
    previous = {sig: signal.signal(sig, _request_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
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
                write_json_atomic(args.stats_out, node.summary())
            node.destroy_node()
        try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def main(argv: list[str] | None = None) -> int:
    """Entry point for ``python -m control``."""
    parser = argparse.ArgumentParser(prog="python -m control", description=__doc__)
    configure(parser)
    return run(parser.parse_args(argv))
