"""``cdw-twin bench line --json``: what the sorting line costs per simulated second, against its
number of stations, and what each station's controller tick costs.

Runs the line scenario (``experiments/scenarios/line.yaml``: the built-in sample at 0.4 m/s,
seed 1) in process and lockstep (``cdw-twin run --transport inproc --no-record``), one episode
of ``--duration`` simulated seconds (60) on the line cut to its first k stations for every k
of ``--stations`` (1, 2, 4, 8: a temporary cell file holding the first k stations of the
scenario's cell), ``--rounds`` times over, interleaved. Per number of stations:

- ``real_time_factor``: the episode's closed-loop real-time factor (sim time over the wall time
  of its stepping loop, the twin's summary), best over the rounds;
- ``cpu_s_per_sim_s``: the CPU seconds (user + system) of the whole episode command, its
  start-up included (every process it started), per simulated second, best (lowest) round;
- ``episodes_per_core_hour``: 3600 / the CPU seconds of one episode, best round;
- ``tick_us``: per station, the wall time of one controller update (the controller's own
  ``control_update_us`` statistics: the phase handlers, the scheduler, the IK, the
  trajectories, the publishing), from the round with the best real-time factor.

``cpu_s_per_added_station`` is the least-squares slope of ``cpu_s_per_sim_s`` against the
number of stations (what one more station costs). With ``--vs PATH`` (a second checkout, e.g.
``git worktree add /work/base HEAD~1`` with its ``fmus/build`` and ``interfaces/build``) each
episode is also run with that tree's code (``PYTHONPATH`` and working directory at PATH), right
after this tree's, and ``vs`` holds its figures and ``ratio`` this tree's over that one's
(``real_time_factor``: new / old; ``cpu``: old / new; above 1 is faster). The figures of a
shared machine drift by a third within minutes (``docs/benchmarks.md``), hence the
interleaving and the best-of.

Example (a few minutes)::

    cdw-twin bench line --duration 10 --stations 1,8 --vs /work/base --json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from interfaces.errors import CdwTwinError

ROOT = Path(__file__).resolve().parents[1]
"""This checkout (the tree whose code ``bench line`` measures first)."""

LINE_SCENARIO = ROOT / "experiments" / "scenarios" / "line.yaml"
"""The benchmarked scenario: the default line at 0.4 m/s."""


class BenchLineError(CdwTwinError):
    """A ``bench line`` option or an episode it ran was wrong (the message says which)."""


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark options."""
    parser.add_argument(
        "--duration", type=float, default=60.0, help="simulated seconds per episode (60)"
    )
    parser.add_argument(
        "--stations", default="1,2,4,8", help="comma-separated station counts (1,2,4,8)"
    )
    parser.add_argument("--seed", type=int, default=1, help="episode seed (1)")
    parser.add_argument("--speed", type=float, default=0.4, help="belt speed m/s (0.4)")
    parser.add_argument("--rounds", type=int, default=1, help="interleaved rounds, best-of (1)")
    parser.add_argument(
        "--scenario", type=Path, default=LINE_SCENARIO, help="line scenario (the default line)"
    )
    parser.add_argument(
        "--vs", type=Path, default=None, help="a second checkout to run the same episodes with"
    )
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def station_counts(value: str) -> tuple[int, ...]:
    """``--stations``: positive counts, comma-separated (``"1,2,4,8"``)."""
    try:
        counts = tuple(int(part) for part in value.split(",") if part.strip())
    except ValueError:
        counts = ()
    if not counts or any(k < 1 for k in counts):
        msg = f"--stations {value!r}: expected positive integers, comma-separated"
        raise BenchLineError(msg)
    return counts


