"""``cdw-twin demo``: the main job on data the project ships.

Generates the built-in procedural sample, meshes it, then runs one twin episode per belt speed
(0.2, 0.4, 0.6 m/s) and prints summary tables: the meshed objects per class, and per speed the
objects spawned, processed, picked and missed, and the real-time factor. Everything is written
under ``--out`` (default ``out/demo``).
"""

from __future__ import annotations

import argparse
import csv
import time
from collections import defaultdict
from pathlib import Path

SPEEDS_MPS = (0.2, 0.4, 0.6)


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the demo's options."""
    parser.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder")
    parser.add_argument("--images", type=int, default=24, help="sample images (24)")
    parser.add_argument("--seconds", type=float, default=20.0, help="episode length (20 s)")
    parser.add_argument("--seed", type=int, default=0, help="seed (0)")


def _print_table(title: str, header: list[str], rows: list[list[str]]) -> None:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    print(f"\n{title}")
    print("  ".join(h.rjust(w) for h, w in zip(header, widths, strict=True)))
    print("  ".join("-" * w for w in widths))
    for row in rows:
        print("  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)))


def _class_table(meshes: Path) -> list[list[str]]:
    stats: dict[str, list[tuple[float, float, float]]] = defaultdict(list)
    for scene in sorted(meshes.glob("*/scene.csv")):
        with scene.open(newline="", encoding="utf-8") as handle:
            for row in csv.DictReader(handle):
                stats[row["class_name"]].append(
                    (float(row["area_m2"]), float(row["height_m"]), float(row["mass_kg"]))
                )
    rows = []
    for name, values in sorted(stats.items()):
        n = len(values)
        rows.append(
            [
                name,
                str(n),
                f"{1e4 * sum(v[0] for v in values) / n:.1f}",
                f"{1e3 * sum(v[1] for v in values) / n:.1f}",
                f"{sum(v[2] for v in values) / n:.3f}",
            ]
        )
    return rows


def run(args: argparse.Namespace) -> int:
    """Sample, mesh, simulate, summarise."""
    from meshgen.config import MeshgenConfig
    from meshgen.pipeline import mesh_dataset
    from meshgen.sample import write_sample
    from twin.scenario import Scenario, SystemLevel
    from twin.sim import Twin

    out: Path = args.out
    sample, meshes = out / "sample", out / "meshes"
    write_sample(sample, images=args.images, seed=args.seed)
    summary = mesh_dataset(sample, meshes, MeshgenConfig(seed=args.seed))
    print(
        f"meshgen: {summary.images} images, {summary.objects} objects, "
        f"{len(summary.skips)} skipped {summary.skipped}, "
        f"{summary.ms_per_image:.2f} ms/image, {summary.ms_per_object:.3f} ms/object -> {meshes}"
    )
    _print_table(
        "Meshed objects by class",
        ["class", "objects", "area cm2", "height mm", "mass kg"],
        _class_table(meshes),
    )
    rows = []
    for speed in SPEEDS_MPS:
        scenario = Scenario(
            name=f"demo-{speed}",
            seed=args.seed,
            duration_s=args.seconds,
            system=SystemLevel(belt_speed_mps=speed),
        )
        with Twin(scenario, dataset_dir=meshes) as twin:
            twin.reset()
            wall0 = time.perf_counter()
            truncated = False
            while not truncated:
                _, _, _, truncated, _ = twin.step()
            wall = time.perf_counter() - wall0
            scores = twin.scores()
        rows.append(
            [
                f"{speed:.1f}",
                str(scores.spawned),
                str(scores.processed),
                str(scores.picked),
                str(scores.missed),
                f"{scores.miss_rate:.2f}",
                f"{twin.time_s / wall:.1f}",
            ]
        )
    title = f"Twin episodes ({args.seconds:.0f} s each, arm parked: no controller in the loop)"
    _print_table(
        title, ["speed m/s", "spawned", "processed", "picked", "missed", "miss rate", "RTF"], rows
    )
    return 0
