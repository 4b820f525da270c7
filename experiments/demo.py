"""``cdw-twin demo``: the main job, closed loop, on data the project ships.

Generates the built-in procedural sample, meshes it, runs one closed-loop episode per belt speed
(0.2, 0.4, 0.6 m/s: the twin node and the controller as two processes in lockstep, each on its
own ROS domain, exactly as ``cdw-twin run``), then one episode of the sorting line
(``experiments/scenarios/line.yaml``: several stations along the belt, every station's
controller with the twin in one process, ``cdw-twin run --transport inproc``: the same episode
as over ROS, at a fraction of the cost of a process per station), writes the HTML report and
prints summary tables: the meshed objects per class; per speed the picks, success and miss
rates, tracking time to 4 mm, closed-loop round-trip latency and real-time factor; and per
station of the line and for the whole line the picks per minute, recovery, success and miss
rate; then the reference cell with the camera as its perception against the same with the
oracle (``experiments/scenarios/camera.yaml`` and ``default.yaml``, in process,
``--camera-seconds``): picks, success, the camera's recall, precision, class accuracy and
centroid error, and the real-time factor, and one camera frame with its detections drawn.
Everything goes under ``--out`` (default ``out/demo``): ``sample/``, ``meshes/``,
``runs/speed_*``, ``runs/line``, ``runs/camera``, ``runs/oracle_in_process``,
``camera_frame.png`` and ``report/report.html``.

The line's episode is shorter than the others (``--line-seconds``): in lockstep every station's
controller must answer every tick, so even in one process the line runs slower than real time.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
from collections import defaultdict
from pathlib import Path

from interfaces.errors import CdwTwinError
from interfaces.run_folder import RunFolder
from interfaces.run_records import EpisodeMetrics, EpisodeSummary, RunMeans, read_rows

SPEEDS_MPS = (0.2, 0.4, 0.6)
LINE_SECONDS = 20.0
"""Sim seconds of the line's episode."""
LINE_SCENARIO = Path(__file__).resolve().parent / "scenarios" / "line.yaml"
"""The line the demo runs after the single-station speeds."""
CAMERA_PAIR = tuple(
    Path(__file__).resolve().parent / "scenarios" / name for name in ("camera.yaml", "default.yaml")
)
"""The camera against the oracle: the reference cell's scenario with the camera as its
perception, and the same with the oracle."""
CAMERA_SECONDS = 15.0
"""Sim seconds of each of the camera-against-oracle episodes."""
CAMERA_SPEED_MPS = 0.4


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the demo's options."""
    parser.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder")
    parser.add_argument("--images", type=int, default=24, help="sample images (24)")
    parser.add_argument("--seconds", type=float, default=40.0, help="episode length (40 s)")
    parser.add_argument("--seed", type=int, default=0, help="seed (0)")
    parser.add_argument(
        "--line-scenario", type=Path, default=LINE_SCENARIO, help="the line's scenario file"
    )
    parser.add_argument(
        "--line-seconds",
        type=float,
        default=LINE_SECONDS,
        help="line episode length (%(default)s s)",
    )
    parser.add_argument(
        "--camera-seconds",
        type=float,
        default=CAMERA_SECONDS,
        help="length of the camera and oracle episodes (%(default)s s)",
    )


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


def _fmt(value: object, pattern: str) -> str:
    return "-" if value is None else format(value, pattern)


def _first_row(run_dir: Path) -> EpisodeMetrics:
    """The metrics the run wrote for its first episode."""
    row = read_rows(RunFolder(run_dir).episodes_json)[0]
    if not isinstance(row, EpisodeMetrics):
        msg = f"{RunFolder(run_dir).episodes_json}: the episode failed: {row.reason}"
        raise CdwTwinError(msg)
    return row


def _speed_row(run_dir: Path) -> list[str]:
    row = _first_row(run_dir)
    latency = EpisodeSummary.read(RunFolder(run_dir).episode(0).summary).latency
    return [
        _fmt(row.speed_mps, ".1f"),
        str(row.metric("picks")),
        str(row.metric("targeted")),
        _fmt(row.metric("success_rate"), ".2f"),
        _fmt(row.metric("miss_rate"), ".2f"),
        _fmt(row.metric("tracking_time_4mm_mean_s"), ".2f"),
        _fmt(latency.rtt_ms_p50, ".2f"),
        _fmt(latency.rtt_ms_p99, ".2f"),
        _fmt(row.metric("real_time_factor"), ".2f"),
    ]


def _run_episode(
    out: Path,
    meshes: Path,
    args: argparse.Namespace,
    scenario: Path | None,
    speed: float | None,
    transport: str = "ros",
    seconds: float | None = None,
) -> int:
    """One lockstep episode through ``cdw-twin run`` (over ``transport``; ``seconds`` long,
    else the speeds' or the line's length) into ``out``; returns its exit status."""
    from experiments import run as run_cmd

    options = argparse.Namespace(
        scenario=scenario,
        speed=speed,
        episodes=1,
        seed=args.seed,
        duration=seconds or (args.line_seconds if scenario is not None else args.seconds),
        mode="lockstep",
        dataset=meshes,
        cell=None,
        out=out,
        json=True,
        transport=transport,
        replace=True,
    )
    with contextlib.redirect_stdout(io.StringIO()):
        return run_cmd.run(options)