def cut_cell(scenario: Path, k: int, folder: Path) -> Path:
    """Write the scenario's cell file with only its first ``k`` stations into ``folder``
    (named ``<cell>_first<k>``, as a sweep's ``stations: k``); its path."""
    from interfaces.cell import resolve_cell_path
    from twin.scenario import Scenario

    source = resolve_cell_path(Scenario.load(scenario).cell, scenario.parent)
    data = yaml.safe_load(source.read_text(encoding="utf-8"))
    stations = data.get("stations", [])
    if k > len(stations):
        msg = f"--stations {k}: the cell {source} has {len(stations)} station(s)"
        raise BenchLineError(msg)
    data["stations"] = stations[:k]
    data["name"] = f"{data.get('name', source.stem)}_first{k}"
    path = folder / f"{data['name']}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


@dataclass(frozen=True, kw_only=True)
class Episode:
    """One timed episode: its real-time factor, CPU and wall seconds, and per station the
    controller update's statistics (microseconds: ``mean``, ``p95``, ``max``, and ``p50``,
    ``p99`` where the controller writes them)."""

    real_time_factor: float
    cpu_s: float
    wall_s: float
    tick_us: dict[str, dict[str, float | None]]


def _children_cpu_s() -> float:
    times = os.times()
    return times.children_user + times.children_system


def run_episode(
    *, tree: Path, scenario: Path, cell: Path, duration_s: float, seed: int, speed_mps: float
) -> Episode:
    """Run one in-process lockstep episode with the code of ``tree`` (``cdw-twin run
    --transport inproc``, working directory and ``PYTHONPATH`` at ``tree``) and time it."""
    with tempfile.TemporaryDirectory(prefix="cdw-bench-line-") as tmp:
        out = Path(tmp) / "run"
        command = [
            sys.executable,
            "-m",
            "twin.cli",
            "run",
            str(scenario.resolve()),
            "--cell",
            str(cell.resolve()),
            "--transport",
            "inproc",
            "--seed",
            str(seed),
            "--speed",
            str(speed_mps),
            "--duration",
            str(duration_s),
            "--no-record",
            "--out",
            str(out),
            "--json",
        ]
        env = {**os.environ, "PYTHONPATH": str(tree)}
        cpu0, wall0 = _children_cpu_s(), time.perf_counter()
        done = subprocess.run(
            command, cwd=tree, env=env, capture_output=True, text=True, check=False
        )
        wall_s = time.perf_counter() - wall0
        cpu_s = _children_cpu_s() - cpu0
        if done.returncode != 0:
            tail = (done.stderr or done.stdout).strip().splitlines()[-5:]
            msg = f"{tree}: episode on {cell.name} failed ({done.returncode}): {tail}"
            raise BenchLineError(msg)
        metrics = json.loads(done.stdout)
        ticks: dict[str, dict[str, float | None]] = {}
        for path in sorted(out.glob("ep000/controller*.json")):
            stats = json.loads(path.read_text(encoding="utf-8"))
            timing = stats.get("control_update_us", {})
            ticks[str(stats.get("station", path.stem))] = {
                key: timing.get(key) for key in ("p50", "p95", "p99", "max", "mean")
            }
    return Episode(
        real_time_factor=float(metrics["real_time_factor"]),
        cpu_s=cpu_s,
        wall_s=wall_s,
        tick_us=ticks,
    )


@dataclass
class Best:
    """The best round per number of stations of one tree."""

    duration_s: float
    episodes: dict[int, list[Episode]] = field(default_factory=dict)

    def add(self, k: int, episode: Episode) -> None:
        """Keep a round's episode on ``k`` stations."""
        self.episodes.setdefault(k, []).append(episode)

    def result(self) -> dict[str, Any]:
        """Per number of stations the best figures, and the cost of one more station."""
        rows: dict[str, Any] = {}
        points: list[tuple[int, float]] = []
        for k, episodes in sorted(self.episodes.items()):
            fastest = max(episodes, key=lambda e: e.real_time_factor)
            cpu_s = min(e.cpu_s for e in episodes)
            points.append((k, cpu_s / self.duration_s))
            rows[str(k)] = {
                "real_time_factor": round(fastest.real_time_factor, 3),
                "cpu_s_per_sim_s": round(cpu_s / self.duration_s, 3),
                "cpu_s": round(cpu_s, 2),
                "wall_s": round(min(e.wall_s for e in episodes), 2),
                "episodes_per_core_hour": round(3600.0 / cpu_s, 1),
                "tick_us": {
                    station: {key: None if v is None else round(v, 1) for key, v in stats.items()}
                    for station, stats in fastest.tick_us.items()
                },
            }
        return {"stations": rows, "cpu_s_per_added_station": _slope(points)}


