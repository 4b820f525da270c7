"""The class table: every fact about a waste class, defined once.

A :class:`Material` is one class: its density, the range its pieces' heights are sampled from,
its friction and restitution ranges, the seal efficiency a suction cup keeps on it and its
display colour. A :class:`ClassTable` is the classes of a dataset in order, with a ``default``
entry for any class it does not name, so any class name works: an unnamed class takes the
default's facts and a colour of its own derived from its name (:func:`name_rgb`).

The shipped table is ``interfaces/materials.yaml`` (:func:`shipped_table`). A dataset's own
table (``cdw-twin meshgen --classes FILE.yaml``) has the same shape; every field it leaves out
is taken from the shipped table's entry of that class, else from its default::

    classes:
      tiles: {density_kg_m3: 2000, height_min_m: 0.008, height_max_m: 0.015}
      bricks: {density_kg_m3: 1900, seal_efficiency: 0.4, rgb: [0.7, 0.3, 0.2]}
    default: {density_kg_m3: 1800}

meshgen writes the table a dataset was meshed with into its output as ``classes.yaml``
(:data:`DATASET_TABLE`: the classes it meshed pieces of, in the table's order, each with every
field), which :func:`dataset_table` reads; a run writes the same table into its resolved cell
(``materials:``, :mod:`interfaces.cell`), where the twin and the controllers read it. Every
error names the file and the key.
"""

from __future__ import annotations

import colorsys
import json
import math
import zlib
from collections.abc import Iterable
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path
from typing import Any

import yaml

from interfaces.errors import ConfigError, cut, require
from interfaces.fileio import write_atomic
from interfaces.yamlio import load_yaml_file

MATERIALS_FILE = Path(__file__).resolve().parent / "materials.yaml"
"""The shipped class table."""

DATASET_TABLE = "classes.yaml"
"""The file in a meshgen output folder that holds the class table it was meshed with."""

MTL_FILE = "materials.mtl"
"""The file in a meshgen output folder with each class's colour (``newmtl`` + ``Kd``); a
folder written before ``classes.yaml`` existed gives its class order and colours from it."""

RGB = tuple[float, float, float]
"""Red, green, blue in [0, 1]."""

FIELDS = (
    "density_kg_m3",
    "height_min_m",
    "height_max_m",
    "friction",
    "restitution",
    "seal_efficiency",
    "rgb",
)
"""The fields of a class table entry, in the order a table is written."""

MAX_CLASSES = 1000
"""Most classes a table may name."""


class MaterialsError(ConfigError):
    """A class table is malformed (the message names the file and the key)."""


def name_rgb(class_name: str) -> RGB:
    """The colour of a class no table gives one: a hue from the CRC-32 of the name, saturated
    and mid-bright so it stands out on the belt, the same on every machine and in every run."""
    hue = (zlib.crc32(class_name.encode("utf-8")) % 360) / 360.0
    red, green, blue = colorsys.hsv_to_rgb(hue, 0.65, 0.85)
    return (round(red, 3), round(green, 3), round(blue, 3))


def _check_range(key: str, value: tuple[float, float], high: float) -> None:
    low_v, high_v = value
    require(
        0.0 <= low_v <= high_v <= high,
        key,
        list(value),
        f"needs 0 <= low <= high <= {high:g}",
    )


