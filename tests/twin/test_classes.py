"""Classes are data: a dataset of ``bricks``, ``concrete`` and ``tiles`` (its own class table)
runs on the shipped reference cell with no file edited: its bin slots take the dataset's
classes in the class table's order (or as a scenario's ``bins:`` map says), a bin a cell file
fixes to a class keeps it, and a dataset with more classes than a station has bins is refused
naming the station and the counts."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from twin_helpers import box_px, tcp_ik

from interfaces.cell import Cell, default_cell
from interfaces.events import EventType
from twin.errors import ConfigError
from twin.scenario import Scenario
from twin.scenario_check import check_scenario
from twin.sim import ArmCommand, Twin

CLASS_TABLE = """\
classes:
  bricks:   {density_kg_m3: 1900, height_min_m: 0.05, height_max_m: 0.07}
  concrete: {density_kg_m3: 2400, height_min_m: 0.04, height_max_m: 0.08}
  tiles:    {density_kg_m3: 2000, height_min_m: 0.04, height_max_m: 0.05, rgb: [0.2, 0.4, 0.9]}
"""
NAMES = ("bricks", "concrete", "tiles")
SLOTS_X_M = (-0.60, -0.33, 0.33, 0.60)
"""The reference cell's four bin slots along x (interfaces/cells/default.yaml)."""


Labels = dict[str, list[tuple[int, list[tuple[float, float]]]]]


def _mesh(root: Path, names: tuple[str, ...], labels: Labels) -> Path:
    """Mesh YOLO polygons whose data.yaml names ``names``, with :data:`CLASS_TABLE`."""
    from meshgen.classes import load_table_file
    from meshgen.config import MeshgenConfig
    from meshgen.pipeline import mesh_dataset

    table_path = root / "classes.yaml"
    table_path.write_text(CLASS_TABLE, encoding="utf-8")
    data = root / "data"
    (data / "labels").mkdir(parents=True)
    listed = "".join(f"  {i}: {name}\n" for i, name in enumerate(names))
    (data / "data.yaml").write_text(f"names:\n{listed}", encoding="utf-8")
    for stem, polygons in labels.items():
        lines = [
            f"{cls} " + " ".join(f"{u / 1000:.6f} {v / 1000:.6f}" for u, v in points)
            for cls, points in polygons
        ]
        (data / "labels" / f"{stem}.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")
    out = root / "meshes"
    config = MeshgenConfig(image_size_px=(1000, 1000), seed=0, classes=load_table_file(table_path))
    mesh_dataset(data, out, config)
    return out


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Meshgen output of image ``a`` (a tiles box, 60 x 30 mm) and ``b`` (bricks, concrete),
    meshed with the three-class table."""
    labels: Labels = {
        "a": [(2, box_px(500, 500, 100, 50))],
        "b": [(0, box_px(300, 300, 150, 90)), (1, box_px(700, 700, 120, 100))],
    }
    return _mesh(tmp_path_factory.mktemp("classes"), NAMES, labels)


def _scenario(tmp_path: Path, text: str = "") -> tuple[Scenario, str]:
    path = tmp_path / "scenario.yaml"
    path.write_text(
        "duration_s: 30\n"
        "system: {belt_speed_mps: 0.0, prefill_m: 1.7, repeat_images: false}\n" + text,
        encoding="utf-8",
    )
    return Scenario.load(path), str(path)


def _bins(cell: Cell | None) -> list[tuple[str, float]]:
    """The (class, centre x) of the first station's bins of a resolved cell."""
    assert cell is not None
    return [(b.class_name, b.centre_x_m) for b in cell.stations[0].bins]


def test_the_reference_cells_slots_take_the_datasets_classes_in_its_tables_order(
    tmp_path: Path, dataset: Path
) -> None:
    scenario, where = _scenario(tmp_path)  # the default cell: interfaces/cells/default.yaml
    selection = check_scenario(scenario, dataset, where=where)
    assert selection.entering == NAMES
    assert _bins(selection.cell) == list(zip(NAMES, SLOTS_X_M[:3], strict=True))
    assert selection.cell is not None
    assert selection.cell.materials.material("tiles").density_kg_m3 == 2000.0
    # the shipped cell itself, read without a dataset, sorts the shipped classes
    assert default_cell().classes == ("concrete", "brick", "wood", "rubber")


def test_a_bins_map_puts_a_class_into_the_slot_it_names(tmp_path: Path, dataset: Path) -> None:
    scenario, where = _scenario(tmp_path, "bins: {slots: {tiles: 3, concrete: 0}}\n")
    selection = check_scenario(scenario, dataset, where=where)
    assert sorted(_bins(selection.cell)) == [
        ("bricks", SLOTS_X_M[1]),  # the first free slot
        ("concrete", SLOTS_X_M[0]),
        ("tiles", SLOTS_X_M[3]),
    ]