def _slope(points: list[tuple[int, float]]) -> float | None:
    """Least-squares slope of ``(x, y)`` points (None with fewer than two distinct x)."""
    if len({x for x, _ in points}) < 2:
        return None
    n = len(points)
    mx = sum(x for x, _ in points) / n
    my = sum(y for _, y in points) / n
    sxx = sum((x - mx) ** 2 for x, _ in points)
    sxy = sum((x - mx) * (y - my) for x, y in points)
    return round(sxy / sxx, 4)


def _ratio(new: dict[str, Any], old: dict[str, Any]) -> dict[str, Any]:
    """This tree's figures over the other's, per number of stations (above 1: faster)."""
    ratio = {}
    for k, row in new["stations"].items():
        other = old["stations"][k]
        ratio[k] = {
            "real_time_factor": round(row["real_time_factor"] / other["real_time_factor"], 3),
            "cpu": round(other["cpu_s_per_sim_s"] / row["cpu_s_per_sim_s"], 3),
        }
    return ratio


def run(args: argparse.Namespace) -> int:
    """Time the line on every number of stations (and on ``--vs``), interleaved."""
    from twin.builtin import builtin_dataset

    counts = station_counts(args.stations)
    if args.duration <= 0.0 or args.rounds < 1:
        msg = f"--duration {args.duration}, --rounds {args.rounds}: need > 0 and >= 1"
        raise BenchLineError(msg)
    trees = [ROOT]
    if args.vs is not None:
        vs = args.vs.expanduser().resolve()
        if not (vs / "twin" / "cli.py").is_file():
            msg = f"--vs {args.vs}: not a cdw-twin checkout (no twin/cli.py)"
            raise BenchLineError(msg)
        trees.append(vs)
    builtin_dataset()  # mesh the sample once, outside the timed episodes
    bests = [Best(duration_s=args.duration) for _ in trees]
    with tempfile.TemporaryDirectory(prefix="cdw-bench-line-cells-") as tmp:
        cells = {k: cut_cell(args.scenario, k, Path(tmp)) for k in counts}
        for _ in range(args.rounds):
            for k in counts:
                for tree, best in zip(trees, bests, strict=True):
                    episode = run_episode(
                        tree=tree,
                        scenario=args.scenario,
                        cell=cells[k],
                        duration_s=args.duration,
                        seed=args.seed,
                        speed_mps=args.speed,
                    )
                    best.add(k, episode)
    result: dict[str, Any] = bests[0].result()
    if len(bests) > 1:
        result["vs"] = bests[1].result()
        result["vs_tree"] = str(trees[1])
        result["ratio"] = _ratio(result, result["vs"])
    result.update(
        {
            "duration_s": args.duration,
            "speed_mps": args.speed,
            "seed": args.seed,
            "rounds": args.rounds,
            "transport": "inproc",
            "mode": "lockstep",
            "statistic": "best of the rounds (real-time factor: highest; CPU: lowest)",
            "cpus": os.cpu_count(),
        }
    )
    print_result(result, as_json=args.json, width=26)
    return 0


def print_result(result: dict[str, Any], *, as_json: bool, width: int) -> None:
    """A benchmark's result: one JSON line, or one ``key: value`` line per figure, the keys
    right-aligned in ``width`` columns."""
    if as_json:
        print(json.dumps(result))
        return
    for key, value in result.items():
        print(f"{key:>{width}}: {value}")


__all__ = [
    "LINE_SCENARIO",
    "BenchLineError",
    "Episode",
    "configure",
    "cut_cell",
    "print_result",
    "run",
    "run_episode",
    "station_counts",
]
