"""The same polygons as YOLO, COCO and labelme give the same meshes; auto-detection works."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from meshgen.config import MeshgenConfig
from meshgen.errors import DatasetError
from meshgen.imagesize import read_image_size
from meshgen.loaders import discover
from meshgen.pipeline import mesh_dataset

NAMES = ("concrete", "brick", "wood", "rubber")


def _read_yolo(sample: Path) -> dict[str, tuple[tuple[int, int], list[tuple[int, list[float]]]]]:
    images = {}
    for label in sorted((sample / "labels").glob("*.txt")):
        size = read_image_size(sample / "images" / f"{label.stem}.jpg")
        assert size is not None
        polys = []
        for line in label.read_text().splitlines():
            cls, *coords = line.split()
            pts = [float(v) * size[i % 2] for i, v in enumerate(coords)]
            polys.append((int(cls), pts))
        images[label.stem] = (size, polys)
    return images


def _write_labelme(images: dict, root: Path) -> None:  # type: ignore[type-arg]
    (root / "labelme").mkdir(parents=True)
    for stem, ((w, h), polys) in images.items():
        shapes = [
            {
                "label": NAMES[c],
                "points": [pts[i : i + 2] for i in range(0, len(pts), 2)],
                "shape_type": "polygon",
                "group_id": None,
                "flags": {},
            }
            for c, pts in polys
        ]
        doc = {
            "version": "5.0",
            "shapes": shapes,
            "imagePath": f"../images/{stem}.jpg",
            "imageData": None,
            "imageWidth": w,
            "imageHeight": h,
        }
        (root / "labelme" / f"{stem}.json").write_text(json.dumps(doc))


def _write_coco(images: dict, root: Path) -> None:  # type: ignore[type-arg]
    root.mkdir(parents=True)
    doc: dict[str, list[dict[str, object]]] = {
        "images": [],
        "annotations": [],
        "categories": [{"id": i + 1, "name": n} for i, n in enumerate(NAMES)],
    }
    for image_id, (stem, ((w, h), polys)) in enumerate(images.items(), start=1):
        doc["images"].append({"id": image_id, "file_name": f"{stem}.jpg", "width": w, "height": h})
        for c, pts in polys:
            doc["annotations"].append(
                {
                    "id": len(doc["annotations"]) + 1,
                    "image_id": image_id,
                    "category_id": c + 1,
                    "segmentation": [pts],
                    "iscrowd": 0,
                }
            )
    (root / "instances.json").write_text(json.dumps(doc))


def _files(out: Path, pattern: str) -> dict[str, bytes]:
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob(pattern))}


def test_yolo_coco_labelme_give_same_meshes(sample_dir: Path, tmp_path: Path) -> None:
    """All three formats find their photos (YOLO images/, labelme imagePath, COCO file_name)
    and give the same meshes and textures."""
    images = _read_yolo(sample_dir)
    _write_labelme(images, tmp_path / "lm")
    _write_coco(images, tmp_path / "coco")
    for folder in ("lm", "coco"):
        shutil.copytree(sample_dir / "images", tmp_path / folder / "images")
    results = {}
    textures = {}
    for fmt, data in (
        ("yolo", sample_dir),
        ("labelme", tmp_path / "lm"),
        ("coco", tmp_path / "coco"),
    ):
        assert discover(data).fmt == fmt
        summary = mesh_dataset(data, tmp_path / f"out_{fmt}", MeshgenConfig())
        assert summary.fmt == fmt
        assert summary.notices == ()
        assert dict(summary.textures) == {"photo": summary.images}
        results[fmt] = _files(summary.out, "*.obj")
        textures[fmt] = _files(summary.out, "texture.jpg")
    assert results["yolo"]
    assert results["yolo"] == results["labelme"] == results["coco"]
    assert len(textures["yolo"]) == len(images)
    assert textures["yolo"] == textures["labelme"] == textures["coco"]


def test_sizes_are_read_per_image(sample_dir: Path) -> None:
    sizes = {s.size_px for s in discover(sample_dir).sources}
    assert sizes == {(1024, 960), (990, 990)}


def test_unknown_format_and_empty_dataset(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="no annotations found"):
        discover(tmp_path)
    with pytest.raises(DatasetError, match="unknown format 'voc'"):
        discover(tmp_path, "voc")


BOM = "\ufeff"
SQUARE_YOLO = "1 0.40 0.40 0.60 0.40 0.60 0.60 0.40 0.60"


def test_yolo_label_with_a_byte_order_mark_keeps_its_first_object(tmp_path: Path) -> None:
    data = tmp_path / "data"
    (data / "labels").mkdir(parents=True)
    (data / "data.yaml").write_text("names: [concrete, brick]\n")
    (data / "labels" / "img.txt").write_text(
        f"{BOM}{SQUARE_YOLO}\n{SQUARE_YOLO.replace('0.60', '0.55')}\n", encoding="utf-8"
    )
    summary = mesh_dataset(data, tmp_path / "out", MeshgenConfig(image_size_px=(200, 100)))
    assert summary.skips == ()
    assert summary.objects == 2
    assert (tmp_path / "out" / "img" / "img_000.obj").is_file()


def _labelme_doc() -> str:
    shape = {"label": "brick", "points": [[80, 40], [120, 40], [120, 60], [80, 60]]}
    return json.dumps({"shapes": [shape], "imageWidth": 200, "imageHeight": 100})


@pytest.mark.parametrize("route", ["orjson", "json"])
@pytest.mark.parametrize("fmt", ["labelme", "coco"])
def test_json_with_a_byte_order_mark_is_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fmt: str, route: str
) -> None:
    from meshgen import jsondoc, loaders

    if route == "json":  # the standard route, taken when orjson would not give json's result
        monkeypatch.setattr(loaders, "loads_exact", lambda data: jsondoc.NOT_DECODED)
    data = tmp_path / "data"
    if fmt == "labelme":
        (data / "labelme").mkdir(parents=True)
        (data / "labelme" / "img.json").write_text(BOM + _labelme_doc(), encoding="utf-8")
    else:
        data.mkdir()
        doc = {
            "images": [{"id": 1, "file_name": "img.png", "width": 200, "height": 100}],
            "annotations": [
                {
                    "id": 1,
                    "image_id": 1,
                    "category_id": 1,
                    "segmentation": [[80, 40, 120, 40, 120, 60]],
                }
            ],
            "categories": [{"id": 1, "name": "brick"}],
        }
        (data / "instances.json").write_text(BOM + json.dumps(doc), encoding="utf-8")
    summary = mesh_dataset(data, tmp_path / "out", MeshgenConfig())
    assert summary.fmt == fmt
    assert summary.skips == ()
    assert (summary.images, summary.objects) == (1, 1)
