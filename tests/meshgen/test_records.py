"""Scene record texts: the direct formatting gives exactly what csv/json of the fields give."""

from __future__ import annotations

import json

import numpy as np
import pytest

from meshgen.export import SCENE_COLUMNS, csv_text
from meshgen.records import EntryExtras, ObjectRecord, csv_row, object_json_text, objects_json_text
from tests.meshgen.reference_text import object_json, points_json


def _record(**changes: object) -> ObjectRecord:
    fields: dict[str, object] = {
        "object_id": "img_007",
        "source_image": "labelme/img.json",
        "class_id": 2,
        "class_name": "wood",
        "centroid_x_m": 0.0123456789,
        "centroid_y_m": -0.25,
        "yaw_rad": 1.0e-17,
        "length_m": 0.3,
        "width_m": 0.1,
        "area_m2": 0.0299999,
        "height_m": 0.04,
        "volume_m3": 0.0012,
        "mass_kg": 0.72,
        "mesh_path": "img_007.obj",
        "convex_path": "img_007_convex.obj",
        "n_convex_pieces": 3,
        "area_change_ratio": 1.0,
        "repairs": ("removed_duplicates:2", "simplified:40->12"),
    }
    fields.update(changes)
    return ObjectRecord(**fields)  # type: ignore[arg-type]


FOOTPRINT = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.05], [-1e-12, 0.05]])
PIXELS = np.array([[10.0, 20.0], [30.0, 20.0], [30.0, 41.0]])


def _texts(record: ObjectRecord, density: float) -> tuple[str, str]:
    """``object_json_text`` of ``record`` and the ``json.dumps`` reference of it."""
    where, seed, key = "shape 7", 5, (5, 123, 7)
    extra = EntryExtras(
        where, density, key, points_json(FOOTPRINT, "%.9f"), points_json(PIXELS, "%.3f")
    )
    text = object_json_text(record, extra, seed)
    reference = object_json(
        record,
        source_where=where,
        density_kg_m3=density,
        seed=seed,
        rng_key=key,
        footprint_m=FOOTPRINT,
        polygon_px=PIXELS,
    )
    return text, reference


@pytest.mark.parametrize(
    "changes",
    [
        {},
        {"object_id": 'quote"and,comma', "class_name": "bois\u00e9", "repairs": ()},
        {"source_image": "dir/with\nnewline.json", "convex_path": "", "n_convex_pieces": 1},
        {"mass_kg": np.float64(0.1) + np.float64(0.2)},
        {"yaw_rad": float("nan")},
        {"area_change_ratio": float("inf"), "width_m": 1e300},
    ],
)
def test_object_json_text_is_sorted_compact_json(changes: dict[str, object]) -> None:
    record = _record(**changes)
    text, reference = _texts(record, 600.0)
    assert text == reference
    assert json.loads(text)["object_id"] == record.object_id


def test_object_json_text_keeps_an_integer_density() -> None:
    text, reference = _texts(_record(), 600)  # a YAML int would print as 600, not 600.0
    assert text == reference
    assert '"density_kg_m3":600,' in text


@pytest.mark.parametrize(
    "changes",
    [{}, {"object_id": 'a,"b"', "repairs": ("x;y", "z")}, {"source_image": "line\nbreak"}],
)
def test_csv_row_matches_csv_text(changes: dict[str, object]) -> None:
    record = _record(**changes)
    header = ",".join(SCENE_COLUMNS) + "\n"
    assert header + csv_row(record) == csv_text(SCENE_COLUMNS, [record.row()])


def test_objects_json_text_joins_the_json_dumps_entries() -> None:
    # plain records (one template) and, in a second batch, records that need json.dumps
    plain = [_record(), _record(object_id='quote"and,comma', repairs=()), _record(mass_kg=0.1)]
    odd = [*plain, _record(yaw_rad=float("nan")), _record(mass_kg=np.float64(0.3))]
    footprints = [FOOTPRINT, FOOTPRINT * 3.0, FOOTPRINT[:3], FOOTPRINT, FOOTPRINT]
    for records in (plain, odd, plain[:1], []):
        extras = [
            EntryExtras(
                f"shape {k}",
                600.0 if k % 2 else 750,  # a YAML int stays an int
                (5, 123, k),
                points_json(footprints[k], "%.9f"),
                points_json(PIXELS + k, "%.3f"),
            )
            for k in range(len(records))
        ]
        text = objects_json_text(records, extras, 5)
        want = [
            object_json(
                record,
                source_where=extra.source_where,
                density_kg_m3=extra.density_kg_m3,
                seed=5,
                rng_key=extra.rng_key,
                footprint_m=footprints[k],
                polygon_px=PIXELS + k,
            )
            for k, (record, extra) in enumerate(zip(records, extras, strict=True))
        ]
        assert text == ",".join(want)
        assert json.loads(f"[{text}]") == [json.loads(w) for w in want]
