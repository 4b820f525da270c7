"""``cdw-twin bench camera --json``: what the camera costs the closed loop, against the oracle.

Runs a scenario with ``perception.source: camera`` and its twin with the oracle (by default
``experiments/scenarios/camera.yaml`` and ``default.yaml``: the reference cell, the built-in
sample at 0.4 m/s, the camera at 15 Hz; ``--line`` takes ``line_camera.yaml`` and ``line.yaml``)
in process and lockstep (``cdw-twin run --transport inproc --no-record``), one episode of
``--duration`` simulated seconds each, ``--rounds`` times over, interleaved (the machine's speed
drifts within minutes). Per source, best over the rounds: the closed-loop ``real_time_factor``
(sim time over the stepping loop's wall time) and ``cpu_s_per_sim_s`` (the episode command's
CPU seconds, every process it started, per simulated second); ``ratio``: the camera's
real-time factor over the oracle's (issue 36's target: >= 0.7).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from experiments.bench_line import BenchLineError, Episode, print_result, run_episode
from interfaces.cell import load_cell

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "experiments" / "scenarios"

PAIRS: dict[str, tuple[Path, Path]] = {
    "reference": (SCENARIOS / "camera.yaml", SCENARIOS / "default.yaml"),
    "line": (SCENARIOS / "line_camera.yaml", SCENARIOS / "line.yaml"),
}
"""The benchmarked pairs: (camera scenario, oracle scenario), the same but for the perception."""


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark options."""
    parser.add_argument(
        "--duration", type=float, default=20.0, help="simulated seconds per episode (20)"
    )
    parser.add_argument("--rounds", type=int, default=2, help="interleaved rounds, best-of (2)")
    parser.add_argument("--seed", type=int, default=1, help="episode seed (1)")
    parser.add_argument("--speed", type=float, default=0.4, help="belt speed m/s (0.4)")
    parser.add_argument("--line", action="store_true", help="the line with its four cameras (slow)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def _cell_file(scenario: Path) -> Path:
    """The cell file a scenario names (its ``cell:``, a shipped name)."""
    import yaml

    data = yaml.safe_load(scenario.read_text(encoding="utf-8"))
    name = data.get("cell", "default") if isinstance(data, dict) else "default"
    cell = load_cell(name)
    if not cell.source:
        msg = f"{scenario}: its cell {name!r} has no file"
        raise BenchLineError(msg)
    return Path(cell.source)


def _figures(episodes: list[Episode], duration_s: float) -> dict[str, float]:
    return {
        "real_time_factor": round(max(e.real_time_factor for e in episodes), 3),
        "cpu_s_per_sim_s": round(min(e.cpu_s for e in episodes) / duration_s, 3),
    }


def run(args: argparse.Namespace) -> int:
    """Time the camera and the oracle episodes, interleaved, and print their figures."""
    from twin.builtin import builtin_dataset

    if args.duration <= 0.0 or args.rounds < 1:
        msg = f"--duration {args.duration}, --rounds {args.rounds}: need > 0 and >= 1"
        raise BenchLineError(msg)
    pair = "line" if args.line else "reference"
    builtin_dataset()  # mesh the sample once, outside the timed episodes
    runs: dict[str, list[Episode]] = {"camera": [], "oracle": []}
    for _ in range(args.rounds):
        for source, scenario in zip(("camera", "oracle"), PAIRS[pair], strict=True):
            runs[source].append(
                run_episode(
                    tree=ROOT,
                    scenario=scenario,
                    cell=_cell_file(scenario),
                    duration_s=args.duration,
                    seed=args.seed,
                    speed_mps=args.speed,
                )
            )
    camera, oracle = (_figures(runs[s], args.duration) for s in ("camera", "oracle"))
    result: dict[str, Any] = {
        "pair": pair,
        "scenarios": [str(p.relative_to(ROOT)) for p in PAIRS[pair]],
        "camera": camera,
        "oracle": oracle,
        "ratio": round(camera["real_time_factor"] / oracle["real_time_factor"], 3),
        "duration_s": args.duration,
        "rounds": args.rounds,
        "seed": args.seed,
        "speed_mps": args.speed,
        "transport": "inproc",
        "mode": "lockstep",
        "statistic": "best of the rounds (real-time factor: highest; CPU: lowest)",
        "cpus": os.cpu_count(),
    }
    print_result(result, as_json=args.json, width=18)
    return 0


__all__ = ["PAIRS", "configure", "run"]
