"""``cdw-twin episode``: one lockstep episode in one process, the in-process transport.

``cdw-twin run --transport inproc`` (and ``sweep``) start this instead of a twin node and one
controller process per station: the twin's endpoint (:class:`twin.ros_node.InprocTwin`) and
every station's controller (:class:`control.node.InprocController`) share the in-process bus
(:mod:`interfaces.inproc`), fed the same messages at the same ticks as over ROS 2 in lockstep,
so the events and metrics are the same, bit for bit, without DDS, its threads and the process
switches. The options are the twin node's (:mod:`twin.cmd_node`: ``--scenario``, ``--cell``,
``--dataset``, ``--seed``, ``--out``, ``--record``, ...) and the controllers'
``--params-file`` (default: the file the scenario's ``controller`` names, as ``cdw-twin run``
takes it); ``--controller-stats STATION=PATH`` names each station's stats file (default:
``controller.json`` or ``controller-<station>.json`` next to ``--out``). Lockstep
only: realtime and a real cell need ROS 2 (``cdw-twin twin-node``, ``cdw-twin controller``).

Example::

    cdw-twin episode --scenario experiments/scenarios/line.yaml --seed 1 --out runs/ep/twin
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from interfaces.errors import CdwTwinError
from interfaces.run_folder import EpisodeFolder

if TYPE_CHECKING:
    from control.node import InprocController
    from interfaces.cell import Cell
    from interfaces.inproc import Bus


def configure(parser: argparse.ArgumentParser) -> None:
    """The twin node's options (its ``--params-file`` is the controllers' too) and the
    controllers' stats files."""
    from twin.cmd_node import configure as configure_node

    configure_node(parser)
    parser.set_defaults(mode="lockstep")
    parser.add_argument(
        "--controller-stats",
        action="append",
        default=[],
        metavar="STATION=PATH",
        help="write this station's controller stats there (repeatable)",
    )


def stats_paths(values: list[str], cell: Cell, out: Path | None) -> dict[str, Path | None]:
    """Each station's stats file: from ``STATION=PATH`` values, else next to ``out`` (the
    names ``cdw-twin run`` gives: ``controller.json`` with one station,
    ``controller-<station>.json`` with several), else none."""
    names = [s.name for s in cell.stations]
    given: dict[str, Path] = {}
    for value in values:
        station, sep, path = value.partition("=")
        if not sep or not path:
            msg = f"--controller-stats {value!r}: expected STATION=PATH"
            raise CdwTwinError(msg)
        if station not in names:
            msg = f"--controller-stats {value!r}: no station {station!r} in the cell {names}"
            raise CdwTwinError(msg)
        given[station] = Path(path)
    paths: dict[str, Path | None] = {}
    for name in names:
        default = None
        if out is not None:
            default = EpisodeFolder(out.parent).controller_stats(name, names, 0)
        paths[name] = given.get(name, default)
    return paths


class Controllers:
    """Every station's controller on the bus (:class:`twin.cmd_node.InprocPeers`)."""

    def __init__(self, params_file: Path, stats: list[str], out: Path | None) -> None:
        self._params_file = params_file
        self._stats = stats
        self._out = out
        self._controllers: list[tuple[InprocController, Path | None]] = []

    def start(self, bus: Bus, cell: Cell) -> None:
        """Load each station's controller parameters and create its controller; the twin's
        endpoint exists, so each matches at once."""
        from control.config import load_config
        from control.node import InprocController

        paths = stats_paths(self._stats, cell, self._out)
        for station in cell.stations:
            config = load_config(self._params_file, cell=cell, station=station.name)
            controller = InprocController(config, bus)
            self._controllers.append((controller, paths[station.name]))
        for controller, _ in self._controllers:
            controller.try_match()
            if not controller.outputs_matched():
                msg = f"station {controller.config.station.name!r}: its controller did not match"
                raise CdwTwinError(msg)

    def finish(self) -> None:
        """Write each controller's stats (JSON, atomically)."""
        for controller, path in self._controllers:
            if path is not None:
                controller.summary().write(path)


def run(args: argparse.Namespace) -> int:
    """Run the episode; the twin node's exit statuses (130 when stopped by a signal)."""
    from twin.cmd_node import run as run_node

    if args.mode != "lockstep":
        msg = f"--mode {args.mode}: the in-process transport runs lockstep only; use twin-node"
        raise CdwTwinError(msg)
    params_file = args.params_file if args.params_file is not None else scenario_params(args)
    return run_node(args, peers=Controllers(params_file, args.controller_stats, args.out))


def scenario_params(args: argparse.Namespace) -> Path:
    """Without ``--params-file``: the file the scenario's ``controller`` names (as ``cdw-twin
    run`` takes it, :func:`control.config.params_path`), or the default parameters without a
    scenario."""
    from control.config import DEFAULT_PARAMS, params_path
    from twin.scenario import Scenario

    if not args.scenario:
        return DEFAULT_PARAMS
    scenario = Scenario.load(args.scenario)
    try:
        return params_path(scenario.controller, Path(args.scenario).parent).resolve()
    except CdwTwinError as exc:
        msg = f"{args.scenario}: controller = {scenario.controller!r}: {exc}"
        raise CdwTwinError(msg) from None


__all__ = ["Controllers", "configure", "run", "stats_paths"]
