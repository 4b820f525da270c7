"""The ``cdw-twin`` console script: one entry point, one subcommand per job.

Each subcommand lives in its own module exposing ``configure(parser)`` and ``run(args) -> int``;
those modules import their heavy dependencies (PyBullet, rclpy, fmpy) only inside ``run`` so that
``cdw-twin --help`` and light jobs start fast.

Examples::

    cdw-twin sample --out data/sample
    cdw-twin meshgen data/sample --out out/meshes --json
    cdw-twin bench meshgen --json
    cdw-twin fmu build
    cdw-twin bench fmu --json
    cdw-twin picture --out cell.png
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
from collections.abc import Sequence
from typing import Protocol, cast

from twin.errors import CdwTwinError


class _CommandModule(Protocol):
    def configure(self, parser: argparse.ArgumentParser) -> None: ...

    def run(self, args: argparse.Namespace) -> int: ...


# (command words, module, one-line help). Nested words ("bench", "meshgen") form sub-subcommands.
COMMANDS: tuple[tuple[tuple[str, ...], str, str], ...] = (
    (("sample",), "meshgen.cmd_sample", "write the built-in procedural YOLO-seg sample dataset"),
    (("meshgen",), "meshgen.cmd_meshgen", "turn annotated polygons into metric 3D proxy meshes"),
    (("bench", "meshgen"), "meshgen.cmd_bench", "benchmark mesh generation against a baseline"),
    (("fmu", "build"), "fmus.build", "compile the belt-drive FMUs (FMI 3.0 and 2.0) with gcc"),
    (("bench", "fmu"), "twin.bench_fmu", "benchmark one FMU co-simulation step"),
    (("bench", "twin"), "twin.bench_twin", "benchmark the twin's real-time factor"),
    (("bench", "render"), "twin.bench_render", "benchmark the camera's renderers per frame"),
    (("bench", "control"), "control.bench", "benchmark the controller on an ideal arm"),
    (("bench", "bound"), "control.bound", "the shortest pursuit the arm's joint limits allow"),
    (("bench", "guard"), "experiments.bench_guard", "headline figures vs the baseline"),
    (("bench", "rtt"), "twin.bench_rtt", "round-trip latency to the twin node over ROS 2"),
    (("bench", "perception"), "detector.bench_perception", "the detector on photos and renders"),
    (("twin-node",), "twin.cmd_node", "run the twin as a ROS 2 node"),
    (("controller",), "control.cmd_controller", "run the controller as a ROS 2 node"),
    (("detector-node",), "detector.cmd_node", "run the camera detector as a ROS 2 node"),
    (("episode",), "experiments.inproc", "one lockstep episode in one process (no ROS 2)"),
    (("run",), "experiments.run", "closed-loop episodes: twin node + controller processes"),
    (("sweep",), "experiments.sweep", "a grid of scenarios x seeds in parallel, aggregated"),
    (("bench", "sweep"), "experiments.bench_sweep", "sweep speed-up with 2 workers against 1"),
    (("bench", "line"), "experiments.bench_line", "the line's cost against its number of stations"),
    (
        ("bench", "camera"),
        "experiments.bench_camera",
        "the camera's cost to the loop vs oracle",
    ),
    (("bench", "ray"), "experiments.bench_ray", "the same sweep on the local pool and on Ray"),
    (("report",), "experiments.report", "HTML report with figures from run folders"),
    (("record",), "experiments.record", "record every twin/controller topic to MCAP"),
    (("demo",), "experiments.demo", "the main job: sample, mesh, closed-loop runs, report"),
    (("picture",), "experiments.picture", "a PNG of the cell as the twin renders it"),
    (("photo",), "experiments.photo_render", "a dataset's photo beside the twin's render of it"),
    (("player",), "experiments.player", "an episode's self-contained HTML player"),
    (("fit",), "experiments.fit", "which tools fit a dataset's pieces, by the controllers' rules"),
    (("perception", "fit"), "experiments.oracle_fit", "refit the oracle to the camera's errors"),
)


def _available(module: str) -> bool:
    return importlib.util.find_spec(module) is not None


def selected_command(argv: Sequence[str]) -> tuple[str, ...] | None:
    """The longest command words ``argv`` starts with (``("bench", "sweep")``), if any."""
    matches = [words for words, _, _ in COMMANDS if tuple(argv[: len(words)]) == words]
    return max(matches, key=len, default=None)


def build_parser(only: tuple[str, ...] | None = None) -> argparse.ArgumentParser:
    """Build the argument parser with every subcommand whose module is installed.

    Every subcommand is listed, but with ``only`` just that one's module is imported and its
    options added: a process started as ``cdw-twin twin-node`` (each episode starts two) does
    not import and configure the fifteen others.
    """
    parser = argparse.ArgumentParser(
        prog="cdw-twin",
        description="Digital twin and benchmark for robotic sorting of CDW on a conveyor.",
    )
    top = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    groups: dict[str, argparse._SubParsersAction[argparse.ArgumentParser]] = {}
    for words, module_name, help_text in COMMANDS:
        if not _available(module_name):
            continue
        action = top
        for word in words[:-1]:
            if word not in groups:
                group_parser = top.add_parser(word, help=f"{word} subcommands")
                groups[word] = group_parser.add_subparsers(
                    dest=f"{word}_command", metavar="COMMAND", required=True
                )
            action = groups[word]
        sub = action.add_parser(words[-1], help=help_text, description=help_text)
        sub.set_defaults(_module=module_name)
        if only is None or words == only:
            module = cast(_CommandModule, importlib.import_module(module_name))
            module.configure(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``cdw-twin`` command line; returns the process exit status."""
    words = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(selected_command(words))
    args = parser.parse_args(words)
    module = cast(_CommandModule, importlib.import_module(args._module))
    try:
        return module.run(args)
    except CdwTwinError as exc:
        print(f"cdw-twin: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("cdw-twin: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
