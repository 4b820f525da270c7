"""The scenario suite loads and validates; injected belt stalls act on the real twin."""

from __future__ import annotations

import dataclasses
import importlib.util
import itertools
import json
import subprocess
import sys
from pathlib import Path

import pytest

from control.config import load_config
from interfaces.cell import CELLS_DIR, load_cell
from twin.scenario import FaultLevel, Scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "experiments" / "scenarios"
EXPECTED = {
    "default",
    "speed_0.2",
    "speed_0.4",
    "speed_0.6",
    "dense",
    "perturbed",
    "perception_low",
    "perception_high",
    "fault_dropout",
    "fault_belt_stall",
    "fault_controller_restart",
    "line",
    "suction",
    "suction_throughput",
    "wide_gripper",
}
GRIDS = SCENARIOS.parent / "grids"
LINE_STANDIN = Path(__file__).resolve().parent / "cells" / "line_standin.yaml"


@pytest.mark.parametrize("cell_name", sorted(p.stem for p in CELLS_DIR.glob("*.yaml")))
@pytest.mark.parametrize("params", ["default", "throughput"])
def test_controller_drops_over_the_cells_bins_and_the_bins_clear_the_belt(
    params: str, cell_name: str
) -> None:
    """Every station's controller (its own process, reading the cell file) must release over
    its bins with its drop tolerance to spare, and no bin may stand on the belt or on another."""
    cell = load_cell(cell_name)
    belt_near_edge = cell.belt.centre_y_m - 0.5 * cell.belt.width_m
    for station in cell.stations:
        config = load_config(
            SCENARIOS.parents[1] / "control" / "config" / f"{params}.yaml",
            cell=cell,
            station=station.name,
        )
        tolerance = config.pick.drop_tolerance_m
        assert set(config.bins) == {b.class_name for b in station.bins}
        for bin_spec in station.bins:
            x, y, z = config.bins[bin_spec.class_name]
            inner_half = bin_spec.inner_half_m
            assert abs(x - bin_spec.centre_x_m) + tolerance <= inner_half, bin_spec
            assert abs(y - bin_spec.centre_y_m) + tolerance <= inner_half, bin_spec
            assert z > bin_spec.top_z_m
            assert bin_spec.centre_y_m + 0.5 * bin_spec.size_m < belt_near_edge
    edges = sorted(
        (b.centre_x_m - 0.5 * b.size_m, b.centre_x_m + 0.5 * b.size_m) for b in cell.bins
    )
    assert all(a[1] <= b[0] for a, b in itertools.pairwise(edges))


def test_every_scenario_file_loads_and_round_trips(tmp_path: Path) -> None:
    files = sorted(SCENARIOS.glob("*.yaml"))
    assert {f.stem for f in files} >= EXPECTED
    for path in files:
        scenario = Scenario.load(path)
        assert scenario.name == path.stem
        assert 0 < scenario.duration_s <= 600
        copy = tmp_path / path.name
        scenario.save(copy)
        assert Scenario.load(copy) == scenario
    speeds = [
        Scenario.load(SCENARIOS / f"speed_{v}.yaml").system.belt_speed_mps for v in (0.2, 0.4, 0.6)
    ]
    assert speeds == [0.2, 0.4, 0.6]
    low = Scenario.load(SCENARIOS / "perception_low.yaml").perception
    high = Scenario.load(SCENARIOS / "perception_high.yaml").perception
    assert low.position_noise_m < Scenario().perception.position_noise_m < high.position_noise_m
    assert Scenario.load(SCENARIOS / "fault_dropout.yaml").faults.detection_dropout
    assert Scenario.load(SCENARIOS / "fault_belt_stall.yaml").faults.belt_stall
    assert Scenario.load(SCENARIOS / "fault_controller_restart.yaml").faults.controller_restart_at_s
    assert Scenario.load(SCENARIOS / "throughput.yaml").controller == "throughput"
    suction = Scenario.load(SCENARIOS / "suction_throughput.yaml")
    assert (suction.controller, suction.cell) == ("suction_throughput", "suction_ur10")
    assert Scenario.load(SCENARIOS / "default.yaml").controller == "default"