def test_a_bins_map_naming_a_class_the_dataset_lacks_is_refused(
    tmp_path: Path, dataset: Path
) -> None:
    scenario, where = _scenario(tmp_path, "bins: {slots: {glass: 1}}\n")
    with pytest.raises(ConfigError, match=r"bins: class 'glass' is not a class of the dataset"):
        check_scenario(scenario, dataset, where=where)


def test_a_bin_a_cell_file_fixes_keeps_its_class(tmp_path: Path, dataset: Path) -> None:
    """The cell file fixes its first bin to ``tiles``; the other three are slots."""
    text = (Path(default_cell().source)).read_text(encoding="utf-8")
    fixed = text.replace("- {centre_x_m: -0.60,", "- {class_name: tiles, centre_x_m: -0.60,", 1)
    assert fixed != text
    (tmp_path / "fixed.yaml").write_text(fixed, encoding="utf-8")
    scenario, where = _scenario(tmp_path, "cell: fixed.yaml\n")
    selection = check_scenario(scenario, dataset, where=where)
    assert _bins(selection.cell) == [
        ("tiles", SLOTS_X_M[0]),
        ("bricks", SLOTS_X_M[1]),
        ("concrete", SLOTS_X_M[2]),
    ]


def test_more_classes_than_a_station_has_bins_is_one_clear_error(
    tmp_path_factory: pytest.TempPathFactory, tmp_path: Path
) -> None:
    names = ("bricks", "concrete", "tiles", "glass", "gypsum")
    labels: Labels = {"a": [(i, box_px(150 + 170 * i, 500, 100, 60)) for i in range(5)]}
    five = _mesh(tmp_path_factory.mktemp("five"), names, labels)
    scenario, where = _scenario(tmp_path)
    pattern = (
        rf"{re.escape(where)}: the cell .*default\.yaml: stations\[0\] \(panda\): 5 classes to "
        r"sort \(bricks, concrete, tiles, glass, gypsum\) but 4 bin slot\(s\) \(of 4 bins, 0 "
        r"fixed to a class\): 1 class\(es\) without a bin \(gypsum\)"
    )
    with pytest.raises(ConfigError, match=pattern):
        check_scenario(scenario, five, where=where)
    # letting four classes in fits
    scenario, where = _scenario(tmp_path, "objects: {classes: [bricks, glass, tiles, gypsum]}\n")
    selection = check_scenario(scenario, five, where=where)
    assert [name for name, _ in _bins(selection.cell)] == ["bricks", "tiles", "glass", "gypsum"]


def _hold(twin: Twin, position: tuple[float, float, float], width_m: float, s: float) -> None:
    twin.command(ArmCommand(tcp_ik(twin, position), gripper_width_m=width_m))
    end = twin.time_s + s
    while twin.time_s < end - 1e-9:
        twin.advance()


def test_a_tiles_object_is_picked_and_sorted_into_the_tiles_bin(
    tmp_path: Path, dataset: Path
) -> None:
    scenario, _ = _scenario(tmp_path)
    with Twin(scenario, dataset_dir=dataset) as twin:  # the reference cell, resolved
        obs, _ = twin.reset(seed=0)
        assert twin.classes == NAMES  # the camera's labels, in the cell's order
        assert twin.cell.materials.material("tiles").colour == (0.2, 0.4, 0.9)
        assert sorted(o.class_name for o in obs.objects) == sorted(NAMES)
        (tile,) = [o for o in obs.objects if o.class_name == "tiles"]
        x, y, z = tile.position_m
        z += 0.5 * tile.height_m - 0.02
        _hold(twin, (x, y, z + 0.3), 0.08, 2.0)
        _hold(twin, (x, y, z + 0.1), 0.08, 1.0)
        _hold(twin, (x, y, z), 0.08, 1.0)
        _hold(twin, (x, y, z), 0.0, 0.5)
        _hold(twin, (x, y, 0.3), 0.0, 1.0)
        bin_spec = twin.cell.stations[0].bin_for("tiles")
        assert bin_spec is not None
        assert bin_spec.centre_x_m == SLOTS_X_M[2]
        _hold(twin, (bin_spec.centre_x_m, 0.35, 0.3), 0.0, 1.0)
        _hold(twin, (bin_spec.centre_x_m, bin_spec.centre_y_m, 0.2), 0.0, 1.5)
        _hold(twin, (bin_spec.centre_x_m, bin_spec.centre_y_m, 0.2), 0.08, 1.5)
        events = twin.events
        counts = twin.counts()
    assert {e.class_name for e in events if e.type is EventType.SPAWNED} == set(NAMES)
    (pick,) = [e for e in events if e.type is EventType.PICK_SUCCESS]
    (placed,) = [e for e in events if e.type is EventType.PLACED_IN_BIN]
    assert (pick.class_name, pick.object_id) == ("tiles", tile.id)
    assert (placed.class_name, placed.data["bin"], placed.data["correct"]) == (
        "tiles",
        "tiles",
        True,
    )
    assert counts.placed_correct_by_class == {"tiles": 1}
    assert counts.spawned_by_class == dict.fromkeys(NAMES, 1)
