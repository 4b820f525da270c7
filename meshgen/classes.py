"""Material classes: density and height range of every waste class.

Default table (override it with ``--classes FILE.yaml``)::

    class     density kg/m^3   height m       colour
    concrete  2400             0.03 - 0.10    grey
    brick     1900             0.04 - 0.08    brick red
    wood       600             0.02 - 0.06    light brown
    rubber    1200             0.005 - 0.03   near black

Justification and sources:

- concrete: normal-weight concrete is 2200-2500 kg/m^3 (EN 1991-1-1 Annex A, table A.1 gives
  24 kN/m^3 for plain concrete); demolition pieces are slab and screed fragments a few cm thick.
- brick: fired clay brick 1600-2100 kg/m^3 (EN 1991-1-1 table A.1, masonry units); a standard
  brick is 65-71 mm high, broken pieces lie flat, hence 0.04-0.08 m.
- wood: softwood construction timber 450-600 kg/m^3 at 12 % moisture (EN 338 classes C16-C30
  mean densities 370-460, plus moisture and coatings of demolition wood); boards and battens
  are 20-60 mm thick.
- rubber: solid rubber (seals, tyre and mat fragments) 1100-1300 kg/m^3; sheets and seals are
  5-30 mm thick.

The YAML override has the shape::

    classes:
      concrete: {density_kg_m3: 2400, height_min_m: 0.03, height_max_m: 0.10, rgb: [0.6, 0.6, 0.6]}
      gypsum:   {density_kg_m3: 1000, height_min_m: 0.01, height_max_m: 0.02}

Class names in annotations are matched exactly; a name missing from the table is never given a
made-up density: the object is skipped with reason ``unknown_class`` naming the class.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from interfaces.class_colours import CLASS_RGB
from meshgen.errors import ClassTableError


@dataclass(frozen=True, slots=True, kw_only=True)
class ClassSpec:
    """Physical properties of one waste class."""

    name: str
    density_kg_m3: float
    height_min_m: float
    height_max_m: float
    rgb: tuple[float, float, float] = (0.5, 0.5, 0.5)


DEFAULT_CLASSES: dict[str, ClassSpec] = {
    spec.name: spec
    for spec in (
        ClassSpec(
            name="concrete",
            density_kg_m3=2400.0,
            height_min_m=0.03,
            height_max_m=0.10,
            rgb=CLASS_RGB["concrete"],
        ),
        ClassSpec(
            name="brick",
            density_kg_m3=1900.0,
            height_min_m=0.04,
            height_max_m=0.08,
            rgb=CLASS_RGB["brick"],
        ),
        ClassSpec(
            name="wood",
            density_kg_m3=600.0,
            height_min_m=0.02,
            height_max_m=0.06,
            rgb=CLASS_RGB["wood"],
        ),
        ClassSpec(
            name="rubber",
            density_kg_m3=1200.0,
            height_min_m=0.005,
            height_max_m=0.03,
            rgb=CLASS_RGB["rubber"],
        ),
    )
}


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        msg = f"{where}: expected a number, got {value!r}"
        raise ClassTableError(msg)
    number = float(value)
    if not math.isfinite(number):
        msg = f"{where}: expected a finite number, got {value!r}"
        raise ClassTableError(msg)
    return number


def _spec_from_mapping(name: str, entry: Any, where: str) -> ClassSpec:
    if not isinstance(entry, dict):
        msg = f"{where}: expected a mapping with density_kg_m3, height_min_m, height_max_m"
        raise ClassTableError(msg)
    unknown = set(entry) - {"density_kg_m3", "height_min_m", "height_max_m", "rgb"}
    if unknown:
        msg = f"{where}: unknown field(s) {sorted(unknown)}"
        raise ClassTableError(msg)
    for field in ("density_kg_m3", "height_min_m", "height_max_m"):
        if field not in entry:
            msg = f"{where}: missing field {field!r}"
            raise ClassTableError(msg)
    density = _number(entry["density_kg_m3"], f"{where}.density_kg_m3")
    h_min = _number(entry["height_min_m"], f"{where}.height_min_m")
    h_max = _number(entry["height_max_m"], f"{where}.height_max_m")
    if density <= 0.0:
        msg = f"{where}.density_kg_m3: must be > 0, got {density}"
        raise ClassTableError(msg)
    if not 0.0 < h_min <= h_max:
        msg = f"{where}: need 0 < height_min_m <= height_max_m, got {h_min} and {h_max}"
        raise ClassTableError(msg)
    rgb_raw = entry.get("rgb", [0.5, 0.5, 0.5])
    if not isinstance(rgb_raw, list) or len(rgb_raw) != 3:
        msg = f"{where}.rgb: expected a list of 3 numbers in [0, 1], got {rgb_raw!r}"
        raise ClassTableError(msg)
    rgb = tuple(_number(c, f"{where}.rgb") for c in rgb_raw)
    if not all(0.0 <= c <= 1.0 for c in rgb):
        msg = f"{where}.rgb: components must lie in [0, 1], got {rgb_raw!r}"
        raise ClassTableError(msg)
    return ClassSpec(
        name=name,
        density_kg_m3=density,
        height_min_m=h_min,
        height_max_m=h_max,
        rgb=(rgb[0], rgb[1], rgb[2]),
    )


def load_class_table(path: Path) -> dict[str, ClassSpec]:
    """Read a class table from a YAML file (see the module docstring for its shape)."""
    import yaml

    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        msg = f"{path}: cannot read class table: {exc.strerror}"
        raise ClassTableError(msg) from exc
    except yaml.YAMLError as exc:
        msg = f"{path}: not valid YAML: {exc}"
        raise ClassTableError(msg) from exc
    if not isinstance(data, dict) or not isinstance(data.get("classes"), dict):
        msg = f'{path}: expected a top-level mapping "classes: {{name: {{...}}}}"'
        raise ClassTableError(msg)
    table: dict[str, ClassSpec] = {}
    for name, entry in data["classes"].items():
        if not isinstance(name, str) or not name or any(c.isspace() for c in name):
            msg = f"{path}: classes: invalid class name {name!r} (non-empty, no spaces)"
            raise ClassTableError(msg)
        table[name] = _spec_from_mapping(name, entry, f"{path}: classes.{name}")
    if not table:
        msg = f"{path}: classes: the table is empty"
        raise ClassTableError(msg)
    return table