@dataclass(frozen=True, kw_only=True)
class Material:
    """One waste class.

    ``density_kg_m3`` gives a piece's mass from its volume (meshgen) and a seen box's mass
    estimate (a controller's too-heavy check); a piece's height is sampled uniformly from
    ``[height_min_m, height_max_m]``; its friction coefficient and restitution from the
    ``friction`` and ``restitution`` ranges (``[low, high]``); ``seal_efficiency`` is the
    fraction of a suction cup's vacuum kept on its surface (the cup's holding force, see
    :class:`interfaces.tools.SuctionCupSpec`); ``rgb`` its colour (None only for a table's
    default entry: each unnamed class then gets :func:`name_rgb`).
    """

    name: str
    density_kg_m3: float
    height_min_m: float
    height_max_m: float
    friction: tuple[float, float]
    restitution: tuple[float, float]
    seal_efficiency: float
    rgb: RGB | None = None

    def __post_init__(self) -> None:
        require(
            0 < len(self.name) <= 64
            and self.name.isprintable()
            and not any(c.isspace() for c in self.name),
            "name",
            self.name,
            "1 to 64 printable characters, no spaces",
        )
        require(
            math.isfinite(self.density_kg_m3) and 0.0 < self.density_kg_m3 <= 100_000.0,
            "density_kg_m3",
            self.density_kg_m3,
            "must be > 0 (and at most 1e5 kg/m^3)",
        )
        require(
            0.0 < self.height_min_m <= self.height_max_m <= 1.0,
            "height_min_m",
            [self.height_min_m, self.height_max_m],
            "need 0 < height_min_m <= height_max_m <= 1 m",
        )
        _check_range("friction", self.friction, 2.0)
        _check_range("restitution", self.restitution, 1.0)
        require(
            0.0 < self.seal_efficiency <= 1.0,
            "seal_efficiency",
            self.seal_efficiency,
            "must be in (0, 1]",
        )
        if self.rgb is not None:
            require(
                all(0.0 <= c <= 1.0 for c in self.rgb),
                "rgb",
                list(self.rgb),
                "three components in [0, 1]",
            )

    @property
    def colour(self) -> RGB:
        """``rgb``, else the colour of the name (:func:`name_rgb`)."""
        return self.rgb if self.rgb is not None else name_rgb(self.name)

    def to_data(self) -> dict[str, Any]:
        """The entry as plain data (without its name; ``rgb`` left out when None)."""
        data: dict[str, Any] = {
            "density_kg_m3": self.density_kg_m3,
            "height_min_m": self.height_min_m,
            "height_max_m": self.height_max_m,
            "friction": list(self.friction),
            "restitution": list(self.restitution),
            "seal_efficiency": self.seal_efficiency,
        }
        if self.rgb is not None:
            data["rgb"] = list(self.rgb)
        return data


DEFAULT_KEY = "default"
"""The table key of the entry for classes the table does not name."""


@dataclass(frozen=True, kw_only=True)
class ClassTable:
    """Classes in order (``classes``, each with its colour) and the ``default`` entry every
    class the table does not name takes (:meth:`material`)."""

    classes: tuple[Material, ...]
    default: Material

    def __post_init__(self) -> None:
        names = [m.name for m in self.classes]
        require(len(set(names)) == len(names), "classes", names, "names a class twice")
        require(len(names) <= MAX_CLASSES, "classes", len(names), f"at most {MAX_CLASSES}")

    @property
    def names(self) -> tuple[str, ...]:
        """The classes the table names, in order."""
        return tuple(m.name for m in self.classes)

    def names_class(self, name: str) -> bool:
        """Whether the table has an entry of its own for ``name``."""
        return any(m.name == name for m in self.classes)

    def material(self, name: str) -> Material:
        """The entry of ``name``; a class the table does not name: the default's facts under
        its own name, with the default's colour if it has one, else :func:`name_rgb`."""
        for entry in self.classes:
            if entry.name == name:
                return entry
        return replace(self.default, name=name, rgb=self.default.rgb or name_rgb(name))

    def including(self, names: Iterable[str]) -> ClassTable:
        """The table with an entry (:meth:`material`: the default's) appended for each of
        ``names`` it does not name, in the order given."""
        extra: dict[str, Material] = {}
        for name in names:
            if not self.names_class(name) and name not in extra:
                extra[name] = self.material(name)
        return replace(self, classes=(*self.classes, *extra.values()))

    def restricted(self, names: Iterable[str]) -> ClassTable:
        """The table's entries (:meth:`material`) of ``names`` only, in the table's order, then
        those it does not name in the order given; the default kept."""
        wanted = dict.fromkeys(names)
        ordered = [m for m in self.classes if m.name in wanted]
        ordered += [self.material(n) for n in wanted if not self.names_class(n)]
        return replace(self, classes=tuple(ordered))

    def to_data(self) -> dict[str, Any]:
        """The table as plain data: ``default``, then ``classes`` (name -> entry, in order)."""
        return {
            DEFAULT_KEY: self.default.to_data(),
            "classes": {m.name: m.to_data() for m in self.classes},
        }

    def to_yaml(self) -> str:
        """The table as YAML, in the shape :func:`load_table` reads."""
        return yaml.safe_dump(self.to_data(), sort_keys=False)

    def save(self, path: Path) -> None:
        """Write the table as YAML atomically."""
        write_atomic(path, self.to_yaml())


