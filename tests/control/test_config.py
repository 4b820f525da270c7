"""Controller configuration: the tuning file, the cell's station, and errors naming the key."""

from __future__ import annotations

import argparse
import math
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from control.config import ControllerConfig, load_config
from control.errors import ControlConfigError
from interfaces.cell import load_cell

CONFIG_DIR = Path(__file__).parents[2] / "control" / "config"
DEFAULT_YAML = CONFIG_DIR / "default.yaml"


def _write(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "controller.yaml"
    path.write_text("controller:\n  ros__parameters:\n" + body, encoding="utf-8")
    return path


def test_default_yaml_spells_out_the_dataclass_defaults_for_any_robot_but_the_panda(
    tmp_path: Path,
) -> None:
    """default.yaml's sections are the built-in defaults (an xArm station gets exactly them);
    its ``robots.panda`` entry is the reference Panda's tuning on top."""
    text = (Path(__file__).parents[2] / "interfaces" / "cells" / "default.yaml").read_text()
    xarm = tmp_path / "xarm.yaml"
    xarm.write_text(
        text.replace("robot: panda", "robot: xarm6").replace(
            "tool: panda_hand", "tool: xarm_gripper"
        ),
        encoding="utf-8",
    )
    cell = load_cell(xarm)
    assert load_config(DEFAULT_YAML, cell=cell) == ControllerConfig(cell=cell)
    config = load_config(DEFAULT_YAML)
    assert config.tool.open_command == 0.08
    assert config.bins["rubber"] == (0.60, 0.07, 0.15)
    assert config.classes == ("concrete", "brick", "wood", "rubber")
    assert config.steps_per_update == 2
    assert config.pick.approach_space == "joint"  # the Panda's own tuning
    assert config.ready_tcp_position_m == (-0.25, 0.5, 0.15)


def test_a_file_extends_another_key_by_key(tmp_path: Path) -> None:
    base = _write(tmp_path, "    pick:\n      dwell_s: 0.4\n      release_s: 0.1\n")
    top = tmp_path / "top.yaml"
    top.write_text(
        f"extends: {base}\ncontroller:\n  ros__parameters:\n    pick:\n      release_s: 0.2\n",
        encoding="utf-8",
    )
    config = load_config(top)
    assert (config.pick.dwell_s, config.pick.release_s) == (0.4, 0.2)
    loop = tmp_path / "loop.yaml"
    loop.write_text("extends: loop.yaml\ncontroller:\n  ros__parameters: {}\n", encoding="utf-8")
    with pytest.raises(ControlConfigError, match="stacked"):
        load_config(loop)


def test_the_default_station_is_the_reference_cells_exactly() -> None:
    """The reference station at the origin: the cell's numbers unchanged, bit for bit."""
    config = ControllerConfig()
    robot = config.robot
    assert config.station.name == "panda"
    assert config.ready_tcp_position_m == (-0.3, 0.5, 0.2)
    assert config.ready_yaw_rad == math.pi / 2
    assert robot.ready_joint_positions_rad == (math.pi / 2, -0.3, 0.0, -2.2, 0.0, 1.9, math.pi / 4)
    assert robot.joint_max_acceleration_rps2 == (15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0)
    assert config.physics_dt_s == 1.0 / 240.0
    assert config.pick_window_x_m == (-0.35, 0.35)
    assert config.class_priorities == dict.fromkeys(config.classes, 1.0)


def test_partial_file_keeps_other_defaults(tmp_path: Path) -> None:
    path = _write(tmp_path, "    pick:\n      dwell_s: 0.4\n")
    config = load_config(path)
    assert config.pick.dwell_s == 0.4
    assert config.motion == ControllerConfig().motion


def test_a_station_of_another_cell_is_chosen_by_name() -> None:
    cell = load_cell("two_pandas")
    config = load_config(DEFAULT_YAML, cell=cell, station="upstream")
    assert config.station.namespace == "s1"
    assert config.base_position_m == (-1.5, 0.0, 0.0)
    assert config.pick_window_x_m == (-1.85, -1.15)
    assert config.bins["concrete"] == (-2.10, 0.07, 0.15)
    assert load_config(DEFAULT_YAML, cell=cell).station.name == "upstream"  # the first
    with pytest.raises(ControlConfigError, match=r"no station named 'middle'.*upstream, down"):
        load_config(DEFAULT_YAML, cell=cell, station="middle")


@pytest.mark.parametrize(
    ("body", "key", "where"),
    [
        ("    robot:\n      urdf_path: franka_panda/panda.urdf\n", "robot", "robot, tool"),
        ("    belt:\n      width_m: 0.6\n", "belt", "pick_window_x_m"),
        ("    bins:\n      concrete: [-0.6, 0.07, 0.15]\n", "bins", "station's bins"),
        ("    tracking:\n      class_names: [brick]\n", "tracking.class_names", "bins"),
        ("    node:\n      physics_dt_s: 0.004\n", "node.physics_dt_s", "physics_hz"),
        ("    scheduler:\n      hand_width_m: 0.2\n", "scheduler.hand_width_m", "tool's"),
        ("    scheduler:\n      min_height_m: 0.02\n", "scheduler.min_height_m", "pad_height_m"),
        (
            "    motion:\n      joint_max_jerk_rps3: [1.0]\n",
            "motion.joint_max_jerk_rps3",
            "robot's",
        ),
    ],
)
def test_an_old_file_with_what_the_cell_now_says_is_refused_clearly(
    tmp_path: Path, body: str, key: str, where: str
) -> None:
    """Robot, belt, bins (and the tool, class and physics keys) moved to the cell file: a
    parameter file still carrying one is refused with the file, the key and where it lives now
    (the old loader took them as the cell's description)."""
    path = _write(tmp_path, "    pick:\n      dwell_s: 0.5\n" + body)
    with pytest.raises(ControlConfigError) as info:
        load_config(path)
    text = str(info.value)
    assert text.startswith(f"{path}: {key}: this now comes from the cell file (--cell")
    assert where in text
    assert text.endswith("remove it")


@pytest.mark.parametrize(
    ("body", "match"),
    [
        ("    pick:\n      dwell_s: fast\n", r"pick\.dwell_s = 'fast': expected a number"),
        ("    pick:\n      dwel_s: 0.4\n", r"pick: unknown key 'dwel_s'"),
        ("    picking:\n      dwell_s: 0.4\n", r"picking: unknown section"),
        ("    motion:\n      max_jerk: [1, 2, 3]\n", r"motion\.max_jerk = \[1, 2, 3\]: expected 4"),
        ("    tracking:\n      confirm_hits: 0\n", r"tracking\.confirm_hits = 0"),
        ("    scheduler:\n      class_priorities: {gypsum: 2.0}\n", r"not a class of the cell"),
        ("    pick:\n      approach_space: diagonal\n", r"pick\.approach_space = 'diagonal'"),
        ("    motion:\n      control_period_s: 0.005\n", r"whole multiple of the cell's physics"),
        (
            "    pick:\n      close_overlap_s: 0.3\n",
            r"pick\.close_overlap_s = 0\.3: must not exceed dwell_s",
        ),
    ],
)
def test_bad_values_name_file_and_key(tmp_path: Path, body: str, match: str) -> None:
    path = _write(tmp_path, body)
    with pytest.raises(ControlConfigError, match=match) as info:
        load_config(path)
    assert str(path) in str(info.value)


def test_invalid_yaml_names_line(tmp_path: Path) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("controller:\n  ros__parameters:\n    pick: [1, 2\n", encoding="utf-8")
    with pytest.raises(ControlConfigError, match=r"broken\.yaml:\d+:\d+: not valid YAML"):
        load_config(path)


def test_missing_file_and_missing_node(tmp_path: Path) -> None:
    with pytest.raises(ControlConfigError, match="cannot read"):
        load_config(tmp_path / "absent.yaml")
    other = tmp_path / "other.yaml"
    other.write_text("twin:\n  ros__parameters: {}\n", encoding="utf-8")
    with pytest.raises(ControlConfigError, match="top-level key 'controller'"):
        load_config(other)


def test_shipped_throughput_file_changes_only_tuning() -> None:
    throughput = load_config(CONFIG_DIR / "throughput.yaml")
    default = ControllerConfig()
    assert throughput.pick.approach_space == "joint"
    assert throughput.station == default.station
    assert throughput.tracking == default.tracking


def test_the_suction_throughput_file_keeps_its_moves_to_what_the_ur10_can_follow() -> None:
    """The suction throughput benchmark's parameters, on its UR10: throughput first (the next
    target met from the bin, the quickest cycle first, no retry at the point that did not seal),
    the Cartesian moves within what the joints can follow, the reach of the UR10."""
    cell = load_cell("suction_ur10")
    config = load_config(CONFIG_DIR / "suction_throughput.yaml", cell=cell)
    assert config.robot.name == "ur10"
    assert config.motion.posture_acceleration_margin == 0.8
    assert (config.pick.approach_space, config.scheduler.rank) == ("joint", "cycle")
    assert config.pick.grip_retries == 0
    assert config.scheduler.max_reach_m > 1.0
    assert config.tracking == ControllerConfig().tracking


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--cell", "two_pandas", "--station", "nope"],
            r"two_pandas\.yaml: no station named 'nope'",
        ),
        (["--cell", "no_such_cell"], r"cell = 'no_such_cell': no shipped cell of that name"),
        (["--params-file", "OLD"], r"old\.yaml: robot: this now comes from the cell file"),
    ],
)
def test_the_controller_command_refuses_a_bad_cell_station_or_file_in_one_line(
    tmp_path: Path, args: list[str], message: str
) -> None:
    old = tmp_path / "old.yaml"
    old.write_text("controller:\n  ros__parameters:\n    robot: {urdf_path: x}\n", encoding="utf-8")
    args = [str(old) if a == "OLD" else a for a in args]
    done = subprocess.run(
        [sys.executable, "-m", "control", *args], capture_output=True, text=True, check=False
    )
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1
    assert re.search(message, lines[0]), lines


