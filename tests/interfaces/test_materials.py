"""The class table: the shipped file, a dataset's table over it, the default for any other
class, the table a meshgen output records (and an older output's), and the cell's copy."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from interfaces.cell import default_cell, load_cell
from interfaces.materials import (
    MaterialsError,
    dataset_table,
    load_table,
    name_rgb,
    shipped_table,
    table_from_data,
    user_table,
)


def test_the_shipped_table_holds_every_class_fact_once() -> None:
    table = shipped_table()
    assert table.names == ("concrete", "brick", "wood", "rubber")
    concrete = table.material("concrete")
    assert (concrete.density_kg_m3, concrete.height_min_m, concrete.height_max_m) == (
        2400.0,
        0.03,
        0.10,
    )
    assert (concrete.friction, concrete.restitution) == ((0.6, 0.8), (0.05, 0.15))
    assert [table.material(n).seal_efficiency for n in table.names] == [0.45, 0.45, 0.6, 0.9]
    assert table.material("rubber").rgb == (0.10, 0.10, 0.10)


def test_a_class_the_table_does_not_name_takes_the_default_and_a_colour_of_its_name() -> None:
    table = shipped_table()
    gypsum = table.material("gypsum")
    default = table.default
    assert gypsum.name == "gypsum"
    assert (gypsum.density_kg_m3, gypsum.friction, gypsum.seal_efficiency) == (
        default.density_kg_m3,
        default.friction,
        default.seal_efficiency,
    )
    assert gypsum.colour == name_rgb("gypsum") != name_rgb("glass")


def test_a_datasets_table_overrides_field_by_field_and_keeps_its_order(tmp_path: Path) -> None:
    path = tmp_path / "classes.yaml"
    path.write_text(
        "classes:\n"
        "  tiles: {density_kg_m3: 2000, height_min_m: 0.008, height_max_m: 0.015}\n"
        "  concrete: {seal_efficiency: 0.3}\n"
        "default: {density_kg_m3: 1800}\n",
        encoding="utf-8",
    )
    table = user_table(path)
    assert table.names == ("tiles", "concrete", "brick", "wood", "rubber")
    tiles, concrete = table.material("tiles"), table.material("concrete")
    assert (tiles.density_kg_m3, tiles.height_max_m) == (2000.0, 0.015)
    assert tiles.friction == shipped_table().default.friction  # left out: the default's
    assert concrete.seal_efficiency == 0.3
    assert concrete.density_kg_m3 == 2400.0  # left out: the shipped concrete's
    assert table.default.density_kg_m3 == 1800.0
    assert table.material("glass").density_kg_m3 == 1800.0


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("classes: [1, 2]", "top-level mapping"),
        ("classes:\n  x: {density_kg_m3: -1}", r"classes\.x\.density_kg_m3 = -1\.0: must be > 0"),
        ("classes:\n  x: {friction: [0.8, 0.2]}", r"classes\.x\.friction = \[0\.8, 0\.2\]"),
        ("classes:\n  x: {seal_efficiency: 1.5}", r"classes\.x\.seal_efficiency = 1\.5"),
        ("classes:\n  x: {height_min_m: 0.1}", "missing field 'height_max_m'"),
        ("classes:\n  x: {colour: red}", r"classes\.x: unknown field\(s\) \['colour'\]"),
        ("classes:\n  x: {rgb: [1, 2]}", r"classes\.x\.rgb = \[1, 2\]: expected a list of 3"),
        ("classes: {x: [", "not valid YAML"),
    ],
)
def test_a_bad_table_names_the_file_and_key(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(MaterialsError, match=match) as info:
        user_table(path)
    assert str(path) in str(info.value)


def test_a_complete_table_needs_its_default_in_full(tmp_path: Path) -> None:
    path = tmp_path / "t.yaml"
    path.write_text("classes: {}\ndefault: {density_kg_m3: 1000}\n", encoding="utf-8")
    with pytest.raises(MaterialsError, match=r"default: missing field\(s\) height_min_m"):
        load_table(path)


def test_an_older_meshgen_output_gives_its_classes_from_summary_and_mtl(tmp_path: Path) -> None:
    """An output written before ``classes.yaml``: the classes of its ``summary.json`` in
    ``materials.mtl``'s order with its colours, the other facts the shipped table's."""
    config = {
        "classes": {
            "brick": {"density_kg_m3": 1000.0, "height_min_m": 0.02, "height_max_m": 0.03},
            "gypsum": {"density_kg_m3": 900.0, "height_min_m": 0.01, "height_max_m": 0.02},
        }
    }
    (tmp_path / "summary.json").write_text(json.dumps({"config": config}), encoding="utf-8")
    (tmp_path / "materials.mtl").write_text(
        "newmtl gypsum\nKd 0.9 0.9 0.8\nnewmtl brick\nKd 0.5 0.2 0.1\n", encoding="utf-8"
    )
    table = dataset_table(tmp_path)
    assert table.names == ("gypsum", "brick")
    brick = table.material("brick")
    assert (brick.density_kg_m3, brick.rgb) == (1000.0, (0.5, 0.2, 0.1))
    assert brick.friction == shipped_table().material("brick").friction
    (tmp_path / "summary.json").unlink()
    with pytest.raises(MaterialsError, match=r"summary\.json: no such file"):
        dataset_table(tmp_path)


def test_a_cell_carries_its_class_table_and_writes_it_out(tmp_path: Path) -> None:
    """A cell file without ``materials:`` has the shipped table; its written (resolved) copy
    carries the table it was resolved with, read back the same."""
    from interfaces.cell import resolve_cell

    assert default_cell().materials == shipped_table()
    table = table_from_data({"classes": {"tiles": {"density_kg_m3": 2000}}}, "t", shipped_table())
    resolved = resolve_cell(default_cell(), table)
    resolved.save(tmp_path / "cell.yaml")
    again = load_cell(tmp_path / "cell.yaml")
    assert again.materials == table
    assert again.classes == ("tiles",)
    assert again.stations[0].bins == resolved.stations[0].bins
