"""``cdw-twin bench sweep --json``: the sweep's speed-up with 2 workers against 1.

Runs the same grid (the default scenario, ``--episodes`` lockstep episodes of ``--duration``
simulated seconds, built-in dataset) once with 1 worker and once with 2, and
prints ``{"speedup": wall_s_1 / wall_s_2, "wall_s_1": ..., "wall_s_2": ..., "episodes": ...}``
plus the episode processes' CPU seconds per pass (``cpu_s_*``), the machine's core count and
the 1-minute load average at the start of each pass: the speed-up can only reach 2 when the two
cores are free for this benchmark. ``machine_speedup`` calibrates the machine in the same run:
the speed-up of ``--workers`` copies of a fixed pure-Python CPU loop run as separate processes
against one copy (median of three). No sweep can scale better than that; on a shared virtual
machine it is often well below the core count.

Episodes last as long as the default scenario's (60 s) unless ``--duration`` says otherwise: the
first 2 s of every episode start the twin and the controller side by side (about 1.7 cores
busy), so short episodes measure start-up more than sweeping. Measured here: 10 s episodes gave
speed-ups of 1.40-2.09 (median 1.6, machine_speedup 1.36-2.29 in the same runs); 60 s episodes
1.75, 1.87 and 1.62 (machine_speedup 1.90-2.05). About 6.5 minutes with the defaults.

Lockstep is the benchmarked mode: it runs as fast as the CPU allows (twin and controller are two
busy processes), so the figure measures throughput. Realtime episodes are paced by the wall clock
and would "parallelise" perfectly whatever the cost, which says nothing about throughput.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from twin.errors import CdwTwinError
from twin.fileio import write_atomic
from twin.scenario import Scenario


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark options."""
    parser.add_argument("--episodes", type=int, default=4, help="episodes per pass (4)")
    parser.add_argument(
        "--duration",
        type=float,
        default=Scenario().duration_s,
        help="sim seconds each (the default scenario's: %(default)s)",
    )
    parser.add_argument("--workers", type=int, default=2, help="workers of the parallel pass")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def _grid(folder: Path, episodes: int, duration_s: float) -> Path:
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


def run(args: argparse.Namespace) -> int:
    """Time the grid with 1 worker, then with ``--workers``."""
    from experiments.sweep import run_sweep
    from twin.builtin import builtin_dataset

    builtin_dataset()  # mesh the sample once, outside the timed passes
    walls: dict[int, float] = {}
    cpus: dict[int, float] = {}
    loads: dict[int, float] = {}
    with tempfile.TemporaryDirectory(prefix="cdw-bench-sweep-") as tmp:
        grid = _grid(Path(tmp), args.episodes, args.duration)
        for workers in (1, args.workers):
            loads[workers] = os.getloadavg()[0]
            t0, c0 = time.perf_counter(), os.times()
            data, code = run_sweep(grid, Path(tmp) / f"w{workers}", workers, quiet=True)
            walls[workers] = time.perf_counter() - t0
            c1 = os.times()
            cpus[workers] = (c1.children_user - c0.children_user) + (
                c1.children_system - c0.children_system
            )
            if code != 0:
                print(json.dumps({"error": data.get("stopped"), "workers": workers}))
                return code
    ceiling = machine_speedup(args.workers)
    result = {
        "speedup": walls[1] / walls[args.workers],
        "machine_speedup": ceiling,
        "wall_s_1": walls[1],
        f"wall_s_{args.workers}": walls[args.workers],
        "workers": args.workers,
        "episodes": args.episodes,
        "duration_s": args.duration,
        "mode": "lockstep",
        "cpu_s_1": cpus[1],
        f"cpu_s_{args.workers}": cpus[args.workers],
        "cpus": os.cpu_count(),
        "loadavg_1m_1": loads[1],
        f"loadavg_1m_{args.workers}": loads[args.workers],
    }
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:>20}: {value}")
    return 0