def test_belt_stall_stops_the_belt_and_dropout_silences_the_camera(builtin_meshes: Path) -> None:
    """The stall starts once the belt runs at speed (the drive ramps up from standstill) and
    lasts long enough for the drive to ramp down and hold the belt."""
    from twin.sim import Twin

    scenario = dataclasses.replace(
        Scenario(duration_s=4.0),
        faults=FaultLevel(belt_stall=((1.5, 4.0),), detection_dropout=((2.0, 4.0),)),
    )
    speeds: dict[float, float] = {}
    frames_after_dropout = 0
    with Twin(scenario, dataset_dir=builtin_meshes) as twin:
        twin.reset()
        while True:
            _, _, _, truncated, _ = twin.step()
            speeds[round(twin.time_s, 4)] = twin.observe_belt().belt_speed_mps
            frames = twin.take_detections()
            if twin.time_s > 2.2:
                frames_after_dropout += len(frames)
            if truncated:
                break
        kinds = [(e.data["kind"], e.time_s) for e in twin.events if e.type.value == "fault"]
        assert twin.setpoint_mps == pytest.approx(0.4)
    assert speeds[1.5] == pytest.approx(0.4, abs=0.05)
    assert speeds[4.0] < 0.05
    assert frames_after_dropout == 0
    assert kinds == [
        ("injected_belt_stall", 1.5),
        ("injected_detection_dropout", 2.0),
    ]


@pytest.mark.parametrize(
    ("name", "cell"),
    [
        ("line", "line"),
        ("suction", "suction"),
        ("wide_gripper", "wide_gripper"),
        ("default", "default"),
        ("throughput", "default"),
        ("suction_throughput", "suction_ur10"),
    ],
)
def test_the_line_and_each_tool_have_a_scenario_on_their_own_cell(
    name: str, cell: str, builtin_meshes: Path
) -> None:
    """The line and one station per tool each run the reference stream on their shipped cell;
    when that cell exists, the scenario is valid on it (every class has a bin, ...)."""
    from twin.scenario_check import check_scenario

    scenario = Scenario.load(SCENARIOS / f"{name}.yaml")
    assert scenario.cell == cell
    if name not in ("throughput", "suction_throughput"):
        assert (scenario.dataset, scenario.duration_s) == ("builtin", 60.0)
        assert scenario.system.belt_speed_mps == 0.4
    assert (CELLS_DIR / f"{cell}.yaml").is_file()
    check_scenario(scenario, builtin_meshes, where=name, cell=load_cell(cell))


def test_the_line_scenario_is_valid_on_a_line_of_several_stations(builtin_meshes: Path) -> None:
    from twin.scenario_check import check_scenario

    standin = load_cell(LINE_STANDIN)
    assert len(standin.stations) == 3
    scenario = Scenario.load(SCENARIOS / "line.yaml")
    check_scenario(scenario, builtin_meshes, where="line.yaml", cell=standin)
    assert len(load_cell("line").stations) >= 2


@pytest.mark.parametrize("path", sorted(GRIDS.glob("*.yaml")), ids=lambda p: p.stem)
def test_every_benchmark_grid_runs_seeds_1_to_5_in_lockstep_for_60_s(path: Path) -> None:
    """The issue's targets: mean and 95 % interval over seeds 1-5, lockstep, 60 s episodes;
    each grid names the figure it measures (``headline``) and says its command."""
    from experiments.sweep_grid import Grid, expand

    grid = Grid.load(path)
    assert grid.headline
    cells = expand(grid, path.parent)
    assert cells
    for cell in cells:
        assert cell.seeds == (1, 2, 3, 4, 5)
        assert (cell.mode, cell.scenario.duration_s) == ("lockstep", 60.0)
    assert f"cdw-twin sweep experiments/grids/{path.name}" in path.read_text(encoding="utf-8")


@pytest.mark.slow
@pytest.mark.parametrize("name", ["suction", "wide_gripper", "line"])
def test_the_shipped_tool_and_line_scenarios_run_closed_loop(
    name: str, builtin_meshes: Path, tmp_path: Path
) -> None:
    """``cdw-twin run`` of each scenario on its shipped cell, briefly, in lockstep: the twin and
    a controller process per station start with their tools and finish the episode."""
    for module in ("rclpy", "cdw_interfaces"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed in this venv")
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "twin.cli", "run", str(SCENARIOS / f"{name}.yaml")]
    cmd += ["--dataset", str(builtin_meshes), "--duration", "2", "--mode", "lockstep"]
    cmd += ["--out", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    (episode,) = json.loads((out / "episodes.json").read_text(encoding="utf-8"))
    assert episode["complete"] is True
    assert set(episode["stations"]) == {s.name for s in load_cell(name).stations}
