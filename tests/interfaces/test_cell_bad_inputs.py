"""Impossible cells are refused when the cell file is loaded: one line naming the file, the key
and the value (cut), whatever part of the cell is wrong."""

from __future__ import annotations

import copy
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from interfaces.catalog import _catalog
from interfaces.cell import DEFAULT_CELL, CellError, load_cell

Edit = Callable[[dict[str, Any]], None]


def _default() -> dict[str, Any]:
    data = yaml.safe_load(DEFAULT_CELL.read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data


def _station(data: dict[str, Any], i: int = 0) -> dict[str, Any]:
    station = data["stations"][i]
    assert isinstance(station, dict)
    return station


def _set(*path: str | int, value: object) -> Edit:
    def edit(data: dict[str, Any]) -> None:
        node: Any = data
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value

    return edit


def _second_station(**changes: object) -> Edit:
    def edit(data: dict[str, Any]) -> None:
        other = copy.deepcopy(_station(data))
        other.update(name="second", namespace="s2", bins=[])
        other.update(changes)
        data["stations"].append(other)

    return edit


def _second_bin(data: dict[str, Any]) -> None:
    bins = _station(data)["bins"]
    bins.append({**bins[0], "class_name": "glass"})


def _robot_in_full_without(key: str) -> Edit:
    def edit(data: dict[str, Any]) -> None:
        robot = {"name": "panda", **_catalog()["robots"]["panda"]}
        robot.pop(key, None)
        _station(data)["robot"] = robot

    return edit


def _tool_in_full_without_name(data: dict[str, Any]) -> None:
    _station(data)["tool"] = dict(_catalog()["tools"]["panda_hand"])


CASES: list[tuple[str, Edit, str]] = [
    ("gravity up", _set("physics", "gravity_mps2", value=-9.81),
     r"physics\.gravity_mps2 = -9\.81: must be in \(0, 100\] m/s\^2.*points down"),
    ("window beyond the belt's end", _set("stations", 0, "pick_window_x_m", value=[2.0, 2.7]),
     r"stations\[0\]\.pick_window_x_m = \(2\.0, 2\.7\): must lie on the belt"),
    ("window upstream of the infeed", _set("stations", 0, "pick_window_x_m", value=[-2.1, -2.0]),
     r"stations\[0\]\.pick_window_x_m .*downstream of its infeed"),
    ("two stations on one base and window", _second_station(),
     r"stations\[1\]\.base_position_m = .*0 m from the base of stations\[0\] \(panda\)"),
    ("two bins at one spot", _second_bin,
     r"stations\[0\]\.bins\[glass\] = \(-0\.6, 0\.07\): overlaps stations\[0\]\.bins\[0\]"),
    ("a bin over the belt", _set("stations", 0, "bins", 0, "centre_y_m", value=0.15),
     r"stations\[0\]\.bins\[0\] = \(-0\.6, 0\.15\): its 0\.24 m square reaches over the belt"),
    ("a bin below the floor", _set("stations", 0, "bins", 0, "floor_z_m", value=-0.9),
     r"stations\[0\]\.bins\[0\]\.floor_z_m = -0\.9: lies below the floor"),
    ("a drop below the bin's top", _set("stations", 0, "bins", 0, "drop_z_m", value=-0.2),
     r"stations\[0\]\.bins\[0\]: bins\[slot\]\.drop_z_m = -0\.2: must be above the bin's top"),
    ("a floor above the belt", _set("physics", "floor_z_m", value=0.5),
     r"physics\.floor_z_m = 0\.5: must lie below the belt"),
    ("a camera beside the belt", _set("camera", "fov_min_x_m", value=5.0),
     r"camera\.fov_max_x_m = 0\.45: must exceed fov_min_x_m"),
    ("a camera that sees none of it",
     _set("camera", value={"fov_min_x_m": 5.0, "fov_max_x_m": 6.0}),
     r"camera\.fov_min_x_m = \[5\.0, 6\.0\]: the camera sees none of the belt"),
    ("a negative belt width", _set("belt", "width_m", value=-0.6),
     r"belt\.width_m = -0\.6: must be in \(0, 5\] m"),
    ("an infinite belt end", _set("belt", "end_x_m", value=float("inf")),
     r"belt\.end_x_m = inf: must be finite"),
    ("a NaN friction", _set("belt", "lateral_friction", value=float("nan")),
     r"belt\.lateral_friction = nan: must be finite"),
    ("a far base", _set("stations", 0, "base_position_m", value=[1e9, 0.0, 0.0]),
     r"base_position_m = \(1000000000\.0, 0\.0, 0\.0\): must be finite, within"),
    ("no solver iterations", _set("physics", "solver_iterations", value=0),
     r"physics\.solver_iterations = 0: must be in \[1, 1000\]"),
    ("a robot written out without name", _robot_in_full_without("name"),
     r"stations\[0\]\.robot: missing 'name' \(a robot written out in full needs name, urdf"),
    ("a robot written out without urdf", _robot_in_full_without("urdf"),
     r"stations\[0\]\.robot: missing 'urdf'"),
    ("a tool written out without name", _tool_in_full_without_name,
     r"stations\[0\]\.tool: missing 'name' \(a tool written out in full needs name, tcp_link"),
    ("a robot name that is a path", _set(
        "stations", 0, "robot", value={**_catalog()["robots"]["panda"], "name": "../x"}),
     r"robot\.name = '\.\./x': 1 to 64 letters"),
    ("a vacuum beyond the atmosphere", _set(
        "stations", 0, "tool", value={**_catalog()["tools"]["suction_cup"], "name": "cup",
                                      "vacuum_kPa": 200.0}),
     r"tool\.vacuum_kPa = 200\.0: must be in \(0, 101\.325\]"),
    ("a home pose beyond the joint limits", _set(
        "stations", 0, "robot", value={**_catalog()["robots"]["panda"], "name": "panda",
                                       "home_joint_positions": [0.0, -0.35, 0.0, -2.3, 0.0,
                                                                1.95, 7.0]}),
     r"robot\.home_joint_positions\[6\] = 7\.0: outside the joint's position limits"),
    ("no stations", _set("stations", value=[]),
     r"stations = \[\]: list at least one station"),
]  # fmt: skip


@pytest.mark.parametrize(("name", "edit", "pattern"), CASES, ids=[c[0] for c in CASES])
def test_an_impossible_cell_is_refused_naming_file_key_and_value(
    tmp_path: Path, name: str, edit: Edit, pattern: str
) -> None:
    data = _default()
    edit(data)
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    with pytest.raises(CellError, match=re.escape(str(path)) + ": .*" + pattern) as info:
        load_cell(path)
    assert "\n" not in str(info.value), name


def test_the_unedited_copy_loads(tmp_path: Path) -> None:
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(_default()), encoding="utf-8")
    assert load_cell(path).stations[0].name == "panda"


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("", r"the cell file is empty"),
        ("# nothing\n", r"the cell file is empty"),
        ("name: a\x00\n", r"cell file holds a NUL character"),
    ],
    ids=["empty", "comment only", "NUL"],
)
def test_an_empty_or_binary_cell_file_is_refused(tmp_path: Path, text: str, pattern: str) -> None:
    path = tmp_path / "cell.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(CellError, match=re.escape(str(path)) + ".*" + pattern):
        load_cell(path)


def test_an_alias_bomb_under_stations_is_one_short_line(tmp_path: Path) -> None:
    lol = '["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]'
    lines = [f"a0: &a0 {lol}"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 9)]
    path = tmp_path / "bomb.yaml"
    path.write_text("\n".join([*lines, "stations: [*a8]"]) + "\n", encoding="utf-8")
    with pytest.raises(CellError) as info:
        load_cell(path)
    assert len(str(info.value)) < 300
    # a smaller one passes the node bound: its structure is never printed whole
    small = tmp_path / "small.yaml"
    small.write_text("\n".join([*lines[:4], "stations: [*a3]"]) + "\n", encoding="utf-8")
    with pytest.raises(CellError, match=r"small\.yaml: stations\[0\] = \[\[\[") as info:
        load_cell(small)
    assert len(str(info.value)) < 300
