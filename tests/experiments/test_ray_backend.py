"""Sweeps on a real Ray cluster on this machine (a head on a free port, 2 CPUs): the same
lockstep metrics as the local pool, a killed worker's episode retried, nothing shared but Ray."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from experiments.ray_backend import local_head
from experiments.run_types import RunOptions
from experiments.sweep import run_sweep
from experiments.sweep_shipping import pack, unpack, worker_options
from interfaces.run_folder import RunFolder

pytest.importorskip("ray")

REPO = Path(__file__).resolve().parents[2]
DEFAULT_SCENARIO = REPO / "experiments" / "scenarios" / "default.yaml"
TIMING_METRICS = frozenset({"real_time_factor"})
"""The per-episode figures that measure the machine, not the episode."""


@pytest.fixture(scope="module")
def ray_head() -> Iterator[tuple[str, dict[str, str]]]:
    """A Ray head with 2 CPUs on a free port; its address and the environment a client needs
    (the head's authentication token, as Ray enables by default)."""
    with local_head(2) as address:
        yield address, {**os.environ, "RAY_USAGE_STATS_ENABLED": "0"}


def _grid(tmp_path: Path, seeds: str, duration_s: float) -> Path:
    grid = tmp_path / "grid.yaml"
    grid.write_text(
        f"scenarios: [{DEFAULT_SCENARIO}]\nseeds: {seeds}\n"
        f"overrides: {{duration_s: [{duration_s}]}}\n",
        encoding="utf-8",
    )
    return grid


def _sweep_on_ray(
    grid: Path, out: Path, address: str, env: dict[str, str], dataset: Path
) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "sweep",
            str(grid),
            "--backend",
            "ray",
            "--record",
            "--address",
            address,
            "--dataset",
            str(dataset),
            "--out",
            str(out),
            "--json",
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )


def _rows(cell_folder: Path) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = json.loads(RunFolder(cell_folder).episodes_json.read_text())
    return rows


def _without_timing(row: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in row.items() if k not in TIMING_METRICS}


@pytest.mark.slow
def test_a_grid_gives_the_same_lockstep_metrics_on_ray_as_on_the_local_pool(
    ray_head: tuple[str, dict[str, str]], builtin_meshes: Path, tmp_path: Path
) -> None:
    address, env = ray_head
    grid = _grid(tmp_path, "[1, 2]", 3.0)
    summary, code = run_sweep(grid, tmp_path / "local", 2, quiet=True, dataset=builtin_meshes)
    assert code == 0
    assert summary.backend.name == "local"
    proc = _sweep_on_ray(grid, tmp_path / "ray", address, env, builtin_meshes)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err.decode()[-3000:]
    on_ray = json.loads(out)
    assert on_ray["backend"]["name"] == "ray"
    assert on_ray["backend"]["address"] == address
    assert on_ray["backend"]["episode_cpu_s"] > 0
    assert on_ray["episodes"] == summary.episodes == 2
    assert on_ray["failed"] == summary.failed == 0
    (cell,) = [c.cell for c in summary.cells]
    for i in range(2):
        a = RunFolder(tmp_path / "local" / cell).episode(i)
        b = RunFolder(tmp_path / "ray" / cell).episode(i)
        assert a.events.read_bytes() == b.events.read_bytes(), f"{i}: the events differ"
        assert b.recording.stat().st_size > 0
    rows_local = [_without_timing(r) for r in _rows(tmp_path / "local" / cell)]
    rows_ray = [_without_timing(r) for r in _rows(tmp_path / "ray" / cell)]
    assert rows_local == rows_ray
    agg_local = summary.cells[0].aggregate.line.metrics["placed_correct"].to_data()
    agg_ray = on_ray["cells"][0]["aggregate"]["metrics"]["placed_correct"]
    assert agg_local == agg_ray


