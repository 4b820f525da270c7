"""COCO files in the wrong layout are skipped with a reason; stray JSON does not win detection."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from meshgen.config import MeshgenConfig
from meshgen.loaders import discover
from meshgen.pipeline import mesh_dataset
from meshgen.sample import png_bytes
from twin.cli import main

SQUARE = [80, 40, 120, 40, 120, 60, 80, 60]


def _image(image_id: int, stem: str) -> dict[str, Any]:
    return {"id": image_id, "file_name": f"{stem}.png", "width": 200, "height": 100}


def _annotation(ann_id: int, image_id: int) -> dict[str, Any]:
    return {"id": ann_id, "image_id": image_id, "category_id": 1, "segmentation": [SQUARE]}


def _coco(stem: str, **fields: Any) -> dict[str, Any]:
    """A COCO document of one image ``stem`` with one square brick, ``fields`` overriding."""
    doc: dict[str, Any] = {
        "images": [_image(1, stem)],
        "annotations": [_annotation(1, 1)],
        "categories": [{"id": 1, "name": "brick"}],
    }
    doc.update(fields)
    return doc


def _write(folder: Path, name: str, doc: object) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_text(json.dumps(doc), encoding="utf-8")


BAD_LAYOUTS: dict[str, tuple[dict[str, Any], str]] = {
    "images_number.json": ({"images": 3}, '"images" is a number'),
    "annotations_null.json": ({"annotations": None}, '"annotations" is null'),
    "categories_string.json": ({"categories": "brick"}, '"categories" is a string'),
    "images_object.json": ({"images": {"id": 1}}, '"images" is an object'),
}


def test_non_list_fields_skip_that_file_and_the_others_are_meshed(tmp_path: Path) -> None:
    data = tmp_path / "data"
    _write(data, "good.json", _coco("good"))
    for name, (fields, _) in BAD_LAYOUTS.items():
        _write(data, name, _coco(name.removesuffix(".json"), **fields))
    no_categories = _coco("nocat")
    del no_categories["categories"]
    _write(data, "no_categories.json", no_categories)
    summary = mesh_dataset(data, tmp_path / "out", MeshgenConfig())
    assert summary.fmt == "coco"
    assert (summary.images, summary.objects) == (1, 1)
    assert summary.skipped == {"bad_file": len(BAD_LAYOUTS) + 1}
    details = {s.file: s.detail for s in summary.skips}
    for name, (_, words) in BAD_LAYOUTS.items():
        assert words in details[name]
        assert "not a list" in details[name]
    assert '"categories" is missing' in details["no_categories.json"]
    assert (tmp_path / "out" / "good" / "good_000.obj").is_file()


def _yolo(folder: Path, *, with_image: bool) -> Path:
    (folder / "labels").mkdir(parents=True)
    (folder / "data.yaml").write_text("names: [concrete, brick]\n")
    (folder / "labels" / "img.txt").write_text("1 0.40 0.40 0.60 0.40 0.60 0.60 0.40 0.60\n")
    if with_image:
        (folder / "images").mkdir()
        (folder / "images" / "img.png").write_bytes(png_bytes(200, 100))
    return folder


STRAY = {
    "images_number": '{"images": 3}',
    "numbers": '{"images": 3, "annotations": 5}',
    "nulls": '{"images": null, "annotations": null, "categories": null}',
    "categories_null": '{"images": [], "annotations": [], "categories": null}',
    "list": "[1, 2, 3]",
    "not_json": "these are my notes {",
}


@pytest.mark.parametrize("with_image", [True, False], ids=["images", "no-images"])
@pytest.mark.parametrize("stray", list(STRAY))
def test_stray_json_does_not_win_over_yolo_labels(
    tmp_path: Path, stray: str, with_image: bool
) -> None:
    data = _yolo(tmp_path / "data", with_image=with_image)
    (data / "notes.json").write_text(STRAY[stray], encoding="utf-8")
    config = MeshgenConfig(image_size_px=None if with_image else (200, 100))
    assert discover(data, "auto", config.image_size_px).fmt == "yolo"
    summary = mesh_dataset(data, tmp_path / "out", config)
    assert (summary.fmt, summary.images, summary.objects) == ("yolo", 1, 1)
    assert summary.skips == ()


def test_unknown_image_id_is_skipped_with_a_warning_and_counted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / "data"
    doc = _coco("img", annotations=[_annotation(1, 1), _annotation(2, 99), _annotation(3, 1)])
    _write(data, "instances.json", doc)
    assert main(["meshgen", str(data), "--out", str(tmp_path / "out"), "--json"]) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert summary["objects"] == 2
    assert summary["skipped"] == {"unknown_image_id": 1}
    assert summary["skips"][0]["where"] == "annotations[1]"
    assert "99" in summary["skips"][0]["detail"]
    assert "instances.json:annotations[1]: skipped (unknown_image_id)" in captured.err


def test_duplicate_image_id_skips_that_file_and_the_rest_is_meshed(tmp_path: Path) -> None:
    data = tmp_path / "data"
    _write(data, "dup.json", _coco("a", images=[_image(1, "a"), _image(2, "b"), _image(1, "c")]))
    _write(data, "good.json", _coco("good"))
    summary = mesh_dataset(data, tmp_path / "out", MeshgenConfig())
    assert (summary.images, summary.objects) == (1, 1)
    assert summary.skipped == {"duplicate_image_id": 1}
    (skip,) = summary.skips
    assert (skip.file, skip.where) == ("dup.json", "images[2]")
    assert "image id 1" in skip.detail
    assert "images[0]" in skip.detail
    assert sorted(p.name for p in (tmp_path / "out").iterdir() if p.is_dir()) == ["good"]
