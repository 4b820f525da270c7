"""check_scenario: a scenario is checked against its dataset and cell before anything starts.

The dataset is a real meshgen output of three images: ``a`` (a concrete and a wood box), ``b``
(a brick box) and ``c`` (no object). It has no rubber, so the default physics tables (which name
rubber) also show that values left at their defaults are exempt from the class-name rule.
Cell files written next to the scenario show the cell's rules.
"""

from __future__ import annotations

import argparse
import re
import shutil
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import write_yolo
from twin_helpers import M_PER_PX, box_px

from interfaces.cell import CELLS_DIR, default_cell
from meshgen.outdir import MARKER_NAME as MESHGEN_MARKER
from meshgen.outdir import marker_text
from twin.errors import ConfigError
from twin.scenario import Scenario
from twin.scenario_check import Selection, check_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "experiments" / "scenarios"

# One case per rule: scenario YAML, and the pattern the ConfigError matches after "<file>: ".
RULES = [
    pytest.param(
        "cell: two_pandaz",
        r"cell = 'two_pandaz': no shipped cell of that name \(shipped: "
        + re.escape(", ".join(sorted(p.stem for p in CELLS_DIR.glob("*.yaml"))))
        + r"\)",
        id="cell_name",
    ),
    pytest.param(
        "cell: cells/missing.yaml",
        r"cell = '.*cells/missing\.yaml': .*cells/missing\.yaml: cannot read cell file",
        id="cell_file",
    ),
    pytest.param(
        "objects: {classes: [concrete, rubbr]}",
        r"objects\.classes\[1\] = 'rubbr': names a class the dataset lacks "
        r"\(its classes: 'brick', 'concrete', 'wood'\)",
        id="classes",
    ),
    pytest.param(
        "objects: {height_ranges_m: {wood: [0.02, 0.05], rubber: [0.01, 0.02]}}",
        r"objects\.height_ranges_m = 'rubber': key names a class the dataset lacks",
        id="height_ranges",
    ),
    pytest.param(
        "physics: {friction: {concrete: [0.6, 0.8], gypsum: [0.5, 0.6]}}",
        r"physics\.friction = 'gypsum': key names a class the dataset lacks",
        id="friction",
    ),
    pytest.param(
        "physics: {restitution: {Wood: [0.1, 0.2]}}",
        r"physics\.restitution = 'Wood': key names a class the dataset lacks",
        id="restitution",
    ),
    pytest.param(
        "objects: {images: [a, nope, c]}",
        r"objects\.images = \['a', 'nope', 'c'\]: 'nope', 'c' match no image with objects in the "
        r"dataset \(2 images: 'a', 'b'\)",
        id="images",
    ),
    pytest.param(
        "objects: {images: [b], classes: [concrete, wood]}",
        r"objects\.classes = \['concrete', 'wood'\]: leaves no object: the 1 objects it filters "
        r"have classes \['brick'\]",
        id="filter_classes",
    ),
    pytest.param(
        "objects: {max_width_m: 0.02}",
        r"objects\.max_width_m = 0\.02: leaves no object: the narrowest of the 3 objects the "
        r"filters before it keep is 0\.036 m across",
        id="filter_width",
    ),
    pytest.param(
        "objects: {classes: [brick, wood], min_height_m: 0.09}",
        r"objects\.min_height_m = 0\.09: leaves no object: the tallest of the 2 objects the "
        r"filters before it keep is 0\.0\d+ m tall",
        id="filter_height",
    ),
    pytest.param(
        "system: {prefill_m: 3.5}",
        r"system\.prefill_m = 3\.5: must be at most 3\.1 m, the belt's run from the infeed to its "
        r"end",
        id="prefill",
    ),
    pytest.param(
        "duration_s: 10\nfaults: {detection_dropout: [[5, 12]]}",
        r"faults\.detection_dropout\[0\] = \[5\.0, 12\.0\]: must lie within the episode, "
        r"\[0, 10\] s \(duration_s\)",
        id="dropout",
    ),
    pytest.param(
        "duration_s: 10\nfaults: {belt_stall: [[1, 2], [11, 12]]}",
        r"faults\.belt_stall\[1\] = \[11\.0, 12\.0\]: must lie within the episode",
        id="stall",
    ),
    pytest.param(
        "duration_s: 10\nfaults: {controller_restart_at_s: [4, 10.5]}",
        r"faults\.controller_restart_at_s\[1\] = 10\.5: must lie within the episode",
        id="restart",
    ),
    pytest.param(
        "duration_s: 10\nsystem: {speed_schedule: [[2, 0.3], [20, 0.2]]}",
        r"system\.speed_schedule\[1\] = \[20\.0, 0\.2\]: must lie within the episode",
        id="schedule",
    ),
]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Meshgen output of images a (concrete 0.12 x 0.06 m, wood 0.09 x 0.036 m), b (brick
    0.072 x 0.048 m) and c (empty)."""
    from meshgen.config import MeshgenConfig
    from meshgen.pipeline import mesh_dataset

    root = tmp_path_factory.mktemp("check")
    labels = {
        "a": [(0, box_px(300, 300, 200, 100)), (2, box_px(700, 700, 150, 60))],
        "b": [(1, box_px(500, 500, 120, 80))],
        "c": [],
    }
    data = write_yolo(root / "data", labels)
    out = root / "meshes"
    mesh_dataset(data, out, MeshgenConfig(image_size_px=(1000, 1000), seed=0))
    return out


def _scenario(tmp_path: Path, text: str) -> tuple[Scenario, str]:
    path = tmp_path / "scenario.yaml"
    path.write_text(text + "\n", encoding="utf-8")
    return Scenario.load(path), str(path)


def _refused(tmp_path: Path, dataset: Path, text: str, pattern: str) -> str:
    scenario, where = _scenario(tmp_path, text)
    with pytest.raises(ConfigError, match=re.escape(where) + ": " + pattern) as info:
        check_scenario(scenario, dataset, where=where)
    message = str(info.value)
    assert "\n" not in message
    return message


@pytest.mark.parametrize(("text", "pattern"), RULES)
def test_each_rule_refuses_with_the_file_and_key(
    tmp_path: Path, dataset: Path, text: str, pattern: str
) -> None:
    _refused(tmp_path, dataset, text, pattern)


def test_defaults_pass_and_the_selection_is_summarised(tmp_path: Path, dataset: Path) -> None:
    scenario, where = _scenario(tmp_path, "name: ok")
    selection = check_scenario(scenario, dataset, where=where)
    assert selection == Selection(
        classes=("brick", "concrete", "wood"),
        images=("a", "b"),
        objects=3,
        entering=("brick", "concrete", "wood"),
    )


def test_the_filters_keep_what_the_stream_would(tmp_path: Path, dataset: Path) -> None:
    """Width is the narrow side; a re-sampled height counts as its range's top."""
    text = (
        "objects:\n"
        "  images: [a, b]\n"
        "  classes: [concrete, wood, brick]\n"
        f"  max_width_m: {60 * M_PER_PX:.4f}\n"
        "  resample_heights: true\n"
        "  height_ranges_m: {wood: [0.2, 0.3]}\n"
        "  min_height_m: 0.15\n"
        "physics: {friction: {wood: [0.3, 0.4]}, restitution: {brick: [0.1, 0.2]}}\n"
        "system: {prefill_m: 3.1, speed_schedule: [[10, 0.2]]}\n"
        "duration_s: 10\n"
        "faults: {belt_stall: [[0, 10]], controller_restart_at_s: [10]}"
    )
    scenario, where = _scenario(tmp_path, text)
    selection = check_scenario(scenario, dataset, where=where)
    assert selection.images == ("a",)
    assert selection.objects == 1


