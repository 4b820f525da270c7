"""The cell description: shipped cells load, round-trip, and bad files name file and key."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import pytest

from interfaces.cell import CELLS_DIR, CellError, default_cell, load_cell, resolve_cell_path
from interfaces.contract import JOINT_STATES, TOPICS, resolved_topics
from interfaces.errors import ConfigError

STATION = """\
  - name: {name}
    namespace: {ns}
    robot: {robot}
    tool: panda_hand
    base_position_m: [{x}, 0.0, 0.0]
    pick_window_x_m: [{lo}, {hi}]
    bins:
      - {{class_name: wood, centre_x_m: {x}, centre_y_m: 0.07}}
"""


def _cell(tmp_path: Path, stations: str, head: str = "name: t\n") -> Path:
    path = tmp_path / "cell.yaml"
    path.write_text(f"{head}stations:\n{stations}", encoding="utf-8")
    return path


def _station(**kw: object) -> str:
    values = {"name": "a", "ns": '""', "robot": "panda", "x": 0.0, "lo": -0.35, "hi": 0.35}
    values.update(kw)
    return STATION.format(**values)


@pytest.mark.parametrize("path", sorted(CELLS_DIR.glob("*.yaml")), ids=lambda p: p.stem)
def test_every_shipped_cell_loads_and_round_trips(path: Path, tmp_path: Path) -> None:
    cell = load_cell(path)
    copy = tmp_path / "copy.yaml"
    cell.save(copy)
    again = load_cell(copy)
    assert again.stations == cell.stations
    assert again.belt == cell.belt
    assert again.drive == cell.drive
    assert again.classes == cell.classes


def test_the_default_cell_is_the_reference_cell() -> None:
    cell = default_cell()
    (station,) = cell.stations
    assert station.namespace == ""
    assert station.robot.name == "panda"
    assert station.tool.max_opening_m == 0.08
    assert station.pick_window_x_m == (-0.35, 0.35)
    assert [(b.class_name, b.centre_x_m, b.centre_y_m) for b in station.bins] == [
        ("concrete", -0.60, 0.07),
        ("brick", -0.33, 0.07),
        ("wood", 0.33, 0.07),
        ("rubber", 0.60, 0.07),
    ]
    assert cell.drive.builtin
    assert resolve_cell_path(None) == resolve_cell_path("default")


@pytest.mark.parametrize(
    ("name", "tool"),
    [("suction", "suction_cup"), ("suction_ur10", "suction_cup"), ("wide_gripper", "wide_gripper")],
)
def test_each_tool_has_a_shipped_cell_of_one_station_that_sorts_every_class(
    name: str, tool: str
) -> None:
    """The reference cell's layout with the tool on the flange: one station, one bin per
    class of the reference cell."""
    cell = load_cell(name)
    (station,) = cell.stations
    assert station.tool.name == tool
    assert station.tool.mount == "flange"
    assert cell.classes == default_cell().classes
    assert cell.belt == default_cell().belt


def test_the_shipped_line_lists_its_stations_upstream_first_in_view_of_the_camera() -> None:
    """Several stations along one belt, upstream first (a sweep's ``stations: k`` runs the
    first k), windows and bins apart, each sorting every class, every window seen by the
    camera and on the belt downstream of the infeed."""
    cell = load_cell("line")
    assert len(cell.stations) >= 2
    windows = [s.pick_window_x_m for s in cell.stations]
    assert all(a[1] < b[0] for a, b in itertools.pairwise(windows))
    assert cell.camera.fov_min_x_m < windows[0][0]
    assert cell.camera.fov_max_x_m >= windows[-1][1]
    assert cell.belt.infeed_x_m < cell.camera.fov_min_x_m
    assert windows[-1][1] < cell.belt.end_x_m
    for station in cell.stations:
        assert {b.class_name for b in station.bins} == set(default_cell().classes)
        assert station.namespace


def test_an_unknown_robot_names_the_file_the_station_and_the_catalogue(tmp_path: Path) -> None:
    path = _cell(tmp_path, _station(robot="ur99"))
    with pytest.raises(ConfigError, match=r"stations\[0\]\.robot: unknown robot 'ur99'.*panda"):
        load_cell(path)


@pytest.mark.parametrize(
    ("stations", "pattern"),
    [
        (_station() + _station(name="b", x=-1.5, lo=-1.85, hi=-1.15), "namespaces must differ"),
        (_station() + _station(ns="s2", x=-1.5, lo=-1.85, hi=-1.15), "names must differ"),
        (_station(lo=0.5, hi=0.1), r"pick_window_x_m.*needs min < max"),
        (_station(ns="a/b"), r"namespace.*without slashes"),
    ],
    ids=["shared namespace", "shared name", "window", "namespace"],
)
def test_an_inconsistent_cell_is_refused_naming_the_file(
    tmp_path: Path, stations: str, pattern: str
) -> None:
    path = _cell(tmp_path, stations)
    with pytest.raises(CellError, match=re.escape(str(path)) + ".*" + pattern):
        load_cell(path)


def test_a_bin_standing_on_the_belt_is_refused(tmp_path: Path) -> None:
    text = _station().replace("centre_y_m: 0.07", "centre_y_m: 0.5")
    with pytest.raises(CellError, match=r"bins\[wood\].*stands on the belt"):
        load_cell(_cell(tmp_path, text))


def test_a_duplicate_key_is_refused_with_its_line(tmp_path: Path) -> None:
    path = _cell(tmp_path, _station(), head="name: t\nname: u\n")
    with pytest.raises(ConfigError, match=re.escape(str(path)) + r":2: duplicate key 'name'"):
        load_cell(path)


def test_a_relative_fmu_path_is_resolved_against_the_cell_file(tmp_path: Path) -> None:
    path = _cell(tmp_path, _station(), head="name: t\ndrive: {fmu: drives/belt.fmu}\n")
    assert load_cell(path).drive.fmu == str(tmp_path / "drives" / "belt.fmu")


def test_an_unknown_shipped_name_lists_the_shipped_cells() -> None:
    with pytest.raises(CellError, match=r"no shipped cell of that name \(shipped: .*default"):
        resolve_cell_path("nowhere")


def test_station_topics_take_the_namespace_and_cell_topics_do_not() -> None:
    assert JOINT_STATES.resolve("") == "/joint_states"
    assert JOINT_STATES.resolve("s1") == "/s1/joint_states"
    names = [name for name, _ in resolved_topics(("s1", "s2"))]
    assert len(names) == len(set(names))
    station_topics = [t for t in TOPICS if t.scope == "station"]
    assert len(names) == len(TOPICS) + len(station_topics)
    assert "/clock" in names
    assert "/s2/lockstep/ack" in names
