"""``--transport inproc``: the same lockstep episode as over ROS 2, bit for bit.

Each case runs one scenario, seed and cell twice through ``cdw-twin run``, once as a twin node
and one controller process per station over ROS 2 and once in one process on the in-process
bus, and compares what the episode produced: every event line, the final state of every body,
every metric of ``episodes.json`` but the wall-clock ones, and each controller's pick
statistics.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

WALL_CLOCK_METRICS = {"real_time_factor"}
"""The metrics of an episode that measure the machine, not the episode."""

DEFAULT_CELL = "name: same\nduration_s: 10.0\nsystem: {prefill_m: 1.5, belt_speed_mps: 0.4}\n"
TWO_STATIONS = (
    "name: same_line\ncell: two_pandas\nduration_s: 12.0\n"
    "system: {prefill_m: 3.0, belt_speed_mps: 0.3}\n"
)


def _needs_ros() -> None:
    for module in ("rclpy", "cdw_interfaces"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed in this venv")


def _json(path: Path) -> Any:
    return json.loads(path.read_text(encoding="utf-8"))


def _run(scenario: Path, dataset: Path, out: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [
            *(sys.executable, "-m", "twin.cli", "run", str(scenario)),
            *("--dataset", str(dataset), "--out", str(out), *args),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def _episodes(scenario: Path, dataset: Path, out: Path, seed: int) -> tuple[Path, Path]:
    """The same lockstep episode over ROS 2 and in process, run side by side (lockstep: the
    load of one does not change the other's events)."""
    runs = {
        transport: subprocess.Popen(
            [
                *(sys.executable, "-m", "twin.cli", "run", str(scenario), "--dataset"),
                *(str(dataset), "--out", str(out / transport), "--seed", str(seed)),
                *("--transport", transport),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for transport in ("ros", "inproc")
    }
    for transport, process in runs.items():
        try:
            _, err = process.communicate(timeout=300)
        finally:
            process.kill()
        assert process.returncode == 0, f"{transport}: {err[-3000:]}"
    return out / "ros" / "ep000", out / "inproc" / "ep000"


@pytest.mark.parametrize(
    ("text", "seed"),
    [(DEFAULT_CELL, 1), (TWO_STATIONS, 3)],
    ids=["default-seed1", "two_pandas-seed3"],
)
def test_inproc_gives_the_ros_episode_bit_for_bit(
    builtin_meshes: Path, tmp_path: Path, text: str, seed: int
) -> None:
    _needs_ros()
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(text, encoding="utf-8")
    ros, inproc = _episodes(scenario, builtin_meshes, tmp_path, seed)

    events = (ros / "twin" / "events.jsonl").read_bytes()
    assert events == (inproc / "twin" / "events.jsonl").read_bytes()
    ros_summary, inproc_summary = (
        _json(ros / "twin" / "summary.json"),
        _json(inproc / "twin" / "summary.json"),
    )
    assert (ros_summary["transport"], inproc_summary["transport"]) == ("ros", "inproc")
    assert ros_summary["final_state"] == inproc_summary["final_state"]
    assert ros_summary["scores"] == inproc_summary["scores"]

    (ros_row,) = _json(tmp_path / "ros" / "episodes.json")
    (inproc_row,) = _json(tmp_path / "inproc" / "episodes.json")
    assert ros_row.keys() == inproc_row.keys()
    differ = {k for k in ros_row if ros_row[k] != inproc_row[k]}
    assert differ <= WALL_CLOCK_METRICS, {k: (ros_row[k], inproc_row[k]) for k in differ}
    assert ros_row["picked"] > 0, "an episode without a pick compares too little"

    stats = sorted(p.name for p in ros.glob("controller*.json"))
    assert stats == sorted(p.name for p in inproc.glob("controller*.json"))
    for name in stats:
        ros_stats, inproc_stats = _json(ros / name), _json(inproc / name)
        assert ros_stats["pick"] == inproc_stats["pick"], name
        assert ros_stats["received"] == inproc_stats["received"], name
        assert ros_stats["published"] == inproc_stats["published"], name
        assert ros_stats["ticks_acked"] == inproc_stats["ticks_acked"], name


def test_inproc_refuses_realtime_and_controller_restarts(
    builtin_meshes: Path, tmp_path: Path
) -> None:
    scenario = tmp_path / "restart.yaml"
    scenario.write_text(
        "name: restart\nduration_s: 4.0\nfaults: {controller_restart_at_s: [2.0]}\n",
        encoding="utf-8",
    )
    done = _run(scenario, builtin_meshes, tmp_path / "a", "--transport", "inproc")
    assert done.returncode == 2
    assert "controller_restart_at_s [2.0]" in done.stderr
    assert "--transport ros" in done.stderr
    assert not (tmp_path / "a").exists()

    plain = tmp_path / "plain.yaml"
    plain.write_text("name: plain\nduration_s: 2.0\n", encoding="utf-8")
    done = _run(
        plain, builtin_meshes, tmp_path / "b", "--transport", "inproc", "--mode", "realtime"
    )
    assert done.returncode == 2
    assert "--transport inproc runs lockstep only, not --mode realtime" in done.stderr
    assert not (tmp_path / "b").exists()


def test_a_sweep_refuses_inproc_for_a_cell_that_restarts_controllers(tmp_path: Path) -> None:
    from twin.cli import main

    (tmp_path / "restart.yaml").write_text(
        "name: restart\nduration_s: 4.0\nfaults: {controller_restart_at_s: [2.0]}\n",
        encoding="utf-8",
    )
    grid = tmp_path / "grid.yaml"
    grid.write_text("scenarios: [restart.yaml]\nseeds: [1]\n", encoding="utf-8")
    out = tmp_path / "sweep"
    assert main(["sweep", str(grid), "--transport", "inproc", "--out", str(out)]) == 2
    assert not out.exists()


def test_the_episode_takes_the_controller_parameters_its_scenario_names() -> None:
    """Without ``--params-file``, ``cdw-twin episode`` tunes its controllers as ``cdw-twin run``
    does: with the file the scenario's ``controller`` names; without a scenario, the default."""
    import argparse

    from control.cmd_controller import DEFAULT_PARAMS
    from experiments.inproc import scenario_params

    root = Path(__file__).resolve().parents[2]
    line = argparse.Namespace(scenario=root / "experiments" / "scenarios" / "line.yaml")
    assert scenario_params(line) == (root / "control" / "config" / "line.yaml").resolve()
    assert scenario_params(argparse.Namespace(scenario=None)) == DEFAULT_PARAMS
