"""``cdw-twin bench sweep --json``: what a lockstep episode costs, on each transport, and the
sweep's speed-up with 2 workers against 1.

Runs the same grid (the default scenario at 0.4 m/s, ``--episodes`` lockstep episodes of
``--duration`` simulated seconds, built-in dataset; no recordings, as a sweep writes none
unless ``--record``) on each transport of ``--transports``
(``ros``: a twin node and a controller process over ROS 2; ``inproc``: one process, see
:mod:`experiments.inproc`), each with 1 worker and then with ``--workers`` (2), and repeats
that set of passes ``--rounds`` times, interleaved (round r: ros 1 worker, ros N, inproc 1,
inproc N). Per transport:

- ``episodes_per_core_hour``: 3600 x episodes / the CPU seconds (user + system) of the pass,
  the runner's own and every process it started, best (lowest) 1-worker pass: the cost of an
  episode, whatever the parallelism;
- ``real_time_factor``: each episode's closed-loop real-time factor (sim time over the wall
  time of its stepping loop, the twin's summary), best over the 1-worker passes' episodes;
- ``speedup``: the best 1-worker wall time over the best ``--workers`` wall time (the statistic
  of ``bench meshgen``: the shortest run is the one the rest of the machine disturbed least),
  with every round's own ratio and their median.

``inproc_over_ros`` gives the ratios of the first two (when both transports ran).

Why rounds, interleaving and a best-of: on a shared virtual machine the speed of one core
drifts within minutes, so two long passes timed minutes apart compare two machines as much as
two configurations. ``machine_speedup`` calibrates the machine after each round: the speed-up
of ``--workers`` copies of a fixed pure-Python CPU loop run as separate processes against one
copy (median of three; the median over rounds is printed). No sweep can scale better than that.
Over ROS 2 one lockstep episode keeps more than one core busy at times (twin and controller
alternate, but Fast DDS's threads and the start, in which the processes start side by side,
run in parallel), so its parallel pass has less than 2 cores to gain; an in-process episode is
one single-threaded process. Episodes last as long as the default scenario's (60 s) unless
``--duration`` says otherwise; short ones measure start-up more than sweeping. Measurements are
in ``docs/benchmarks.md``.

Lockstep is the benchmarked mode: it runs as fast as the CPU allows, so the figure measures
throughput. Realtime episodes are paced by the wall clock and would "parallelise" perfectly
whatever the cost, which says nothing about throughput.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from interfaces.errors import CdwTwinError
from interfaces.fileio import write_atomic
from twin.scenario import Scenario

if TYPE_CHECKING:
    from experiments.run_types import Transport


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark options."""
    parser.add_argument(
        "--episodes", type=int, default=2, help="episodes per pass (2: one batch of 2 workers)"
    )
    parser.add_argument(
        "--rounds", type=int, default=3, help="rounds of (1-worker pass, parallel pass) (3)"
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=Scenario().duration_s,
        help="sim seconds each (the default scenario's: %(default)s)",
    )
    parser.add_argument("--workers", type=int, default=2, help="workers of the parallel pass")
    parser.add_argument(
        "--transports",
        default="ros,inproc",
        help="comma-separated transports to measure (ros,inproc)",
    )
    parser.add_argument(
        "--record",
        action="store_true",
        help="record every episode's MCAP, as sweep --record does (default: as sweep, none)",
    )
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def bench_grid(folder: Path, episodes: int, duration_s: float) -> Path:
    """The benchmark grid: the default scenario at 0.4 m/s, ``episodes`` lockstep episodes."""
    scenario = folder / "bench.yaml"
    write_atomic(
        scenario, f"name: bench\nduration_s: {duration_s}\nsystem:\n  belt_speed_mps: 0.4\n"
    )
    grid = folder / "grid.yaml"
    write_atomic(
        grid,
        f"scenarios: [bench.yaml]\nepisodes: {episodes}\noverrides:\n  mode: [lockstep]\n",
    )
    return grid


STATISTIC = (
    "per transport: speedup = min(wall_s_1 over rounds) / min(wall_s_N over rounds); "
    "episodes_per_core_hour = 3600 * episodes / min(cpu_s_1 over rounds); each round runs, per "
    "transport, the 1-worker pass, then the N-worker pass; then the machine calibration"
)

_CALIBRATION = "x = 0\nfor i in range(4_000_000):\n    x += i * i % 7\n"


def machine_speedup(workers: int, repeats: int = 3) -> float:
    """Throughput of ``workers`` parallel CPU-bound processes over one (median of repeats)."""
    import statistics
    import subprocess
    import sys

    def wall(copies: int) -> float:
        start = time.perf_counter()
        procs = [subprocess.Popen([sys.executable, "-c", _CALIBRATION]) for _ in range(copies)]
        for proc in procs:
            if proc.wait() != 0:
                msg = f"machine calibration: a CPU-loop process exited with {proc.returncode}"
                raise CdwTwinError(msg)
        return time.perf_counter() - start

    ratios = [workers * wall(1) / wall(workers) for _ in range(repeats)]
    return statistics.median(ratios)


def _transports(value: str) -> tuple[Transport, ...]:
    from experiments.run_types import TRANSPORTS

    names = tuple(v.strip() for v in value.split(",") if v.strip())
    bad = [n for n in names if n not in TRANSPORTS]
    if not names or bad or len(set(names)) != len(names):
        msg = f"--transports {value!r}: a comma-separated list of distinct {', '.join(TRANSPORTS)}"
        raise CdwTwinError(msg)
    return cast("tuple[Transport, ...]", names)