def test_prefill_bound_follows_the_cell(tmp_path: Path, dataset: Path) -> None:
    scenario, where = _scenario(tmp_path, "system: {prefill_m: 3.5}")
    cell = default_cell()
    long_belt = replace(cell, belt=replace(cell.belt, end_x_m=2.0))
    assert check_scenario(scenario, dataset, where=where, cell=long_belt).objects == 3


MINI_CELL = """\
name: mini
stations:
  - name: only
    robot: panda
    tool: panda_hand
    bins:
      - {class_name: concrete, centre_x_m: -0.6, centre_y_m: 0.07}
      - {class_name: wood, centre_x_m: 0.33, centre_y_m: 0.07}
"""

# One case per rule of the cell: cell file (next to the scenario), scenario, pattern.
CELL_RULES = [
    pytest.param(
        MINI_CELL,
        "cell: mini.yaml",
        r"class 'brick' can enter the belt but no station of the cell .*mini\.yaml has a bin "
        r"for it \(its bins sort: 'concrete', 'wood'\)",
        id="class_without_bin",
    ),
    pytest.param(
        MINI_CELL + "drive: {perturbation: null}\n",
        "cell: mini.yaml\nobjects: {classes: [concrete, wood]}\n"
        "system: {perturbation: {enabled: true}}",
        r"system\.perturbation\.enabled = True: the belt drive of the cell .*mini\.yaml "
        r"\(builtin\) has no perturbation mapping",
        id="perturbation_without_mapping",
    ),
    pytest.param(
        MINI_CELL + "drive: {fmu: nowhere.fmu, perturbation: null}\n",
        "cell: mini.yaml\nobjects: {classes: [concrete, wood]}",
        r"the cell .*mini\.yaml: drive\.fmu = '.*nowhere\.fmu': no such file",
        id="missing_fmu",
    ),
]


@pytest.mark.parametrize(("cell_text", "text", "pattern"), CELL_RULES)
def test_each_cell_rule_refuses_with_the_scenario_and_the_cell_file(
    tmp_path: Path, dataset: Path, cell_text: str, text: str, pattern: str
) -> None:
    (tmp_path / "mini.yaml").write_text(cell_text, encoding="utf-8")
    message = _refused(tmp_path, dataset, text, pattern)
    assert str(tmp_path / "mini.yaml") in message or "nowhere" in message


