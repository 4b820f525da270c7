"""``cdw-twin run``: closed-loop episodes, the twin node and the controller as two processes.

Example::

    cdw-twin run --speed 0.4 --seed 1 --json
    cdw-twin run experiments/scenarios/default.yaml --episodes 3 --mode realtime --out runs/a

Each episode gets its own ROS domain (claimed with a lock, LOCALHOST discovery). The run folder
holds the resolved scenario, one folder per episode (the twin's ``events.jsonl`` and
``summary.json``, the controller's stats, both processes' logs), ``episodes.json`` and
``episodes.csv`` with the per-episode metrics, and ``run.json`` with their means. ``run.json``
says ``"complete": false`` until every episode has finished, so an interrupted run is recognisable
and its finished episodes stay readable.

Metrics per episode:

- ``picks``: successful picks (``pick_success``), ``placed_correct``: objects in their class bin;
- ``targeted``: objects the controller committed to and finished with (completed or aborted);
- ``success_rate`` = placed_correct / targeted; ``untargeted``: objects never targeted, by reason;
- ``miss_rate``: the twin's missed / processed (objects that left the window unpicked);
- ``throughput_per_min`` = placed_correct per simulated minute;
- ``tracking_time_4mm_mean_s`` / ``_p95_s``: the twin's ground-truth tracking time.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.fileio import write_atomic

METRIC_KEYS = (
    "speed_mps",
    "seed",
    "mode",
    "picks",
    "placed_correct",
    "targeted",
    "untargeted_total",
    "success_rate",
    "miss_rate",
    "throughput_per_min",
    "tracking_time_4mm_mean_s",
    "tracking_time_4mm_p95_s",
    "real_time_factor",
    "faults",
)


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the run options."""
    parser.add_argument("scenario", type=Path, nargs="?", default=None, help="scenario YAML")
    parser.add_argument("--speed", type=float, default=None, help="belt speed m/s (override)")
    parser.add_argument("--episodes", type=int, default=1, help="episodes (1)")
    parser.add_argument("--seed", type=int, default=None, help="first seed (override)")
    parser.add_argument("--duration", type=float, default=None, help="episode seconds")
    parser.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
    parser.add_argument("--dataset", type=Path, default=None, help="meshgen output folder")
    parser.add_argument("--out", type=Path, default=None, help="run folder (default runs/...)")
    parser.add_argument("--json", action="store_true", help="print the run's metrics as JSON")


@dataclass(frozen=True)
class EpisodeSpec:
    """One episode to run."""

    index: int
    seed: int
    folder: Path


def _cli() -> list[str]:
    return [sys.executable, "-m", "twin.cli"]


def _twin_args(args: argparse.Namespace, episode: EpisodeSpec) -> list[str]:
    cmd = [
        *_cli(),
        "twin-node",
        "--mode",
        args.mode,
        "--seed",
        str(episode.seed),
        "--out",
        str(episode.folder / "twin"),
    ]
    if args.scenario is not None:
        cmd += ["--scenario", str(args.scenario)]
    if args.speed is not None:
        cmd += ["--speed", str(args.speed)]
    if args.duration is not None:
        cmd += ["--duration", str(args.duration)]
    if args.dataset is not None:
        cmd += ["--dataset", str(args.dataset)]
    return cmd


def _controller_args(args: argparse.Namespace, episode: EpisodeSpec) -> list[str]:
    cmd = [*_cli(), "controller", "--stats-out", str(episode.folder / "controller.json")]
    if args.mode == "lockstep":
        cmd.append("--lockstep")
    return cmd


def episode_metrics(folder: Path, mode: str) -> dict[str, Any]:
    """The metrics of one finished episode folder."""
    twin = json.loads((folder / "twin" / "summary.json").read_text(encoding="utf-8"))
    ctl_path = folder / "controller.json"
    ctl = json.loads(ctl_path.read_text(encoding="utf-8")) if ctl_path.is_file() else {}
    pick = ctl.get("pick") or {}
    scores = twin["scores"]
    targeted = int(pick.get("completed", 0)) + sum(
        int(v) for v in (pick.get("aborted") or {}).values()
    )
    untargeted = {str(k): int(v) for k, v in (pick.get("untargeted") or {}).items()}
    placed_correct = int(scores["placed_correct"])
    minutes = float(twin["sim_seconds"]) / 60.0
    tracking = twin["tracking"]
    faults = sum(
        1
        for line in (folder / "twin" / "events.jsonl").read_text().splitlines()
        if '"type": "fault"' in line
    )
    return {
        "speed_mps": twin.get("belt_speed_mps"),
        "seed": twin["seed"],
        "mode": mode,
        "picks": int(scores["picked"]),
        "placed_correct": placed_correct,
        "targeted": targeted,
        "untargeted": untargeted,
        "untargeted_total": sum(untargeted.values()),
        "success_rate": placed_correct / targeted if targeted else 0.0,
        "miss_rate": float(scores["miss_rate"]),
        "throughput_per_min": placed_correct / minutes if minutes > 0 else 0.0,
        "tracking_time_4mm_mean_s": tracking["tracking_time_4mm_mean_s"],
        "tracking_time_4mm_p95_s": tracking["tracking_time_4mm_p95_s"],
        "tracking_pursuits": tracking["pursuits"],
        "tracking_unsettled": tracking["unsettled"],
        "real_time_factor": twin["real_time_factor"],
        "faults": faults,
        "complete": bool(twin["complete"]),
    }


