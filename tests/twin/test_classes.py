"""Classes are data: a dataset of ``bricks``, ``concrete`` and ``tiles`` (its own class table)
with a cell file whose bins sort those classes is checked, loaded and scored by their names."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import pytest
from twin_helpers import box_px, tcp_ik

from interfaces.cell import BinSpec, default_cell
from interfaces.events import EventType
from twin.errors import ConfigError
from twin.scenario import Scenario
from twin.scenario_check import check_scenario
from twin.sim import ArmCommand, Twin

CLASS_TABLE = """\
classes:
  bricks:   {density_kg_m3: 1900, height_min_m: 0.05, height_max_m: 0.07}
  concrete: {density_kg_m3: 2400, height_min_m: 0.04, height_max_m: 0.08}
  tiles:    {density_kg_m3: 2000, height_min_m: 0.04, height_max_m: 0.05}
"""
NAMES = ("bricks", "concrete", "tiles")


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Meshgen output of image ``a`` (a tiles box, 60 x 30 mm) and ``b`` (bricks, concrete),
    meshed with the three-class table."""
    from meshgen.classes import load_class_table
    from meshgen.config import MeshgenConfig
    from meshgen.pipeline import mesh_dataset

    root = tmp_path_factory.mktemp("classes")
    table_path = root / "classes.yaml"
    table_path.write_text(CLASS_TABLE, encoding="utf-8")
    data = root / "data"
    (data / "labels").mkdir(parents=True)
    names = "".join(f"  {i}: {name}\n" for i, name in enumerate(NAMES))
    (data / "data.yaml").write_text(f"names:\n{names}", encoding="utf-8")
    labels = {
        "a": [(2, box_px(500, 500, 100, 50))],
        "b": [(0, box_px(300, 300, 150, 90)), (1, box_px(700, 700, 120, 100))],
    }
    for stem, polygons in labels.items():
        lines = [
            f"{cls} " + " ".join(f"{u / 1000:.6f} {v / 1000:.6f}" for u, v in points)
            for cls, points in polygons
        ]
        (data / "labels" / f"{stem}.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")
    out = root / "meshes"
    table = tuple(load_class_table(table_path).values())
    mesh_dataset(data, out, MeshgenConfig(image_size_px=(1000, 1000), seed=0, classes=table))
    return out


@pytest.fixture
def cell_file(tmp_path: Path) -> Path:
    """The reference cell with one bin per class of the dataset."""
    cell = default_cell()
    bins = tuple(
        BinSpec(class_name=name, centre_x_m=x, centre_y_m=0.07)
        for name, x in zip(NAMES, (-0.6, -0.33, 0.33), strict=True)
    )
    path = tmp_path / "cdw3.yaml"
    replace(cell, name="cdw3", stations=(replace(cell.stations[0], bins=bins),)).save(path)
    return path


def _scenario(tmp_path: Path, cell: Path) -> tuple[Scenario, str]:
    path = tmp_path / "scenario.yaml"
    path.write_text(
        f"cell: {cell.name}\n"
        "duration_s: 30\n"
        "system: {belt_speed_mps: 0.0, prefill_m: 1.7, repeat_images: false}\n",
        encoding="utf-8",
    )
    return Scenario.load(path), str(path)


def test_the_default_cell_refuses_classes_it_has_no_bin_for(
    tmp_path: Path, dataset: Path, cell_file: Path
) -> None:
    scenario, where = _scenario(tmp_path, cell_file)
    selection = check_scenario(scenario, dataset, where=where)
    assert selection.entering == NAMES
    default = replace(scenario, cell="default")
    pattern = (
        rf"{re.escape(where)}: class 'bricks' can enter the belt but no station of the cell "
        r".*interfaces/cells/default\.yaml has a bin for it"
    )
    with pytest.raises(ConfigError, match=pattern):
        check_scenario(default, dataset, where=where)


def _hold(twin: Twin, position: tuple[float, float, float], width_m: float, s: float) -> None:
    twin.command(ArmCommand(tcp_ik(twin, position), gripper_width_m=width_m))
    end = twin.time_s + s
    while twin.time_s < end - 1e-9:
        twin.advance()


def test_a_tiles_object_is_picked_and_sorted_into_the_tiles_bin(
    tmp_path: Path, dataset: Path, cell_file: Path
) -> None:
    scenario, _ = _scenario(tmp_path, cell_file)
    with Twin(scenario, dataset_dir=dataset) as twin:
        obs, _ = twin.reset(seed=0)
        assert twin.classes == NAMES  # the camera's labels, in the cell's order
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
