"""Material classes: the class table meshgen takes densities, height ranges and colours from.

The table is the shipped one (``interfaces/materials.yaml``, :mod:`interfaces.materials`:
concrete 2400 kg/m^3 and 0.03-0.10 m, brick 1900 and 0.04-0.08, wood 600 and 0.02-0.06, rubber
1200 and 0.005-0.03, with their sources there) unless ``--classes FILE.yaml`` gives a dataset's
own, in the same shape: its classes in its order, every field it leaves out taken from the
shipped entry of that class, else from the shipped default; the shipped classes it does not
name follow it::

    classes:
      concrete: {density_kg_m3: 2400, height_min_m: 0.03, height_max_m: 0.10, rgb: [0.6, 0.6, 0.6]}
      gypsum:   {density_kg_m3: 1000, height_min_m: 0.01, height_max_m: 0.02}

Class names in annotations are matched exactly. A name the table does not name is meshed with
the table's ``default`` entry (its density and height range), with a ``default_material``
warning naming the class, and its ``class_id`` in the outputs is -1. meshgen records the table
it used in the output's ``classes.yaml`` (:data:`interfaces.materials.DATASET_TABLE`): the
classes it meshed pieces of, in the table's order, and the default.
"""

from __future__ import annotations

from pathlib import Path

from interfaces.errors import ConfigError
from interfaces.materials import ClassTable, Material, shipped_table, user_table
from meshgen.errors import ClassTableError

ClassSpec = Material
"""The physical properties of one waste class (:class:`interfaces.materials.Material`)."""

DEFAULT_CLASSES: dict[str, Material] = {m.name: m for m in shipped_table().classes}
"""The shipped classes by name, in the shipped order."""


def load_class_table(path: Path) -> dict[str, Material]:
    """The classes of a dataset's class table file over the shipped one
    (:func:`interfaces.materials.user_table`), by name in order; :class:`ClassTableError`
    naming the file and the key when it is malformed."""
    return {m.name: m for m in load_table_file(path).classes}


def load_table_file(path: Path) -> ClassTable:
    """A dataset's class table file over the shipped one, default included
    (:func:`interfaces.materials.user_table`); :class:`ClassTableError` naming the file and the
    key when it is malformed."""
    try:
        return user_table(path)
    except ConfigError as exc:
        raise ClassTableError(str(exc)) from None


__all__ = ["DEFAULT_CLASSES", "ClassSpec", "ClassTable", "load_class_table", "load_table_file"]