def test_classes_the_filters_keep_out_need_no_bin(tmp_path: Path, dataset: Path) -> None:
    """A class the cell has no bin for passes when ``objects.classes`` keeps it off the belt;
    the cell path is relative to the scenario file, wherever the check runs from."""
    (tmp_path / "mini.yaml").write_text(MINI_CELL, encoding="utf-8")
    scenario, where = _scenario(tmp_path, "cell: mini.yaml\nobjects: {classes: [wood]}")
    assert scenario.cell == str(tmp_path / "mini.yaml")
    selection = check_scenario(scenario, dataset, where=where)
    assert selection.entering == ("wood",)


def test_a_scenario_no_longer_chooses_the_robot(tmp_path: Path) -> None:
    """The cell chooses robots: ``robot:`` in a scenario is an unknown key."""
    path = tmp_path / "scenario.yaml"
    path.write_text("robot: xarm6\n", encoding="utf-8")
    with pytest.raises(
        ConfigError, match=r"scenario\.yaml: unknown key 'robot' \(allowed: bins, cell,"
    ):
        Scenario.load(path)


@pytest.mark.parametrize("path", ["missing", "file.txt"])
def test_dataset_that_is_no_folder_is_named(tmp_path: Path, dataset: Path, path: str) -> None:
    (tmp_path / "file.txt").write_text("x", encoding="utf-8")
    target = tmp_path / path
    scenario, where = _scenario(tmp_path, "name: ok")
    what = "no such folder" if path == "missing" else "not a folder"
    with pytest.raises(ConfigError, match=rf": dataset = '{re.escape(str(target))}': {what}"):
        check_scenario(scenario, target, where=where)


def test_folder_without_index_is_not_a_meshgen_output(tmp_path: Path) -> None:
    empty = tmp_path / "images"
    empty.mkdir()
    scenario, where = _scenario(tmp_path, "name: ok")
    with pytest.raises(ConfigError, match=r"images': no index\.csv: not a meshgen output folder"):
        check_scenario(scenario, empty, where=where)


def test_marker_or_meshgen_header_makes_a_meshgen_output(tmp_path: Path, dataset: Path) -> None:
    copy = tmp_path / "copy"
    shutil.copytree(dataset, copy)
    (copy / MESHGEN_MARKER).unlink(missing_ok=True)
    scenario, where = _scenario(tmp_path, "name: ok")
    assert check_scenario(scenario, copy, where=where).objects == 3
    index = copy / "index.csv"
    lines = index.read_text(encoding="utf-8").splitlines()
    foreign = [",".join(line.split(",")[i] for i in (0, 1, 2, 3, 6)) for line in lines]
    index.write_text("\n".join(foreign) + "\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=rf"neither a {MESHGEN_MARKER} marker nor meshgen's"):
        check_scenario(scenario, copy, where=where)
    (copy / MESHGEN_MARKER).write_text(marker_text(), encoding="utf-8")
    assert check_scenario(scenario, copy, where=where).objects == 3


def test_malformed_dataset_is_named_with_file_and_line(tmp_path: Path, dataset: Path) -> None:
    copy = tmp_path / "copy"
    shutil.copytree(dataset, copy)
    scene = copy / "b" / "scene.csv"
    scene.write_text(scene.read_text(encoding="utf-8").replace("brick", "b r i c k"), "utf-8")
    scenario, where = _scenario(tmp_path, "name: ok")
    with pytest.raises(
        ConfigError, match=r"dataset = '.*copy': .*b/scene\.csv:2: field 'class_name'"
    ):
        check_scenario(scenario, copy, where=where)
    (copy / "classes.yaml").unlink()  # an output of before classes.yaml: its summary.json
    (copy / "summary.json").unlink()
    with pytest.raises(ConfigError, match=r"summary\.json: no such file"):
        check_scenario(scenario, copy, where=where)


def test_shipped_scenarios_pass_on_the_builtin_sample(builtin_meshes: Path) -> None:
    paths = sorted(SCENARIOS.glob("*.yaml"))
    assert len(paths) >= 10
    for path in paths:
        selection = check_scenario(Scenario.load(path), builtin_meshes, where=str(path))
        assert selection.objects > 0, path


def _build_args(scenario: Path, dataset: Path) -> argparse.Namespace:
    from twin.cmd_node import configure

    parser = argparse.ArgumentParser()
    configure(parser)
    return parser.parse_args(["--scenario", str(scenario), "--dataset", str(dataset)])


@pytest.mark.parametrize(("text", "pattern"), RULES)
def test_build_scenario_refuses_before_anything_starts(
    tmp_path: Path, dataset: Path, text: str, pattern: str
) -> None:
    """The entry point of ``cdw-twin run``, ``sweep`` and ``twin-node`` runs the check."""
    from twin.cmd_node import build_scenario

    path = tmp_path / "scenario.yaml"
    path.write_text(text + "\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=re.escape(str(path)) + ": " + pattern):
        build_scenario(_build_args(path, dataset))