@dataclass
class PassLog:
    """Every pass of one transport: wall and CPU seconds, load, episode real-time factors."""

    walls: dict[int, list[float]] = field(default_factory=dict)
    cpus: dict[int, list[float]] = field(default_factory=dict)
    loads: dict[int, list[float]] = field(default_factory=dict)
    rtfs: list[float] = field(default_factory=list)

    def add(self, workers: int, wall_s: float, cpu_s: float, load: float) -> None:
        """One pass of ``workers`` workers."""
        self.walls.setdefault(workers, []).append(round(wall_s, 3))
        self.cpus.setdefault(workers, []).append(round(cpu_s, 2))
        self.loads.setdefault(workers, []).append(round(load, 2))

    def result(self, n: int, episodes: int) -> dict[str, Any]:
        """The transport's figures (see the module docstring)."""
        import statistics

        best_1, best_n = min(self.walls[1]), min(self.walls[n])
        per_round = [round(a / b, 3) for a, b in zip(self.walls[1], self.walls[n], strict=True)]
        return {
            "episodes_per_core_hour": round(3600.0 * episodes / min(self.cpus[1]), 2),
            "real_time_factor": round(max(self.rtfs), 3),
            "real_time_factor_median": round(statistics.median(self.rtfs), 3),
            "real_time_factors": self.rtfs,
            "speedup": round(best_1 / best_n, 3),
            "speedup_rounds": per_round,
            "speedup_median": round(statistics.median(per_round), 3),
            "wall_s_1": best_1,
            f"wall_s_{n}": best_n,
            "wall_s_1_rounds": self.walls[1],
            f"wall_s_{n}_rounds": self.walls[n],
            "cpu_s_1_rounds": self.cpus[1],
            f"cpu_s_{n}_rounds": self.cpus[n],
            "loadavg_1m_1_rounds": self.loads[1],
            f"loadavg_1m_{n}_rounds": self.loads[n],
        }


def _episode_rtfs(out: Path) -> list[float]:
    """The closed-loop real-time factor of every episode of a finished sweep folder (from each
    twin's summary; one that states none has none to give)."""
    from interfaces.run_folder import RunFolder
    from interfaces.run_records import EpisodeSummary

    summaries = [
        EpisodeSummary.read(episode.summary)
        for cell in sorted(p for p in out.iterdir() if p.is_dir())
        for episode in RunFolder(cell).episodes()
        if episode.summary.is_file()
    ]
    return [round(s.real_time_factor, 3) for s in summaries if s.real_time_factor is not None]


def _cpu_s(before: os.times_result, after: os.times_result) -> float:
    """CPU seconds between two ``os.times()``: this process's and its finished children's."""
    return float(
        sum(
            getattr(after, k) - getattr(before, k)
            for k in ("user", "system", "children_user", "children_system")
        )
    )


def run(args: argparse.Namespace) -> int:
    """Time the grid with 1 worker, then with ``--workers``, on every transport, ``--rounds``
    times over, interleaved."""
    import statistics

    from experiments.sweep import Backend, run_sweep
    from twin.builtin import builtin_dataset

    if args.rounds < 1 or args.episodes < 1 or args.workers < 2:
        msg = (
            f"--rounds {args.rounds}, --episodes {args.episodes}, --workers {args.workers}: "
            "need rounds >= 1, episodes >= 1 and workers >= 2"
        )
        raise CdwTwinError(msg)
    transports = _transports(args.transports)
    builtin_dataset()  # mesh the sample once, outside the timed passes
    n = args.workers
    logs = {t: PassLog() for t in transports}
    ceilings: list[float] = []
    with tempfile.TemporaryDirectory(prefix="cdw-bench-sweep-") as tmp:
        grid = bench_grid(Path(tmp), args.episodes, args.duration)
        for r in range(args.rounds):
            for transport in transports:
                for workers in (1, n):
                    load = os.getloadavg()[0]
                    t0, c0 = time.perf_counter(), os.times()
                    out = Path(tmp) / f"r{r}-{transport}-w{workers}"
                    backend = Backend(transport=transport, record=args.record)
                    data, code = run_sweep(grid, out, workers, quiet=True, backend=backend)
                    wall = time.perf_counter() - t0
                    logs[transport].add(workers, wall, _cpu_s(c0, os.times()), load)
                    if code != 0:
                        print(json.dumps({"error": data.stopped, "transport": transport}))
                        return code
                    if workers == 1:
                        logs[transport].rtfs.extend(_episode_rtfs(out))
                    shutil.rmtree(out)
            ceilings.append(round(machine_speedup(n), 3))
    result: dict[str, Any] = {t: logs[t].result(n, args.episodes) for t in transports}
    if "ros" in result and "inproc" in result:
        ros, inproc = result["ros"], result["inproc"]
        result["inproc_over_ros"] = {
            "episodes_per_core_hour": round(
                inproc["episodes_per_core_hour"] / ros["episodes_per_core_hour"], 3
            ),
            "real_time_factor": round(inproc["real_time_factor"] / ros["real_time_factor"], 3),
        }
    result.update(
        {
            "statistic": STATISTIC,
            "machine_speedup": round(statistics.median(ceilings), 3),
            "machine_speedup_rounds": ceilings,
            "workers": n,
            "episodes": args.episodes,
            "rounds": args.rounds,
            "duration_s": args.duration,
            "mode": "lockstep",
            "record": args.record,
            "cpus": os.cpu_count(),
        }
    )
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:>24}: {value}")
    return 0
