"""The display colour of every waste class: one source for meshes, scene markers, players, pictures.

Colours are facts of the class table (:mod:`interfaces.materials`): the shipped table gives
the four CDW classes theirs (the ones meshgen writes into a dataset's ``materials.mtl`` by
default), a dataset's own table (meshgen ``--classes FILE.yaml`` with ``rgb``) may give any
class another, and a class no table colours gets a stable colour of its own derived from its
name (:func:`interfaces.materials.name_rgb`), the same on every machine and in every run.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from interfaces.materials import (
    MTL_FILE,
    RGB,
    ClassTable,
    MaterialsError,
    dataset_table,
    mtl_classes,
    shipped_table,
)

__all__ = [
    "CLASS_RGB",
    "RGB",
    "class_colour",
    "class_rgb",
    "dataset_class_rgb",
    "dataset_colour",
    "rgb_hex",
]

CLASS_RGB: dict[str, RGB] = {m.name: m.colour for m in shipped_table().classes}
"""The shipped classes' colours (``interfaces/materials.yaml``): grey concrete, brick red,
light-brown wood, near-black rubber."""


def class_rgb(class_name: str, overrides: dict[str, RGB] | None = None) -> RGB:
    """The colour of ``class_name``: ``overrides`` first (a dataset's table,
    :func:`dataset_class_rgb`), then the shipped table's (its default: the colour of the
    name)."""
    if overrides and class_name in overrides:
        return overrides[class_name]
    return shipped_table().material(class_name).colour


def class_colour(table: ClassTable) -> Callable[[str], RGB]:
    """Each class's colour in ``table`` (an episode's: its cell's ``materials``), a class it
    does not name the colour of its default or of its name."""

    def colour(class_name: str) -> RGB:
        return table.material(class_name).colour

    return colour


def dataset_colour(dataset_dir: Path | None) -> Callable[[str], RGB]:
    """Each class's colour in a dataset's class table (``classes.yaml``, or an older output's
    ``summary.json`` and ``materials.mtl``: :func:`interfaces.materials.dataset_table`), the
    shipped table's when there is no dataset or it cannot be read."""
    table = shipped_table()
    if dataset_dir is not None:
        try:
            table = dataset_table(Path(dataset_dir))
        except (MaterialsError, OSError):
            table = shipped_table()
    return class_colour(table)


def rgb_hex(rgb: RGB) -> str:
    """``#rrggbb`` of an RGB triple in [0, 1] (for HTML and SVG)."""
    return "#" + "".join(f"{round(min(max(c, 0.0), 1.0) * 255):02x}" for c in rgb)


def dataset_class_rgb(dataset_dir: Path) -> dict[str, RGB]:
    """Each class's colour as the dataset's class table gives it (``classes.yaml``, or an older
    output's ``materials.mtl``: ``newmtl NAME`` and ``Kd R G B``); ``{}`` when the folder has
    neither: the colour is a display hint, never a reason to refuse a dataset."""
    try:
        table = dataset_table(Path(dataset_dir))
    except (MaterialsError, OSError):
        return dict(mtl_classes(Path(dataset_dir) / MTL_FILE)[1])
    return {m.name: m.colour for m in table.classes}