def run_episode(args: argparse.Namespace, episode: EpisodeSpec) -> dict[str, Any]:
    """Run one closed-loop episode in its own ROS domain; returns its metrics."""
    from twin.ros_isolation import clean_stale_fastdds_shm, ros_domain

    episode.folder.mkdir(parents=True, exist_ok=True)
    clean_stale_fastdds_shm()
    with (
        ros_domain() as domain,
        (episode.folder / "twin.log").open("wb") as twin_log,
        (episode.folder / "controller.log").open("wb") as ctl_log,
    ):
        env = {**os.environ, **domain.env}
        twin = subprocess.Popen(
            _twin_args(args, episode), env=env, stdout=twin_log, stderr=subprocess.STDOUT
        )
        controller = subprocess.Popen(
            _controller_args(args, episode), env=env, stdout=ctl_log, stderr=subprocess.STDOUT
        )
        try:
            code = twin.wait()
        finally:
            for proc in (controller, twin):
                if proc.poll() is None:
                    proc.send_signal(signal.SIGTERM)
            for proc in (controller, twin):
                try:
                    proc.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    proc.kill()
    if code != 0 or not (episode.folder / "twin" / "summary.json").is_file():
        log = (episode.folder / "twin.log").read_text(errors="replace")[-2000:]
        msg = f"episode {episode.index} failed (exit {code}); twin log tail:\n{log}"
        raise RuntimeError(msg)
    return episode_metrics(episode.folder, args.mode)


def _mean(values: list[Any]) -> float | None:
    numbers = [float(v) for v in values if v is not None]
    return sum(numbers) / len(numbers) if numbers else None


def aggregate(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Means over episodes of every numeric metric."""
    keys = [k for k in METRIC_KEYS if k not in ("mode", "seed", "speed_mps")]
    return {k: _mean([r.get(k) for r in rows]) for k in keys}


def write_tables(
    out: Path, rows: list[dict[str, Any]], complete: bool, extra: dict[str, Any]
) -> dict[str, Any]:
    """``episodes.json``, ``episodes.csv`` and ``run.json`` (atomically)."""
    write_atomic(out / "episodes.json", json.dumps(rows, indent=2) + "\n")
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(METRIC_KEYS), extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    write_atomic(out / "episodes.csv", buffer.getvalue())
    summary = {"complete": complete, "episodes": len(rows), **extra, "mean": aggregate(rows)}
    write_atomic(out / "run.json", json.dumps(summary, indent=2) + "\n")
    return summary


def run(args: argparse.Namespace) -> int:
    """Run the episodes and summarise them."""
    from twin.cmd_node import build_scenario

    node_args = argparse.Namespace(
        scenario=args.scenario,
        dataset=args.dataset,
        speed=args.speed,
        duration=args.duration,
        seed=args.seed,
        objects=None,
        prefill=None,
    )
    scenario, dataset = build_scenario(node_args)
    if args.dataset is None:
        args.dataset = dataset
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out: Path = args.out or Path("runs") / f"{scenario.name}-{stamp}"
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "scenario.yaml", scenario.to_yaml())
    extra = {
        "scenario": scenario.name,
        "mode": args.mode,
        "speed_mps": scenario.system.belt_speed_mps,
    }
    rows: list[dict[str, Any]] = []
    write_tables(out, rows, complete=False, extra=extra)
    for i in range(args.episodes):
        episode = EpisodeSpec(index=i, seed=scenario.seed + i, folder=out / f"ep{i:03d}")
        if not args.json:
            print(f"episode {i + 1}/{args.episodes} (seed {episode.seed}) ...", flush=True)
        metrics = run_episode(args, episode)
        metrics["speed_mps"] = scenario.system.belt_speed_mps
        rows.append(metrics)
        write_tables(out, rows, complete=False, extra=extra)
    summary = write_tables(out, rows, complete=True, extra=extra)
    result = {
        **summary["mean"],
        "speed_mps": scenario.system.belt_speed_mps,
        "mode": args.mode,
        "episodes": len(rows),
        "out": str(out),
        "untargeted": rows[-1]["untargeted"] if rows else {},
    }
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:>28}: {value}")
    return 0
