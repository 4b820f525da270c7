"""Scene record texts: the direct formatting gives exactly what csv/json of the fields give."""

from __future__ import annotations

import json

import numpy as np
import pytest

from meshgen.export import SCENE_COLUMNS, csv_text
from meshgen.records import (
    ObjectRecord,
    _object_fields,
    csv_row,
    object_json,
    pixels_json,
    points_json,
    whole_pixels,
)


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


def _reference(record: ObjectRecord, polygon_px: np.ndarray, density: float = 600.0) -> str:
    fields = _object_fields(
        record, source_where="shape 7", density_kg_m3=density, seed=5, rng_key=(5, 123, 7)
    )
    head = json.dumps(fields, sort_keys=True, separators=(",", ":"))
    return (
        f'{head[:-1]},"footprint_m":{points_json(FOOTPRINT, "%.9f")}'
        f',"polygon_px":{points_json(polygon_px, "%.3f")}}}'
    )


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
@pytest.mark.parametrize(
    "polygon_px",
    [
        PIXELS,
        PIXELS + 0.5,
        np.array([[-0.0, 5.0], [3.0, 5.0], [3.0, 9.0]]),
        np.array([[-2.0, 5.0], [3.0, 5.0], [3.0, 9.0]]),
        np.array([[2.0**60, 5.0], [3.0, 5.0], [3.0, 9.0]]),
    ],
)
def test_object_json_is_sorted_compact_json(
    changes: dict[str, object], polygon_px: np.ndarray
) -> None:
    record = _record(**changes)
    kwargs = {"source_where": "shape 7", "density_kg_m3": 600.0, "seed": 5, "rng_key": (5, 123, 7)}
    expected = _reference(record, polygon_px)
    for whole in (None, *whole_pixels([polygon_px])):
        text = object_json(
            record, footprint_m=FOOTPRINT, polygon_px=polygon_px, polygon_px_whole=whole, **kwargs
        )
        assert text == expected
    assert json.loads(text)["object_id"] == record.object_id


def test_object_json_keeps_an_integer_density() -> None:
    record = _record()
    text = object_json(
        record,
        source_where="shape 7",
        density_kg_m3=600,  # a YAML int would print as 600, not 600.0
        seed=5,
        rng_key=(5, 123, 7),
        footprint_m=FOOTPRINT,
        polygon_px=PIXELS,
    )
    assert text == _reference(record, PIXELS, density=600)
    assert '"density_kg_m3":600,' in text


def test_pixels_json_matches_float_format() -> None:
    rng = np.random.default_rng(3)
    cases = [
        rng.integers(0, 5000, size=(50, 2)).astype(np.float64),
        rng.uniform(-10, 5000, size=(50, 2)),
        np.array([[0.0, 0.0], [1.0, 2.0], [3.0, 4.0]]),
        np.array([[-0.0, 0.0], [1.0, 2.0], [3.0, 4.0]]),
        np.array([[2.0**53, 1.0], [1.0, 2.0], [3.0, 4.0]]),
        np.array([[0.9999999999999999, 1.0], [1.0, 2.0], [3.0, 4.0]]),
        np.zeros((0, 2)),
    ]
    flags = whole_pixels(cases)
    assert flags == [True, False, True, False, False, False, True]
    for points, whole in zip(cases, flags, strict=True):
        assert pixels_json(points) == points_json(points, "%.3f")
        assert pixels_json(points, whole) == points_json(points, "%.3f")


@pytest.mark.parametrize(
    "changes",
    [{}, {"object_id": 'a,"b"', "repairs": ("x;y", "z")}, {"source_image": "line\nbreak"}],
)
def test_csv_row_matches_csv_text(changes: dict[str, object]) -> None:
    record = _record(**changes)
    header = ",".join(SCENE_COLUMNS) + "\n"
    assert header + csv_row(record) == csv_text(SCENE_COLUMNS, [record.row()])