def _ray_task_pids(function: str) -> list[int]:
    """Processes whose title says they run the Ray task ``function`` (``ray::<function>``)."""
    pids = []
    for pid_dir in Path("/proc").iterdir():
        if not pid_dir.name.isdigit():
            continue
        try:
            title = (pid_dir / "cmdline").read_bytes().split(b"\0")[0].decode(errors="replace")
        except OSError:
            continue
        if title.startswith(f"ray::{function}"):
            pids.append(int(pid_dir.name))
    return pids


@pytest.mark.slow
def test_a_worker_killed_mid_episode_gets_its_episode_retried(
    ray_head: tuple[str, dict[str, str]], builtin_meshes: Path, tmp_path: Path
) -> None:
    address, env = ray_head
    grid = _grid(tmp_path, "[3]", 20.0)  # long enough to be killed in, on a fast machine
    proc = _sweep_on_ray(grid, tmp_path / "ray", address, env, builtin_meshes)
    deadline = time.monotonic() + 120
    while not (pids := _ray_task_pids("run_shipped_episode")):
        assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
        assert time.monotonic() < deadline, "no Ray worker started the episode"
        time.sleep(0.2)
    time.sleep(2.0)  # into the episode: its twin and controller are running
    for pid in pids:
        os.kill(pid, signal.SIGKILL)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err.decode()[-3000:]
    data = json.loads(out)
    assert data["episodes"] == 1
    assert data["failed"] == 0
    assert len(data["retried"]) == 1
    assert "episode 0 (seed 3)" in data["retried"][0]
    assert "WorkerCrashedError" in data["retried"][0]
    (cell,) = data["cells"]
    assert cell["aggregate"]["episodes"] == 1
    summary = json.loads(RunFolder(tmp_path / "ray" / cell["cell"]).episode(0).summary.read_text())
    assert summary["complete"] is True
    assert summary["sim_seconds"] == pytest.approx(20.0)


def test_an_episode_folder_travels_whole_and_lands_whole(tmp_path: Path) -> None:
    src = tmp_path / "ep000"
    (src / "twin").mkdir(parents=True)
    (src / "twin" / "events.jsonl").write_bytes(b'{"type": "spawned"}\n')
    (src / "recording.mcap").write_bytes(bytes(range(256)) * 10)
    archive = pack(src)
    assert pack(src) == archive  # the same folder gives the same bytes
    dest = tmp_path / "driver" / "ep000"
    dest.mkdir(parents=True)
    (dest / "stale.txt").write_text("from an earlier try")
    unpack(archive, dest)
    assert sorted(p.relative_to(dest).as_posix() for p in dest.rglob("*")) == [
        "recording.mcap",
        "twin",
        "twin/events.jsonl",
    ]
    assert (dest / "recording.mcap").read_bytes() == (src / "recording.mcap").read_bytes()
    assert not [p for p in dest.parent.iterdir() if p.name.startswith(".")]


def test_a_worker_runs_from_its_own_copy_of_the_run_folder(tmp_path: Path) -> None:
    driver = tmp_path / "driver" / "cell"
    options = RunOptions(
        scenario_path=driver / "scenario.yaml",
        dataset=tmp_path / "data",
        cell_path=driver / "cell.yaml",
        stations=("s1",),
        controller_params=driver / "controller.yaml",
    )
    mine = worker_options(options, tmp_path / "worker" / "run", tmp_path / "cache" / "abc")
    assert mine.scenario_path == tmp_path / "worker" / "run" / "scenario.yaml"
    assert mine.cell_path == tmp_path / "worker" / "run" / "cell.yaml"
    assert mine.controller_params == tmp_path / "worker" / "run" / "controller.yaml"
    assert mine.dataset == tmp_path / "cache" / "abc"
    assert mine.stations == ("s1",)


def test_ray_options_without_the_ray_backend_are_refused(tmp_path: Path) -> None:
    grid = _grid(tmp_path, "[1]", 1.0)
    proc = subprocess.run(
        [sys.executable, "-m", "twin.cli", "sweep", str(grid), "--address", "127.0.0.1:1"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        cwd=tmp_path,
    )
    assert proc.returncode == 2
    assert "--address and --cpus-per-episode need --backend ray" in proc.stderr
    assert not (tmp_path / "runs").exists()
