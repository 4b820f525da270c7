"""``cdw-twin bench meshgen [DATASET] --json``: pipeline speed against the trimesh baseline.

Without DATASET a fresh built-in sample is generated in a temporary folder. Both the pipeline
(one process, ``workers=1``) and the baseline (:mod:`meshgen.baseline`) run ``--repeats`` times,
alternating, into fresh folders under one temporary folder; the headline figures are the best
run of each (the machine is shared, so the minimum is the least disturbed run), and
``spread_ms`` gives min/median/max of both. Each run's output is deleted right after it is
timed, so every run starts from the same file-system state.

Where the outputs go: with ``--tmp-dir`` there, and nowhere else. Without it, the headline
figures are measured in a RAM file system (``/dev/shm`` when it is a writable tmpfs) and the
same measurement is repeated in the default temporary folder (``tempfile.gettempdir()``, the
disk users write to) and printed under ``disk``. The reason is that creating a file is kernel
work whose cost is set by the file system, not by this code: on a disk it varies by an order of
magnitude from minute to minute and can exceed the whole pipeline's computation (figures in
``docs/benchmarks.md``, meshgen.cmd_bench), so only the RAM figures compare code.
``file_create_us`` calibrates each file system (microseconds to create and write one small file,
before and after the runs) and ``files_written`` counts the files each variant creates, so
``files_written * file_create_us`` is the part of a figure that is file creation alone;
``file_system`` names the type.

Example::

    cdw-twin bench meshgen /path/to/cdw_stacked_sample --json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the ``bench meshgen`` options."""
    parser.add_argument("dataset", type=Path, nargs="?", default=None, help="dataset folder")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--repeats", type=int, default=10, help="runs per variant (best kept; 10)")
    parser.add_argument(
        "--tmp-dir", type=Path, default=None, help="where outputs go (default: system temp)"
    )


def _file_create_us(target: Path, count: int = 200) -> float:
    """Microseconds to create and write one small file in the new folder ``target``."""
    import os
    import time

    target.mkdir()
    start = time.perf_counter()
    for i in range(count):
        fd = os.open(target / f"f{i}.obj", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.write(fd, b"v 0 0 0\n" * 300)
        os.close(fd)
    return 1e6 * (time.perf_counter() - start) / count


BASELINE = (
    "per object: the same parsing, border check and seeded height as the pipeline; shapely "
    "Polygon, make_valid when invalid, simplify(simplify_mm, preserve_topology=True), orient, "
    "area/centroid/minimum_rotated_rectangle; trimesh.creation.extrude_polygon(engine='earcut'), "
    "translation to the centre of mass, trimesh.exchange.obj.export_obj written to <id>.obj; "
    "plus one scene.csv per image (same columns). No convex decomposition, scene.json, index, "
    "summary, textures, texture coordinates or staging folder (work the pipeline does on top)."
)
"""What ``baseline`` means in the JSON (see :mod:`meshgen.baseline`)."""


def _count_files(folder: Path) -> int:
    return sum(1 for p in folder.rglob("*") if p.is_file())


def _spread(times_s: list[float]) -> dict[str, float]:
    ordered = sorted(times_s)
    return {
        "min": round(1e3 * ordered[0], 3),
        "median": round(1e3 * ordered[len(ordered) // 2], 3),
        "max": round(1e3 * ordered[-1], 3),
    }


def _file_system(folder: Path) -> str:
    """The type of the file system holding ``folder`` (from ``/proc/mounts``; "" if unknown)."""
    try:
        mounts = Path("/proc/mounts").read_text(encoding="utf-8").splitlines()
    except OSError:
        return ""
    best, kind = "", ""
    target = str(folder.resolve())
    for line in mounts:
        fields = line.split()
        if len(fields) < 3:
            continue
        point = fields[1]
        inside = target == point or target.startswith(point.rstrip("/") + "/")
        if inside and len(point) > len(best):
            best, kind = point, fields[2]
    return kind


def _ram_dir() -> Path | None:
    """``/dev/shm`` when it is a writable RAM file system (tmpfs), else None."""
    import os

    shm = Path("/dev/shm")
    if shm.is_dir() and _file_system(shm) == "tmpfs" and os.access(shm, os.W_OK | os.X_OK):
        return shm
    return None


def _measure(dataset: Path | None, parent: Path | None, repeats: int) -> dict[str, Any]:
    """Time pipeline and baseline ``repeats`` times each with outputs under ``parent``."""
    import shutil
    import tempfile

    from meshgen.baseline import run_baseline
    from meshgen.config import MeshgenConfig
    from meshgen.pipeline import mesh_dataset
    from meshgen.sample import write_sample

    work = Path(tempfile.mkdtemp(prefix="cdw-bench-", dir=parent))
    try:
        if dataset is None:
            dataset = work / "sample"
            write_sample(dataset)
        config = MeshgenConfig()
        create_before = _file_create_us(work / "cal_before")
        pipe_s: list[float] = []
        base_s: list[float] = []
        images = objects = base_objects = 0
        files = base_files = 0
        for k in range(repeats):
            summary = mesh_dataset(dataset, work / f"pipeline_{k}", config)
            pipe_s.append(summary.elapsed_s)
            images, objects = summary.images, summary.objects
            files = _count_files(work / f"pipeline_{k}")
            shutil.rmtree(work / f"pipeline_{k}")
            _, base_objects, elapsed = run_baseline(dataset, work / f"baseline_{k}", config)
            base_s.append(elapsed)
            base_files = _count_files(work / f"baseline_{k}")
            shutil.rmtree(work / f"baseline_{k}")
        create_after = _file_create_us(work / "cal_after")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    best, best_base = min(pipe_s), min(base_s)
    return {
        "images": images,
        "objects": objects,
        "baseline_objects": base_objects,
        "ms_per_image": round(1e3 * best / max(images, 1), 4),
        "ms_per_object": round(1e3 * best / max(objects, 1), 4),
        "baseline_ms_per_image": round(1e3 * best_base / max(images, 1), 4),
        "baseline_ms_per_object": round(1e3 * best_base / max(base_objects, 1), 4),
        "speedup": round(best_base / best, 3),
        "spread_ms": {"pipeline": _spread(pipe_s), "baseline": _spread(base_s)},
        "file_create_us": round(0.5 * (create_before + create_after), 1),
        "file_create_us_before_after": [round(create_before, 1), round(create_after, 1)],
        "files_written": {"pipeline": files, "baseline": base_files},
        "tmp_dir": str(work.parent),
        "file_system": _file_system(work.parent),
    }


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and print the figures."""
    import tempfile

    from meshgen.errors import MeshgenError

    if args.repeats < 1:
        msg = f"--repeats must be >= 1, got {args.repeats}"
        raise MeshgenError(msg)
    ram = _ram_dir() if args.tmp_dir is None else None
    primary = _measure(args.dataset, args.tmp_dir if ram is None else ram, args.repeats)
    result: dict[str, Any] = {
        "dataset": str(args.dataset) if args.dataset else "built-in sample",
        "repeats": args.repeats,
        "statistic": "best of repeats, wall clock, one process, parse to export incl. file writes",
        "baseline": BASELINE,
        **primary,
    }
    if ram is not None:
        result["disk"] = _measure(args.dataset, Path(tempfile.gettempdir()), args.repeats)
    if args.json:
        print(json.dumps(result, sort_keys=True))
    else:
        for key, value in result.items():
            print(f"{key:24s} {value}")
    return 0
