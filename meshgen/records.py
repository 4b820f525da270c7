"""One meshed object's record and its text forms: the scene.csv row and the scene.json entry.

Both texts are built by direct formatting instead of ``csv``/``json.dumps`` of a dict (which
cost several times as much per object), with exactly the bytes those give:

- scene.csv values: floats with ``%.9g``, text quoted when it holds ``,``, ``"`` or a newline
  (:func:`meshgen.export.csv_field`).
- scene.json objects: compact JSON with sorted keys (what ``json.dumps(meta, sort_keys=True,
  separators=(",", ":"))`` gives), followed by the two point arrays ``footprint_m`` (``%.9f``)
  and ``polygon_px`` (``%.3f``). ``tests/meshgen/test_records.py`` checks this against
  ``json.dumps``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import chain
from json.encoder import encode_basestring_ascii
from typing import NamedTuple, cast

from meshgen.export import SCENE_COLUMNS, csv_field


@dataclass(frozen=True, slots=True, kw_only=True)
class ObjectRecord:
    """One meshed object: the scene.csv row (belt-frame pose, size, mass, file paths)."""

    object_id: str
    source_image: str
    class_id: int
    class_name: str
    centroid_x_m: float
    centroid_y_m: float
    yaw_rad: float
    length_m: float
    width_m: float
    area_m2: float
    height_m: float
    volume_m3: float
    mass_kg: float
    mesh_path: str
    convex_path: str
    n_convex_pieces: int
    area_change_ratio: float
    repairs: tuple[str, ...]
    texture_path: str = ""
    height_source: str = "sampled"

    def row(self) -> tuple[object, ...]:
        """Values in ``SCENE_COLUMNS`` order (repairs joined with ``;``)."""
        return tuple(
            ";".join(self.repairs) if name == "repairs" else getattr(self, name)
            for name in SCENE_COLUMNS
        )


_ROW_FORMAT = "%s,%s,%d,%s," + "%.9g," * 9 + "%s,%s,%d,%.9g,%s,%s,%s\n"


def _csv_str(text: str) -> str:
    """:func:`meshgen.export.csv_field` of a string, without its generator when nothing to quote."""
    if "," in text or '"' in text or "\n" in text:
        return csv_field(text)
    return text


def csv_row(record: ObjectRecord) -> str:
    """One scene.csv line (same formatting as :func:`meshgen.export.csv_text`)."""
    return _ROW_FORMAT % (
        _csv_str(record.object_id),
        _csv_str(record.source_image),
        record.class_id,
        _csv_str(record.class_name),
        record.centroid_x_m,
        record.centroid_y_m,
        record.yaw_rad,
        record.length_m,
        record.width_m,
        record.area_m2,
        record.height_m,
        record.volume_m3,
        record.mass_kg,
        _csv_str(record.mesh_path),
        _csv_str(record.convex_path),
        record.n_convex_pieces,
        record.area_change_ratio,
        _csv_str(";".join(record.repairs)),
        _csv_str(record.texture_path),
        _csv_str(record.height_source),
    )


def _object_fields(
    record: ObjectRecord,
    *,
    source_where: str,
    density_kg_m3: float,
    seed: int,
    rng_key: tuple[int, int, int],
) -> dict[str, object]:
    """The scene.json fields of one object other than its point arrays, for ``json.dumps``."""
    fields: dict[str, object] = dict(zip(SCENE_COLUMNS, record.row(), strict=True))
    fields["repairs"] = list(record.repairs)
    fields["source_where"] = source_where
    fields["density_kg_m3"] = density_kg_m3
    fields["seed"] = seed
    fields["rng_key"] = list(rng_key)
    return fields


_OBJECT_FORMAT = (
    '{"area_change_ratio":%r,"area_m2":%r,"centroid_x_m":%r,"centroid_y_m":%r,"class_id":%d,'
    '"class_name":%s,"convex_path":%s,"density_kg_m3":%r,"height_m":%r,"height_source":%s,'
    '"length_m":%r,"mass_kg":%r,"mesh_path":%s,"n_convex_pieces":%d,"object_id":%s,'
    '"repairs":[%s],"rng_key":[%d,%d,%d],"seed":%d,"source_image":%s,"source_where":%s,'
    '"texture_path":%s,"volume_m3":%r,"width_m":%r,"yaw_rad":%r,'
)
""":func:`_object_fields` as sorted compact JSON without the closing brace, for plain floats."""


def _head_values(
    r: ObjectRecord, where: str, density: float, key: tuple[int, int, int], seed: int
) -> tuple[object, ...]:
    """The values of :data:`_OBJECT_FORMAT` for one object, its texts JSON-escaped."""
    text = encode_basestring_ascii
    return (
        r.area_change_ratio,
        r.area_m2,
        r.centroid_x_m,
        r.centroid_y_m,
        r.class_id,
        text(r.class_name),
        text(r.convex_path),
        density,
        r.height_m,
        text(r.height_source),
        r.length_m,
        r.mass_kg,
        text(r.mesh_path),
        r.n_convex_pieces,
        text(r.object_id),
        ",".join(map(text, r.repairs)),
        *key,
        seed,
        text(r.source_image),
        text(where),
        text(r.texture_path),
        r.volume_m3,
        r.width_m,
        r.yaw_rad,
    )


class EntryExtras(NamedTuple):
    """What an object's scene.json entry holds beyond its record (see :func:`object_json_text`)."""

    source_where: str
    density_kg_m3: float
    rng_key: tuple[int, int, int]
    footprint_json: str
    polygon_json: str


