"""``--heights``: each piece's height from the height image inside its footprint."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import write_yolo
from PIL import Image, ImageDraw

from meshgen.classes import DEFAULT_CLASSES
from meshgen.config import MeshgenConfig
from meshgen.errors import MeshgenError
from meshgen.objfile import read_obj
from meshgen.pipeline import mesh_dataset, object_height_m

SIZE = (1000, 800)
BELT_LEVEL = 3
# (class id, pixel polygon, level painted inside it)
PIECES = [
    (1, [(100.0, 100.0), (300.0, 100.0), (300.0, 260.0), (100.0, 260.0)], 56),
    (2, [(500.0, 300.0), (800.0, 340.0), (700.0, 600.0), (480.0, 520.0)], 21),
    (0, [(150.0, 500.0), (350.0, 520.0), (260.0, 700.0)], 90),
]


def _height_image(path: Path, pieces: list[tuple[int, list[tuple[float, float]], int]]) -> None:
    """An 8-bit height image: the belt at ``BELT_LEVEL`` with noise, each piece at its level
    with noise and a lower rim (the percentile must see through both)."""
    rng = np.random.default_rng(5)
    levels = BELT_LEVEL + rng.integers(-1, 2, (SIZE[1], SIZE[0]))
    image = Image.fromarray(levels.astype(np.uint8), mode="L")
    draw = ImageDraw.Draw(image)
    for _, points, level in pieces:
        draw.polygon(points, fill=level)
    pixels = np.asarray(image).astype(np.int64)
    inside = pixels > BELT_LEVEL + 2
    pixels[inside] += rng.integers(-2, 3, int(inside.sum()))
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(pixels.clip(0, 255).astype(np.uint8), mode="L").save(path)


def _dataset(folder: Path, with_heights: tuple[str, ...] = ("a",)) -> Path:
    labels = {stem: [(c, pts) for c, pts, _ in PIECES] for stem in ("a", "b")}
    write_yolo(folder, labels, size_px=SIZE)
    for stem in with_heights:
        _height_image(folder / "heights" / f"{stem}.png", PIECES)
    return folder


def _rows(out: Path, stem: str) -> list[dict[str, str]]:
    with (out / stem / "scene.csv").open(encoding="utf-8", newline="") as handle:
        return list(csv.DictReader(handle))


def _config(**extra: object) -> MeshgenConfig:
    return MeshgenConfig(image_size_px=SIZE, textures=False, **extra)  # type: ignore[arg-type]


def test_heights_land_near_the_painted_levels(tmp_path: Path) -> None:
    data = _dataset(tmp_path / "data")
    summary = mesh_dataset(data, tmp_path / "out", _config(heights="auto"))
    assert dict(summary.height_sources) == {"image": 3, "sampled": 3}
    for row in _rows(summary.out, "a"):
        index = int(row["object_id"].rsplit("_", 1)[1])
        want_m = 0.001 * (PIECES[index][2] - BELT_LEVEL)
        assert row["height_source"] == "image"
        assert float(row["height_m"]) == pytest.approx(want_m, abs=0.0025)
        mesh = read_obj(summary.out / "a" / row["mesh_path"])
        assert np.ptp(mesh.vertices[:, 2]) == pytest.approx(float(row["height_m"]), abs=2e-6)
        volume = float(row["area_m2"]) * float(row["height_m"])
        assert float(row["volume_m3"]) == pytest.approx(volume, rel=1e-9)
    # image b has no height image: its pieces keep their seeded heights
    for row in _rows(summary.out, "b"):
        index = int(row["object_id"].rsplit("_", 1)[1])
        spec = DEFAULT_CLASSES[row["class_name"]]
        assert row["height_source"] == "sampled"
        assert float(row["height_m"]) == pytest.approx(object_height_m(0, "b", index, spec))
    entry = json.loads((summary.out / "a" / "scene.json").read_text())["objects"][0]
    assert entry["height_source"] == "image"
    config = summary.to_json()["config"]
    assert (config["heights"], config["height_scale_m"], config["height_percentile"]) == (
        "auto",
        0.001,
        90.0,
    )


def test_the_scale_and_a_folder_are_configurable(tmp_path: Path) -> None:
    data = _dataset(tmp_path / "data", with_heights=())
    _height_image(tmp_path / "elsewhere" / "deep" / "b.png", PIECES)
    config = _config(heights=str(tmp_path / "elsewhere"), height_scale_m=0.002)
    summary = mesh_dataset(data, tmp_path / "out", config)
    rows = {r["object_id"]: r for r in _rows(summary.out, "b")}
    square = rows["b_000"]
    assert square["height_source"] == "image"
    assert float(square["height_m"]) == pytest.approx(0.002 * (56 - BELT_LEVEL), abs=0.005)
    assert {r["height_source"] for r in _rows(summary.out, "a")} == {"sampled"}


def test_off_by_default_even_with_a_heights_folder(tmp_path: Path) -> None:
    data = _dataset(tmp_path / "data")
    summary = mesh_dataset(data, tmp_path / "out", _config())
    assert dict(summary.height_sources) == {"sampled": 6}
    for row in _rows(summary.out, "a"):
        index = int(row["object_id"].rsplit("_", 1)[1])
        spec = DEFAULT_CLASSES[row["class_name"]]
        assert float(row["height_m"]) == pytest.approx(object_height_m(0, "a", index, spec))


def test_unusable_height_images_and_flat_pieces_keep_sampled_heights(tmp_path: Path) -> None:
    data = _dataset(tmp_path / "data", with_heights=("b",))
    Image.new("L", (10, 10), 0).save(data / "heights" / "a.png")
    flat = [(c, pts, level if c != 0 else BELT_LEVEL) for c, pts, level in PIECES]
    _height_image(data / "heights" / "b.png", flat)
    summary = mesh_dataset(data, tmp_path / "out", _config(heights="auto"))
    reasons = sorted((n.file, n.where, n.reason) for n in summary.notices)
    assert reasons == [
        ("labels/a.txt", "", "height_image_size_mismatch"),
        ("labels/b.txt", "line 3", "height_not_above_belt"),
    ]
    assert {r["height_source"] for r in _rows(summary.out, "a")} == {"sampled"}
    sources = {r["object_id"]: r["height_source"] for r in _rows(summary.out, "b")}
    assert sources == {"b_000": "image", "b_001": "image", "b_002": "sampled"}
    assert summary.objects == 6


def test_a_heights_folder_that_does_not_exist_is_refused(tmp_path: Path) -> None:
    data = _dataset(tmp_path / "data")
    with pytest.raises(MeshgenError, match=r"--heights: '.*nowhere' is not a folder"):
        mesh_dataset(data, tmp_path / "out", _config(heights=str(tmp_path / "nowhere")))
    with pytest.raises(MeshgenError, match="--height-scale-m"):
        _config(height_scale_m=0.0)


def test_real_sample_heights_from_its_height_images(tmp_path: Path, real_sample: Path) -> None:
    summary = mesh_dataset(
        real_sample, tmp_path / "out", MeshgenConfig(heights="auto", textures=False)
    )
    sources = dict(summary.height_sources)
    assert sources["image"] > 40  # the pieces of the 18 images with a height image
    heights: dict[str, list[float]] = {}
    for scene in sorted(summary.out.glob("*/scene.csv")):
        for row in _rows(summary.out, scene.parent.name):
            measured = row["height_source"] == "image"
            assert measured == scene.parent.name.startswith(("Aauto", "Bauto"))
            if measured:
                heights.setdefault(row["class_name"], []).append(float(row["height_m"]))
    # bricks lie flat at about 45 mm (two stacked about twice that), wood boards about 20 mm
    assert 0.035 < float(np.median(heights["brick"])) < 0.06
    assert 0.012 < float(np.median(heights["wood"])) < 0.03
    assert max(max(v) for v in heights.values()) < 0.2
