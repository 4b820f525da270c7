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
from dataclasses import dataclass
from json.encoder import encode_basestring_ascii

import numpy as np
import numpy.typing as npt

from meshgen.annotations import FloatArray
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

    def row(self) -> tuple[object, ...]:
        """Values in ``SCENE_COLUMNS`` order (repairs joined with ``;``)."""
        return tuple(
            ";".join(self.repairs) if name == "repairs" else getattr(self, name)
            for name in SCENE_COLUMNS
        )


_ROW_FORMAT = "%s,%s,%d,%s," + "%.9g," * 9 + "%s,%s,%d,%.9g,%s\n"


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
    )


def points_json(points: npt.NDArray[np.float64] | npt.NDArray[np.int64], fmt: str) -> str:
    """``[[a,b],...]`` JSON text of ``(n, 2)`` points, each number with the %-format ``fmt``."""
    pair = f"[{fmt},{fmt}],"
    return "[" + (pair * len(points))[:-1] % tuple(points.ravel().tolist()) + "]"


_WHOLE_LIMIT = float(2**53)
"""Whole floats below this are exact integers; ``%d`` of them matches ``%.0f``."""


def whole_pixels(polygons_px: list[FloatArray]) -> list[bool]:
    """Per ``(n_i, 2)`` polygon: True when every coordinate is a whole number in ``[0, 2**53)``.

    ``-0.0`` does not count (its sign bit is set). This is the test :func:`pixels_json` needs,
    made for many polygons in a few numpy calls.
    """
    if not polygons_px:
        return []
    sizes = np.fromiter((p.size for p in polygons_px), dtype=np.int64, count=len(polygons_px))
    values = np.concatenate([p.ravel() for p in polygons_px])
    good = (values == np.trunc(values)) & ~np.signbit(values) & (values < _WHOLE_LIMIT)
    flags = np.ones(len(polygons_px), dtype=bool)
    live = sizes > 0
    flags[live] = np.logical_and.reduceat(good, (np.cumsum(sizes) - sizes)[live])
    return [bool(f) for f in flags.tolist()]


def pixels_json(points_px: FloatArray, whole: bool | None = None) -> str:
    """``points_json(points_px, "%.3f")``, faster when all coordinates are whole and >= 0.

    Annotation tools mostly store whole pixels. For a whole number ``0 <= x < 2**53``,
    ``"%.3f" % x`` is ``"%d.000" % int(x)``, and formatting integers costs about a third of
    formatting floats. Anything else (fractions, negatives, -0.0) takes the float format.
    ``whole`` is that test's result when known (:func:`whole_pixels`), else it is made here.
    """
    if whole is None:
        (whole,) = whole_pixels([points_px])
    if whole:
        return points_json(points_px.astype(np.int64), "%d.000")
    return points_json(points_px, "%.3f")


def _object_fields(
    record: ObjectRecord,
    *,
    source_where: str,
    density_kg_m3: float,
    seed: int,
    rng_key: tuple[int, int, int],
) -> dict[str, object]:
    """The scene.json fields of one object other than its point arrays (the reference form)."""
    fields: dict[str, object] = dict(zip(SCENE_COLUMNS, record.row(), strict=True))
    fields["repairs"] = list(record.repairs)
    fields["source_where"] = source_where
    fields["density_kg_m3"] = density_kg_m3
    fields["seed"] = seed
    fields["rng_key"] = list(rng_key)
    return fields


_OBJECT_FORMAT = (
    '{"area_change_ratio":%r,"area_m2":%r,"centroid_x_m":%r,"centroid_y_m":%r,"class_id":%d,'
    '"class_name":%s,"convex_path":%s,"density_kg_m3":%r,"height_m":%r,"length_m":%r,'
    '"mass_kg":%r,"mesh_path":%s,"n_convex_pieces":%d,"object_id":%s,"repairs":[%s],'
    '"rng_key":[%d,%d,%d],"seed":%d,"source_image":%s,"source_where":%s,"volume_m3":%r,'
    '"width_m":%r,"yaw_rad":%r,'
)
""":func:`_object_fields` as sorted compact JSON without the closing brace, for plain floats."""


def object_json(
    record: ObjectRecord,
    *,
    source_where: str,
    density_kg_m3: float,
    seed: int,
    rng_key: tuple[int, int, int],
    footprint_m: FloatArray,
    polygon_px: FloatArray,
    polygon_px_whole: bool | None = None,
) -> str:
    """The scene.json entry of one object: its record plus where it came from and its points.

    The fields of :func:`_object_fields` as ``json.dumps(..., sort_keys=True,
    separators=(",", ":"))`` writes them, then ``footprint_m`` (``(n, 2)`` metres, ``%.9f``)
    and ``polygon_px`` (``(m, 2)`` pixels, ``%.3f``). When every float is a finite built-in
    ``float`` (always, in the pipeline) the fields are formatted with one template: ``%r`` of
    such a float is the ``float.__repr__`` that ``json`` writes, and text is escaped with the
    function ``json.dumps`` uses for ``str``. Anything else goes through ``json.dumps``.
    ``polygon_px_whole`` is :func:`whole_pixels` of ``polygon_px`` when already known.
    """
    return object_json_text(
        record,
        source_where=source_where,
        density_kg_m3=density_kg_m3,
        seed=seed,
        rng_key=rng_key,
        footprint_json=points_json(footprint_m, "%.9f"),
        polygon_json=pixels_json(polygon_px, polygon_px_whole),
    )


def object_json_text(
    record: ObjectRecord,
    *,
    source_where: str,
    density_kg_m3: float,
    seed: int,
    rng_key: tuple[int, int, int],
    footprint_json: str,
    polygon_json: str,
) -> str:
    """:func:`object_json` with the point arrays given as JSON text already.

    ``footprint_json`` is ``points_json(footprint_m, "%.9f")`` and ``polygon_json``
    ``points_json(polygon_px, "%.3f")`` (the pipeline formats them for many objects at once,
    :func:`meshgen.objtext.points_json_blocks`).
    """
    r = record
    floats = (
        r.area_change_ratio,
        r.area_m2,
        r.centroid_x_m,
        r.centroid_y_m,
        density_kg_m3,
        r.height_m,
        r.length_m,
        r.mass_kg,
        r.volume_m3,
        r.width_m,
        r.yaw_rad,
    )
    ints = (r.class_id, r.n_convex_pieces, *rng_key, seed)
    if (
        all(type(x) is float for x in floats)
        and math.isfinite(sum(floats))
        and all(type(i) is int for i in ints)
    ):
        text = encode_basestring_ascii
        head = _OBJECT_FORMAT % (
            r.area_change_ratio,
            r.area_m2,
            r.centroid_x_m,
            r.centroid_y_m,
            r.class_id,
            text(r.class_name),
            text(r.convex_path),
            density_kg_m3,
            r.height_m,
            r.length_m,
            r.mass_kg,
            text(r.mesh_path),
            r.n_convex_pieces,
            text(r.object_id),
            ",".join(map(text, r.repairs)),
            *rng_key,
            seed,
            text(r.source_image),
            text(source_where),
            r.volume_m3,
            r.width_m,
            r.yaw_rad,
        )
    else:
        fields = _object_fields(
            record,
            source_where=source_where,
            density_kg_m3=density_kg_m3,
            seed=seed,
            rng_key=rng_key,
        )
        head = json.dumps(fields, sort_keys=True, separators=(",", ":"))[:-1] + ","
    return f'{head}"footprint_m":{footprint_json},"polygon_px":{polygon_json}}}'
