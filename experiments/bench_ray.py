"""``cdw-twin bench ray --json``: the same grid on the local pool and on a Ray cluster.

Starts a Ray head on this machine with ``--workers`` CPUs (outside the timed passes: a cluster
is started once and serves many sweeps), then ``--rounds`` times runs the grid (the default
scenario, ``--episodes`` lockstep episodes of ``--duration`` simulated seconds, built-in
dataset) with the local pool of ``--workers`` threads and then on the Ray head, interleaved so
that both meet the machine at the same speed. ``overhead`` is the best Ray wall time over the
best local one, minus one; ``metrics_identical`` says whether every episode's metrics (less
the real-time factor, which measures the machine) and events were the same on both backends
in every round. CPU seconds are the episodes' processes' (children of this process locally,
of the Ray workers on Ray: the tasks measure and report them). The head's start-up is printed
on its own (``ray_start_s``). Measurements are in ``docs/benchmarks.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

from experiments.bench_sweep import bench_grid
from interfaces.errors import CdwTwinError
from interfaces.run_folder import RunFolder
from interfaces.run_records import read_rows
from twin.scenario import Scenario

TIMING = frozenset({"real_time_factor"})
"""Per-episode figures that measure the machine rather than the episode."""


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark options."""
    from experiments.run import add_transport_option

    parser.add_argument("--episodes", type=int, default=4, help="episodes per pass (4)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds of (local, ray) (2)")
    parser.add_argument(
        "--duration",
        type=float,
        default=Scenario().duration_s,
        help="sim seconds each (the default scenario's: %(default)s)",
    )
    parser.add_argument("--workers", type=int, default=2, help="workers / Ray CPUs (2)")
    add_transport_option(parser)
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def _episodes(out: Path) -> list[tuple[dict[str, object], bytes]]:
    """Every episode of a sweep folder: its row as written less the timing figures, and its
    events."""
    found = []
    for cell in sorted(p for p in out.iterdir() if p.is_dir()):
        run = RunFolder(cell)
        for row in read_rows(run.episodes_json):
            events = run.episode(row.episode).events
            kept = {k: v for k, v in row.to_data().items() if k not in TIMING}
            found.append((kept, events.read_bytes()))
    return found


def run(args: argparse.Namespace) -> int:
    """Time the grid on both backends, ``--rounds`` times, interleaved."""
    from experiments.ray_backend import local_head
    from experiments.sweep import Backend, run_sweep
    from twin.builtin import builtin_dataset

    if args.rounds < 1 or args.episodes < 1 or args.workers < 1:
        msg = (
            f"--rounds {args.rounds}, --episodes {args.episodes}, --workers {args.workers}: "
            "each must be >= 1"
        )
        raise CdwTwinError(msg)
    builtin_dataset()  # mesh the sample once, outside the timed passes
    walls: dict[str, list[float]] = {"local": [], "ray": []}
    cpus: dict[str, list[float]] = {"local": [], "ray": []}
    identical = True
    with tempfile.TemporaryDirectory(prefix="cdw-bench-ray-") as tmp:
        grid = bench_grid(Path(tmp), args.episodes, args.duration)
        t_start = time.perf_counter()
        with local_head(args.workers) as address:
            ray_start_s = time.perf_counter() - t_start
            for r in range(args.rounds):
                seen = {}
                backends = (
                    ("local", Backend(transport=args.transport)),
                    ("ray", Backend("ray", address, transport=args.transport)),
                )
                for name, backend in backends:
                    out = Path(tmp) / f"r{r}-{name}"
                    t0, c0 = time.perf_counter(), os.times()
                    data, code = run_sweep(grid, out, args.workers, quiet=True, backend=backend)
                    walls[name].append(round(time.perf_counter() - t0, 3))
                    c1 = os.times()
                    cpu = c1.children_user - c0.children_user
                    cpu += c1.children_system - c0.children_system
                    cpu += data.backend.episode_cpu_s or 0.0
                    cpus[name].append(round(cpu, 2))
                    if code != 0:
                        print(json.dumps({"error": data.stopped, "backend": name}))
                        return code
                    seen[name] = _episodes(out)
                    shutil.rmtree(out)
                identical = identical and seen["local"] == seen["ray"]
    best_local, best_ray = min(walls["local"]), min(walls["ray"])
    result = {
        "overhead": round(best_ray / best_local - 1.0, 3),
        "statistic": "overhead = min(ray wall) / min(local wall) - 1, passes interleaved",
        "metrics_identical": identical,
        "wall_s_local": best_local,
        "wall_s_ray": best_ray,
        "wall_s_local_rounds": walls["local"],
        "wall_s_ray_rounds": walls["ray"],
        "cpu_s_local_rounds": cpus["local"],
        "cpu_s_ray_rounds": cpus["ray"],
        "ray_start_s": round(ray_start_s, 2),
        "workers": args.workers,
        "transport": args.transport,
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