def _number(value: object, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        msg = f"{key} = {cut(value)}: expected a number"
        raise MaterialsError(msg)
    number = float(value)
    if not math.isfinite(number):
        msg = f"{key} = {cut(value)}: expected a finite number"
        raise MaterialsError(msg)
    return number


def _numbers(value: object, key: str, count: int) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or len(value) != count:
        msg = f"{key} = {cut(value)}: expected a list of {count} numbers"
        raise MaterialsError(msg)
    return tuple(_number(v, f"{key}[{i}]") for i, v in enumerate(value))


def material_from_data(name: str, data: object, key: str, base: Material) -> Material:
    """The entry ``data`` (a mapping of :data:`FIELDS`, any of them left out) of class
    ``name`` over ``base`` (the fields it leaves out); ``key`` names it in errors. Heights
    come in pairs: one of ``height_min_m`` and ``height_max_m`` without the other is refused."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        msg = f"{key} = {cut(data)}: expected a mapping of {', '.join(FIELDS)}"
        raise MaterialsError(msg)
    unknown = [k for k in data if k not in FIELDS]
    if unknown:
        msg = f"{key}: unknown field(s) {cut(unknown)} (allowed: {', '.join(FIELDS)})"
        raise MaterialsError(msg)
    heights = [k for k in ("height_min_m", "height_max_m") if k in data]
    if len(heights) == 1:
        missing = "height_max_m" if heights[0] == "height_min_m" else "height_min_m"
        msg = f"{key}: missing field {missing!r} (give both heights, or neither)"
        raise MaterialsError(msg)
    fields: dict[str, Any] = {}
    for field_name in ("density_kg_m3", "height_min_m", "height_max_m", "seal_efficiency"):
        if field_name in data:
            fields[field_name] = _number(data[field_name], f"{key}.{field_name}")
    for field_name in ("friction", "restitution"):
        if field_name in data:
            low, high = _numbers(data[field_name], f"{key}.{field_name}", 2)
            fields[field_name] = (low, high)
    if "rgb" in data:
        if data["rgb"] is None:
            fields["rgb"] = None
        else:
            red, green, blue = _numbers(data["rgb"], f"{key}.rgb", 3)
            fields["rgb"] = (red, green, blue)
    try:
        return replace(base, name=name, **fields)
    except ConfigError as exc:
        msg = f"{key}.{exc}"
        raise MaterialsError(msg) from None


def table_from_data(data: object, where: str, base: ClassTable | None = None) -> ClassTable:
    """A table from plain data (``classes:`` and optionally ``default:``), every field left out
    taken from ``base`` (its entry of that class, else its default; None: the table must be
    complete). ``where`` (the file) prefixes every error."""
    shape = f"expected a top-level mapping `classes: {{name: {{...}}}}` (and `{DEFAULT_KEY}:`)"
    if not isinstance(data, dict):
        msg = f"{where}: {shape}"
        raise MaterialsError(msg)
    unknown = [k for k in data if k not in ("classes", DEFAULT_KEY)]
    if unknown:
        msg = f"{where}: unknown key(s) {cut(unknown)}: {shape}"
        raise MaterialsError(msg)
    raw_classes = data.get("classes") or {}
    if not isinstance(raw_classes, dict):
        msg = f"{where}: classes = {cut(raw_classes)}: {shape}"
        raise MaterialsError(msg)
    if len(raw_classes) > MAX_CLASSES:
        msg = f"{where}: classes: {len(raw_classes)} classes, more than {MAX_CLASSES}"
        raise MaterialsError(msg)
    if base is None:
        default = _complete(data.get(DEFAULT_KEY), f"{where}: {DEFAULT_KEY}")
    else:
        default = material_from_data(
            DEFAULT_KEY, data.get(DEFAULT_KEY), f"{where}: {DEFAULT_KEY}", base.default
        )
    entries = []
    for name, raw in raw_classes.items():
        if not isinstance(name, str) or not name or any(c.isspace() for c in name):
            msg = f"{where}: classes: invalid class name {cut(name)} (non-empty, no spaces)"
            raise MaterialsError(msg)
        key = f"{where}: classes.{name}"
        if base is not None and base.names_class(name):
            below = base.material(name)
        else:
            below = replace(default, name=name, rgb=default.rgb or name_rgb(name))
        entries.append(material_from_data(name, raw, key, below))
    try:
        return ClassTable(classes=tuple(entries), default=default)
    except ConfigError as exc:
        msg = f"{where}: {exc}"
        raise MaterialsError(msg) from None


def _complete(data: object, key: str) -> Material:
    """A complete entry (every field but ``rgb`` given)."""
    if not isinstance(data, dict):
        msg = f"{key} = {cut(data)}: expected a mapping of {', '.join(FIELDS)}"
        raise MaterialsError(msg)
    missing = [f for f in FIELDS if f != "rgb" and f not in data]
    if missing:
        msg = f"{key}: missing field(s) {', '.join(missing)}"
        raise MaterialsError(msg)
    placeholder = Material(
        name=DEFAULT_KEY,
        density_kg_m3=1.0,
        height_min_m=0.01,
        height_max_m=0.01,
        friction=(0.0, 0.0),
        restitution=(0.0, 0.0),
        seal_efficiency=1.0,
    )
    return material_from_data(DEFAULT_KEY, data, key, placeholder)


def load_table(path: Path, base: ClassTable | None = None) -> ClassTable:
    """Read a class table file (at most 1 MB of YAML, :func:`interfaces.yamlio.load_yaml_file`);
    fields it leaves out come from ``base`` (:func:`table_from_data`)."""
    try:
        data = load_yaml_file(path, what="class table")
    except ConfigError as exc:
        raise MaterialsError(str(exc)) from None
    return table_from_data(data, str(path), base)


@cache
def shipped_table() -> ClassTable:
    """The shipped class table (``interfaces/materials.yaml``), read once."""
    return load_table(MATERIALS_FILE)


def user_table(path: Path) -> ClassTable:
    """A dataset's class table file over the shipped one: its classes, in its order, each
    field it leaves out from the shipped entry of that class (else the default), then the
    shipped classes it does not name; its ``default`` over the shipped default."""
    shipped = shipped_table()
    own = load_table(path, base=shipped)
    rest = tuple(m for m in shipped.classes if not own.names_class(m.name))
    return replace(own, classes=(*own.classes, *rest))


def mtl_classes(path: Path) -> tuple[list[str], dict[str, RGB]]:
    """The ``newmtl`` names of a ``materials.mtl`` in order, and their ``Kd`` colours."""
    names: list[str] = []
    colours: dict[str, RGB] = {}
    if not path.is_file():
        return names, colours
    current: str | None = None
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        fields = line.split()
        if len(fields) == 2 and fields[0] == "newmtl":
            current = fields[1]
            names.append(current)
        elif len(fields) == 4 and fields[0] == "Kd" and current is not None:
            try:
                red, green, blue = (float(v) for v in fields[1:])
            except ValueError:
                continue
            if all(0.0 <= c <= 1.0 for c in (red, green, blue)):
                colours[current] = (red, green, blue)
    return names, colours


def _legacy_table(dataset_dir: Path) -> ClassTable:
    """The table of a meshgen output written before ``classes.yaml``: the classes of its
    ``summary.json`` (``config.classes``: density and heights), in ``materials.mtl``'s order
    with its colours, every other fact the shipped table's."""
    shipped = shipped_table()
    path = dataset_dir / "summary.json"
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        msg = f"{path}: no such file (every meshgen output has one)"
        raise MaterialsError(msg) from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        msg = f"{path}: cannot read: {cut(str(exc), 200)}"
        raise MaterialsError(msg) from None
    config = summary.get("config") if isinstance(summary, dict) else None
    table = config.get("classes") if isinstance(config, dict) else None
    if not isinstance(table, dict) or not table:
        msg = f"{path}: no class table (config.classes)"
        raise MaterialsError(msg)
    order, colours = mtl_classes(dataset_dir / MTL_FILE)
    names = [n for n in order if n in table] + [n for n in table if n not in order]
    entries = []
    for name in names:
        raw = table[name]
        fields = {
            k: raw[k]
            for k in ("density_kg_m3", "height_min_m", "height_max_m")
            if isinstance(raw, dict) and k in raw
        }
        if name in colours:
            fields["rgb"] = list(colours[name])
        below = shipped.material(name)
        entries.append(material_from_data(name, fields, f"{path}: config.classes.{name}", below))
    return ClassTable(classes=tuple(entries), default=shipped.default)


def dataset_table(dataset_dir: Path) -> ClassTable:
    """The class table a meshgen output folder was meshed with: its ``classes.yaml`` (complete:
    the classes it has pieces of, in order, and the default), or, for a folder written before
    it, the classes of its ``summary.json`` (:func:`_legacy_table`). :class:`MaterialsError`
    naming the file when neither can be read."""
    path = Path(dataset_dir) / DATASET_TABLE
    if path.is_file():
        return load_table(path)
    return _legacy_table(Path(dataset_dir))


__all__ = [
    "DATASET_TABLE",
    "DEFAULT_KEY",
    "FIELDS",
    "MATERIALS_FILE",
    "RGB",
    "ClassTable",
    "Material",
    "MaterialsError",
    "dataset_table",
    "load_table",
    "material_from_data",
    "mtl_classes",
    "name_rgb",
    "shipped_table",
    "table_from_data",
    "user_table",
]