def object_json_text(record: ObjectRecord, extra: EntryExtras, seed: int) -> str:
    """The scene.json entry of one object: its record plus where it came from and its points.

    The fields of :func:`_object_fields` as ``json.dumps(..., sort_keys=True,
    separators=(",", ":"))`` writes them, then ``extra.footprint_json`` and
    ``extra.polygon_json``: the JSON text of ``footprint_m`` (``(n, 2)`` metres, ``%.9f``) and
    ``polygon_px`` (``(m, 2)`` pixels, ``%.3f``), which the pipeline formats for many objects at
    once (:func:`meshgen.objtext.points_json_blocks`). The general route, for any value types;
    :func:`objects_json_text` formats whole images of plain values with one template and falls
    back to this.
    """
    fields = _object_fields(
        record,
        source_where=extra.source_where,
        density_kg_m3=extra.density_kg_m3,
        seed=seed,
        rng_key=extra.rng_key,
    )
    head = json.dumps(fields, sort_keys=True, separators=(",", ":"))[:-1] + ","
    return f'{head}"footprint_m":{extra.footprint_json},"polygon_px":{extra.polygon_json}}}'


_ENTRY_FORMAT = _OBJECT_FORMAT + '"footprint_m":%s,"polygon_px":%s}'
""":func:`object_json_text` of plain floats as one template (28 values)."""
_ENTRY_WIDTH = 28
_ENTRY_FLOATS = (0, 1, 2, 3, 7, 8, 10, 11, 23, 24, 25)
"""Where in an entry's values the floats stand (written with ``%r``)."""
_ENTRY_INTS = (4, 13, 16, 17, 18, 19)
"""Where in an entry's values the integers stand (written with ``%d``)."""


def objects_json_text(
    records: Sequence[ObjectRecord], extras: Sequence[EntryExtras], seed: int
) -> str:
    """The scene.json entries of many objects joined with ``,`` (one image's ``objects``).

    Exactly ``",".join`` of :func:`object_json_text` of each record with its extras, but when
    every float is a finite built-in ``float`` and every integer a built-in ``int`` (always, in
    the pipeline), all entries are formatted by one ``%`` of one repeated template, which saves
    the per-object checks, calls and copies of the long point texts. Otherwise each entry is
    made on its own.
    """
    values: list[object] = []
    try:
        for r, (where, density, key, footprint_json, polygon_json) in zip(
            records, extras, strict=True
        ):
            values += _head_values(r, where, density, key, seed)
            values += (footprint_json, polygon_json)
    except TypeError:  # a text field that is not a str: as object_json_text handles it
        values = []
    floats = list(chain.from_iterable(values[at::_ENTRY_WIDTH] for at in _ENTRY_FLOATS))
    ints = list(chain.from_iterable(values[at::_ENTRY_WIDTH] for at in _ENTRY_INTS))
    if (
        values
        and set(map(type, floats)) == {float}
        and math.isfinite(sum(cast(list[float], floats)))
        and set(map(type, ints)) == {int}
    ):
        return ",".join([_ENTRY_FORMAT] * len(records)) % tuple(values)
    return ",".join(
        object_json_text(record, extra, seed) for record, extra in zip(records, extras, strict=True)
    )
