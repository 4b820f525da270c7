"""``cdw-twin bench sweep --json``: the sweep's speed-up with 2 workers against 1.

Runs the same grid (the default scenario, ``--episodes`` lockstep episodes of ``--duration``
simulated seconds, built-in dataset) with 1 worker and then with ``--workers`` (2), and repeats
that pair of passes ``--rounds`` times. ``speedup`` is the best (shortest) 1-worker wall time
over the best ``--workers`` wall time, the statistic of ``bench meshgen``: the shortest run is
the one the rest of the machine disturbed least. Every pass's wall and CPU seconds, each
round's own ratio (``speedup_rounds``) and their median are printed next to it.

Why rounds and a best-of: on a shared virtual machine the speed of one core drifts within
minutes, so two long passes timed minutes apart compare two machines as much as two worker
counts. Interleaving the passes and keeping each one's best compares them at the machine's
normal speed. ``machine_speedup`` calibrates the machine after each round: the speed-up of
``--workers`` copies of a fixed pure-Python CPU loop run as separate processes against one copy
(median of three; the median over rounds is printed). No sweep can scale better than that.

The ceiling for this workload is below 2 even on an ideal machine: one lockstep episode keeps
more than one core busy (twin and controller alternate, but Fast DDS's receive and event
threads and the first seconds, in which the processes start side by side, run in parallel),
and the parallel pass has only 2. Episodes last as long as the default scenario's (60 s)
unless ``--duration`` says otherwise; short ones measure start-up more than sweeping. About 10
minutes with the defaults; measurements are in ``docs/benchmarks.md``.

Lockstep is the benchmarked mode: it runs as fast as the CPU allows (twin and controller are two
busy processes), so the figure measures throughput. Realtime episodes are paced by the wall clock
and would "parallelise" perfectly whatever the cost, which says nothing about throughput.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

from interfaces.errors import CdwTwinError
from interfaces.fileio import write_atomic
from twin.scenario import Scenario


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
    "speedup = min(wall_s_1 over rounds) / min(wall_s_N over rounds); each round runs the "
    "1-worker pass, then the N-worker pass, then the machine calibration"
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


def run(args: argparse.Namespace) -> int:
    """Time the grid with 1 worker, then with ``--workers``, ``--rounds`` times over."""
    import statistics

    from experiments.sweep import run_sweep
    from twin.builtin import builtin_dataset

    if args.rounds < 1 or args.episodes < 1 or args.workers < 2:
        msg = (
            f"--rounds {args.rounds}, --episodes {args.episodes}, --workers {args.workers}: "
            "need rounds >= 1, episodes >= 1 and workers >= 2"
        )
        raise CdwTwinError(msg)
    builtin_dataset()  # mesh the sample once, outside the timed passes
    passes = (1, args.workers)
    walls: dict[int, list[float]] = {w: [] for w in passes}
    cpus: dict[int, list[float]] = {w: [] for w in passes}
    loads: dict[int, list[float]] = {w: [] for w in passes}
    ceilings: list[float] = []
    with tempfile.TemporaryDirectory(prefix="cdw-bench-sweep-") as tmp:
        grid = bench_grid(Path(tmp), args.episodes, args.duration)
        for r in range(args.rounds):
            for workers in passes:
                loads[workers].append(round(os.getloadavg()[0], 2))
                t0, c0 = time.perf_counter(), os.times()
                out = Path(tmp) / f"r{r}w{workers}"
                data, code = run_sweep(grid, out, workers, quiet=True)
                walls[workers].append(round(time.perf_counter() - t0, 3))
                c1 = os.times()
                cpu = (c1.children_user - c0.children_user) + (
                    c1.children_system - c0.children_system
                )
                cpus[workers].append(round(cpu, 2))
                if code != 0:
                    print(json.dumps({"error": data.get("stopped"), "workers": workers}))
                    return code
                shutil.rmtree(out)
            ceilings.append(round(machine_speedup(args.workers), 3))
    n = args.workers
    best_1, best_n = min(walls[1]), min(walls[n])
    per_round = [round(a / b, 3) for a, b in zip(walls[1], walls[n], strict=True)]
    result = {
        "speedup": round(best_1 / best_n, 3),
        "statistic": STATISTIC,
        "speedup_rounds": per_round,
        "speedup_median": round(statistics.median(per_round), 3),
        "machine_speedup": round(statistics.median(ceilings), 3),
        "machine_speedup_rounds": ceilings,
        "wall_s_1": best_1,
        f"wall_s_{n}": best_n,
        "wall_s_1_rounds": walls[1],
        f"wall_s_{n}_rounds": walls[n],
        "cpu_s_1_rounds": cpus[1],
        f"cpu_s_{n}_rounds": cpus[n],
        "loadavg_1m_1_rounds": loads[1],
        f"loadavg_1m_{n}_rounds": loads[n],
        "workers": n,
        "episodes": args.episodes,
        "rounds": args.rounds,
        "duration_s": args.duration,
        "mode": "lockstep",
        "cpus": os.cpu_count(),
    }
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:>24}: {value}")
    return 0