def line_rows(run_dir: Path) -> list[list[str]]:
    """The line table of a run folder's first episode: per station, then the line, the picks
    per minute, recovery, success and miss rate (``episodes.json``)."""
    row = _first_row(run_dir)
    blocks = [*((f"  {k}", v) for k, v in row.stations.items()), ("line", row.line)]
    return [
        [
            name,
            str(block["picked"]),
            _fmt(block["pick_throughput_per_min"], ".1f"),
            _fmt(block["recovery_rate"], ".2f"),
            _fmt(block["success_rate"], ".2f"),
            _fmt(block["miss_rate"], ".2f"),
        ]
        for name, block in blocks
    ]


def camera_rows(camera_dir: Path, oracle_dir: Path) -> list[list[str]]:
    """The camera-against-oracle table: per perception source the picks, success and miss
    rates, the camera's recall, precision, class accuracy and centroid error (none for the
    oracle: it has nothing to score) and the real-time factor (``episodes.json``)."""
    rows = []
    for name, run_dir in (("camera", camera_dir), ("oracle", oracle_dir)):
        row = _first_row(run_dir)
        centroid = row.metric("perception_centroid_error_median_m")
        rows.append(
            [
                name,
                str(row.metric("picks")),
                str(row.metric("targeted")),
                _fmt(row.metric("success_rate"), ".2f"),
                _fmt(row.metric("miss_rate"), ".2f"),
                _fmt(row.metric("perception_recall"), ".3f"),
                _fmt(row.metric("perception_precision"), ".3f"),
                _fmt(row.metric("perception_class_accuracy"), ".3f"),
                _fmt(None if centroid is None else 1000.0 * centroid, ".1f"),
                _fmt(row.metric("real_time_factor"), ".2f"),
            ]
        )
    return rows


def _camera_against_oracle(out: Path, meshes: Path, args: argparse.Namespace) -> tuple[int, Path]:
    """The reference cell with the camera and with the oracle, in process; the exit status and
    the camera's run folder. The camera's example frame is copied to ``out/camera_frame.png``."""
    import shutil

    print(
        f"the camera against the oracle (reference cell, {CAMERA_SPEED_MPS} m/s, "
        f"{args.camera_seconds:.0f} s each, in process) ...",
        flush=True,
    )
    dirs = [out / "runs" / "camera", out / "runs" / "oracle_in_process"]
    for run_dir, scenario in zip(dirs, CAMERA_PAIR, strict=True):
        code = _run_episode(
            run_dir, meshes, args, scenario, CAMERA_SPEED_MPS, "inproc", args.camera_seconds
        )
        if code != 0:
            return code, dirs[0]
    frames = RunFolder(dirs[0]).episode(0).camera_frames()
    if frames:
        shutil.copyfile(frames[0], out / "camera_frame.png")
    return 0, dirs[0]


def run(args: argparse.Namespace) -> int:
    """Sample, mesh, run closed-loop episodes and the line, report, summarise."""
    from experiments.report import write_report
    from meshgen.config import MeshgenConfig
    from meshgen.pipeline import mesh_dataset
    from meshgen.sample import write_sample

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
    run_dirs = []
    for speed in SPEEDS_MPS:
        run_dir = out / "runs" / f"speed_{speed:.1f}"
        print(f"closed loop at {speed:.1f} m/s, {args.seconds:.0f} s (lockstep) ...", flush=True)
        code = _run_episode(run_dir, meshes, args, None, speed)
        if code != 0:
            return code
        run_dirs.append(run_dir)
    line_dir = out / "runs" / "line"
    print(
        f"the line ({args.line_scenario.name}), {args.line_seconds:.0f} s (lockstep) ...",
        flush=True,
    )
    code = _run_episode(line_dir, meshes, args, args.line_scenario, None, transport="inproc")
    if code != 0:
        return code
    run_dirs.append(line_dir)
    code, camera_dir = _camera_against_oracle(out, meshes, args)
    if code != 0:
        return code
    # the in-process oracle episode stays out of the report: it would pool with the speeds'
    report = write_report([*run_dirs, camera_dir], out / "report", replace=True)
    _print_table(
        f"Closed-loop episodes ({args.seconds:.0f} s each, lockstep, twin + controller processes)",
        [
            "speed m/s",
            "picks",
            "targeted",
            "success",
            "miss",
            "track 4mm s",
            "RTT p50 ms",
            "RTT p99 ms",
            "RTF",
        ],
        [_speed_row(d) for d in run_dirs[:-1]],
    )
    line = RunMeans.read(RunFolder(line_dir).run_json).info
    _print_table(
        f"The line: cell {line.cell}, {len(line.stations)} stations, "
        f"{line.speed_mps} m/s, {args.line_seconds:.0f} s (lockstep, in one process)",
        ["station", "picks", "picks/min", "recovery", "success", "miss"],
        line_rows(line_dir),
    )
    _print_table(
        f"The camera against the oracle: reference cell, {CAMERA_SPEED_MPS} m/s, "
        f"{args.camera_seconds:.0f} s each (lockstep, in one process)",
        [
            "perception",
            "picks",
            "targeted",
            "success",
            "miss",
            "recall",
            "precision",
            "class acc",
            "centroid mm",
            "RTF",
        ],
        camera_rows(camera_dir, out / "runs" / "oracle_in_process"),
    )
    frame = out / "camera_frame.png"
    if frame.is_file():
        print(f"\na camera frame with its detections: {frame}")
    print(f"\nreport: {report}")
    return 0