def test_the_controller_resolves_its_cells_slots_as_the_twin_does(
    tmp_path: Path, mesh_polygons: Callable[..., Path]
) -> None:
    """``cdw-twin controller --dataset M`` (and ``--scenario``): the cell's slots take the
    dataset's classes in its table's order, or as the scenario's ``bins:`` map says, as the
    twin node's do; without either, the cell file's own (the shipped classes)."""
    from twin_helpers import box_px

    from control.cmd_controller import controller_cell

    meshes = mesh_polygons({"a": [(2, box_px(300, 300, 100, 60)), (1, box_px(700, 700, 90, 60))]})
    scenario = tmp_path / "s.yaml"
    scenario.write_text(f"dataset: {meshes}\nbins: {{slots: {{wood: 3}}}}\n", encoding="utf-8")

    def bins(**given: object) -> list[tuple[str, float]]:
        args = argparse.Namespace(**{"cell": None, "scenario": None, "dataset": None, **given})
        return [(b.class_name, b.centre_x_m) for b in controller_cell(args).stations[0].bins]

    assert [name for name, _ in bins()] == ["concrete", "brick", "wood", "rubber"]
    assert bins(dataset=meshes) == [("brick", -0.60), ("wood", -0.33)]  # the table's order
    assert bins(scenario=scenario) == [("brick", -0.60), ("wood", 0.60)]
