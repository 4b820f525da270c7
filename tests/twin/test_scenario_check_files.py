"""check_scenario finds, before anything starts, what the twin would only meet when it starts:
a belt-drive FMU that is no FMU or lacks a mapped variable, a URDF that cannot be read, a pick
window out of its robot's reach. Each is one line naming the scenario, the cell and the key."""

from __future__ import annotations

import copy
import re
from pathlib import Path
from typing import Any

import pytest
import yaml

from interfaces.catalog import _catalog
from interfaces.cell import DEFAULT_CELL, load_cell
from twin.errors import ConfigError
from twin.scenario import Scenario
from twin.scenario_check import check_scenario


def _cell(tmp_path: Path, edit: Any) -> Path:
    data = yaml.safe_load(DEFAULT_CELL.read_text(encoding="utf-8"))
    edit(data)
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def _check(cell: Path, dataset: Path) -> None:
    check_scenario(Scenario(), dataset, where="s.yaml", cell=load_cell(cell))


def _drive(fmu: Path, **changes: Any) -> Any:
    def edit(data: dict[str, Any]) -> None:
        data["drive"]["fmu"] = str(fmu)
        for key, value in changes.items():
            data["drive"][key] = value

    return edit


def _robot(**changes: Any) -> Any:
    def edit(data: dict[str, Any]) -> None:
        data["stations"][0]["robot"] = {
            "name": "panda",
            **copy.deepcopy(_catalog()["robots"]["panda"]),
            **changes,
        }

    return edit


def test_a_non_zip_fmu_is_refused_up_front(tmp_path: Path, builtin_meshes: Path) -> None:
    fake = tmp_path / "belt.fmu"
    fake.write_text("not a zip", encoding="utf-8")
    cell = _cell(tmp_path, _drive(fake))
    pattern = rf"s\.yaml: the cell {re.escape(str(cell))}: drive: .*belt\.fmu: not a valid FMU"
    with pytest.raises(ConfigError, match=pattern + r": not a zip archive"):
        _check(cell, builtin_meshes)


def test_an_fmu_without_a_mapped_variable_is_refused_up_front(
    tmp_path: Path, builtin_meshes: Path, built_fmus: tuple[Path, Path]
) -> None:
    mapping = {"speed_setpoint": "speed_setpoint_mps", "belt_speed": "conveyor_speed"}
    cell = _cell(tmp_path, _drive(built_fmus[0], mapping=mapping))
    with pytest.raises(
        ConfigError,
        match=r"drive: .*BeltDrive\.fmu: mapping field 'belt_speed' names variable "
        r"'conveyor_speed', which the FMU lacks",
    ):
        _check(cell, builtin_meshes)


def test_an_fmu_parameter_it_lacks_is_refused_up_front(
    tmp_path: Path, builtin_meshes: Path, built_fmus: tuple[Path, Path]
) -> None:
    cell = _cell(tmp_path, _drive(built_fmus[0], parameters={"belt_mass_kgg": 3.0}))
    with pytest.raises(ConfigError, match=r"parameter 'belt_mass_kgg' is not a variable"):
        _check(cell, builtin_meshes)


def test_the_same_third_party_drive_with_good_names_passes(
    tmp_path: Path, builtin_meshes: Path, built_fmus: tuple[Path, Path]
) -> None:
    cell = _cell(tmp_path, _drive(built_fmus[1]))  # our FMI 2.0 build, as a path
    assert check_scenario(Scenario(), builtin_meshes, where="s.yaml", cell=load_cell(cell))


def test_an_unreadable_urdf_is_refused_up_front(tmp_path: Path, builtin_meshes: Path) -> None:
    urdf = tmp_path / "robot.urdf"
    urdf.write_text("<robot name='x'><link", encoding="utf-8")
    cell = _cell(tmp_path, _robot(urdf=str(urdf)))
    with pytest.raises(
        ConfigError,
        match=r"s\.yaml: the cell .*: stations\[0\] \(panda\): .*robot\.urdf: cannot read the "
        r"robot's URDF",
    ):
        _check(cell, builtin_meshes)


def test_a_missing_urdf_or_joint_is_refused_up_front(tmp_path: Path, builtin_meshes: Path) -> None:
    cell = _cell(tmp_path, _robot(urdf=str(tmp_path / "none.urdf")))
    with pytest.raises(ConfigError, match=r"none\.urdf'?: neither a file nor a file under"):
        _check(cell, builtin_meshes)
    joints = [f"panda_joint{i}" for i in range(1, 7)] + ["elbow"]
    cell = _cell(tmp_path, _robot(arm_joints=joints))
    with pytest.raises(ConfigError, match=r"panda\.urdf: no joint named 'elbow'"):
        _check(cell, builtin_meshes)


def test_a_pick_window_out_of_reach_is_refused(tmp_path: Path, builtin_meshes: Path) -> None:
    def edit(data: dict[str, Any]) -> None:
        station = data["stations"][0]
        station["base_position_m"] = [0.0, -1.5, 0.0]  # 2 m from the belt's centreline
        for b in station["bins"]:
            b["centre_y_m"] = -1.0

    cell = _cell(tmp_path, edit)
    with pytest.raises(
        ConfigError,
        match=r"stations\[0\]\.pick_window_x_m = \[-0\.35, 0\.35\]: the belt's centreline at "
        r"x = -0\.35 m is 2\.\d+ m from the robot's first joint, beyond the reach of panda "
        r"with panda_hand \(at most 1\.09\d m\)",
    ):
        _check(cell, builtin_meshes)


@pytest.mark.parametrize("name", ["default", "two_pandas", "line", "suction", "wide_gripper"])
def test_every_shipped_cell_is_within_reach(name: str, builtin_meshes: Path) -> None:
    cell = load_cell(name)
    check_scenario(Scenario(), builtin_meshes, where="s.yaml", cell=cell)
