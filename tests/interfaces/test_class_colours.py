"""Class colours: fixed for the CDW classes, stable for any other name, a dataset's own kept."""

from __future__ import annotations

from pathlib import Path

from interfaces.class_colours import CLASS_RGB, class_rgb, dataset_class_rgb, rgb_hex
from meshgen.classes import DEFAULT_CLASSES


def test_meshgen_writes_the_same_colours_the_viewers_draw() -> None:
    assert {name: spec.rgb for name, spec in DEFAULT_CLASSES.items()} == CLASS_RGB


def test_an_unknown_class_gets_a_stable_colour_of_its_own() -> None:
    gypsum = class_rgb("gypsum")
    assert gypsum == class_rgb("gypsum")
    assert gypsum != class_rgb("glass")
    assert all(0.0 <= c <= 1.0 for c in gypsum)
    assert gypsum not in CLASS_RGB.values()


def test_overrides_come_first_and_hex_is_html() -> None:
    assert class_rgb("brick", {"brick": (0.0, 0.0, 1.0)}) == (0.0, 0.0, 1.0)
    assert rgb_hex((1.0, 0.5, 0.0)) == "#ff8000"


def test_a_datasets_materials_file_is_read_and_bad_lines_ignored(tmp_path: Path) -> None:
    (tmp_path / "materials.mtl").write_text(
        "# x\nnewmtl gypsum\nKd 0.9 0.9 0.8\nnewmtl brick\nKd red 0 0\nKd 0.5 0.2 0.1\n",
        encoding="utf-8",
    )
    assert dataset_class_rgb(tmp_path) == {"gypsum": (0.9, 0.9, 0.8), "brick": (0.5, 0.2, 0.1)}
    assert dataset_class_rgb(tmp_path / "missing") == {}
