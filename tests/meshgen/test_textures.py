"""Every piece is textured: uv of its photo's pixels, one texture per photo, else procedural."""

from __future__ import annotations

import base64
import csv
import io
import json
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
from conftest import write_yolo
from PIL import Image

from interfaces.class_colours import CLASS_RGB
from meshgen.config import MeshgenConfig
from meshgen.imageframe import uv_to_pixels
from meshgen.loaders import discover, load_source
from meshgen.objfile import read_obj
from meshgen.pipeline import DatasetSummary, mesh_dataset
from meshgen.textures import TEXTURE_NAME

SIZE = (1000, 800)
"""Width and height of the test photos, px."""
# (class id, pixel polygon): a triangle, a square, an L (concave: it has convex pieces)
PIECES: list[tuple[int, list[tuple[float, float]]]] = [
    (0, [(100.5, 100.25), (300.0, 120.0), (180.0, 320.75)]),
    (1, [(500.0, 200.0), (700.0, 200.0), (700.0, 400.0), (500.0, 400.0)]),
    (2, [(200, 500), (600, 500), (600, 560), (260, 560), (260, 700), (200, 700)]),
]
INSIDE_PX = [(190.0, 180.0), (600.0, 300.0), (230.0, 600.0)]
"""A pixel well inside each of :data:`PIECES`."""


def _photo(size: tuple[int, int] = SIZE, seed: int = 0) -> Image.Image:
    """A photo of smooth gradients (so that JPEG keeps its pixels within a few levels)."""
    width, height = size
    v, u = np.mgrid[0:height, 0:width]
    rgb = np.stack(
        (255 * u / width, 255 * v / height, 128 + 60 * np.sin(u / 97.0 + v / 53.0 + seed)), axis=2
    )
    return Image.fromarray(rgb.astype(np.uint8), mode="RGB")


def _save(image: Image.Image, path: Path, fmt: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    image.save(path, format=fmt, **({"quality": 95} if fmt == "JPEG" else {}))
    return path


def _yolo(folder: Path, stems: Sequence[str], photo: str | None = "jpg") -> Path:
    write_yolo(folder, dict.fromkeys(stems, PIECES), size_px=SIZE)
    if photo is not None:
        for k, stem in enumerate(stems):
            fmt = "JPEG" if photo == "jpg" else photo.upper()
            _save(_photo(seed=k), folder / "images" / f"{stem}.{photo}", fmt)
    return folder


def _rows(out: Path, stem: str) -> list[dict[str, str]]:
    with (out / stem / "scene.csv").open(encoding="utf-8", newline="") as handle:
        return list(csv.DictReader(handle))


def _pixels(path: Path) -> np.ndarray:
    with Image.open(path) as image:
        return np.asarray(image.convert("RGB"), dtype=np.float64)


def _mesh(data: Path, out: Path, **config: object) -> DatasetSummary:
    return mesh_dataset(data, out, MeshgenConfig(simplify_mm=0.0, **config))  # type: ignore[arg-type]


def test_top_vertex_uv_maps_back_to_its_polygon_pixel(tmp_path: Path) -> None:
    out = _mesh(_yolo(tmp_path / "data", ["img"]), tmp_path / "out").out
    rows = _rows(out, "img")
    assert len(rows) == len(PIECES)
    for row in rows:
        mesh = read_obj(out / "img" / row["mesh_path"])
        assert mesh.uv is not None
        assert mesh.uv.shape == (len(mesh.vertices), 2)
        n = len(mesh.vertices) // 2
        top = mesh.vertices[:, 2] > 0.0
        assert top.sum() == n
        index = int(row["object_id"].rsplit("_", 1)[1])
        polygon = np.array(PIECES[index][1], dtype=np.float64)
        # each top vertex's uv is the pixel of one of its polygon's points (the labels hold
        # them to 6 decimals of the normalised coordinates: 1e-3 px)
        found = uv_to_pixels(mesh.uv[top], *SIZE)
        distance = np.linalg.norm(found[:, None, :] - polygon[None, :, :], axis=2).min(axis=1)
        assert distance.max() < 2e-3
        assert len(found) == len(polygon)
        # a side or bottom vertex takes the uv of the outline vertex it is extruded from
        np.testing.assert_array_equal(mesh.uv[:n], mesh.uv[n:])
        np.testing.assert_array_equal(mesh.vertices[:n, :2], mesh.vertices[n:, :2])


def test_texture_is_written_once_per_photo_and_carries_its_pixels(tmp_path: Path) -> None:
    data = _yolo(tmp_path / "data", ["a", "b"], photo="png")
    summary = _mesh(data, tmp_path / "out")
    out = summary.out
    assert dict(summary.textures) == {"photo": 2}
    assert summary.notices == ()
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*.jpg")) == [
        f"a/{TEXTURE_NAME}",
        f"b/{TEXTURE_NAME}",
    ]
    for k, stem in enumerate(["a", "b"]):
        rows = _rows(out, stem)
        assert {row["texture_path"] for row in rows} == {TEXTURE_NAME}
        texture = _pixels(out / stem / TEXTURE_NAME)
        photo = np.asarray(_photo(seed=k), dtype=np.float64)
        assert texture.shape == photo.shape
        assert np.abs(texture - photo).mean() < 2.0  # the PNG re-encoded as a JPEG
        entry = json.loads((out / stem / "scene.json").read_text())["texture"]
        assert entry == {
            "path": TEXTURE_NAME,
            "source": "photo",
            "photo": f"images/{stem}.png",
            "width_px": SIZE[0],
            "height_px": SIZE[1],
        }


def test_a_jpeg_photo_within_the_bound_is_copied_and_a_larger_one_downscaled(
    tmp_path: Path,
) -> None:
    data = _yolo(tmp_path / "data", ["small"])
    summary = _mesh(data, tmp_path / "out")
    texture = summary.out / "small" / TEXTURE_NAME
    assert texture.read_bytes() == (data / "images" / "small.jpg").read_bytes()
    big = (2400, 1920)
    write_yolo(tmp_path / "big", {"big": PIECES}, size_px=big)
    _save(_photo(big), tmp_path / "big" / "images" / "big.jpg", "JPEG")
    summary = _mesh(tmp_path / "big", tmp_path / "out_big")
    with Image.open(summary.out / "big" / TEXTURE_NAME) as image:
        assert image.size == (1024, 819)
        assert image.mode == "RGB"
    # the uv are normalised: a uv's pixel in the texture shows the photo's pixel there
    rows = _rows(summary.out, "big")
    mesh = read_obj(summary.out / "big" / rows[1]["mesh_path"])
    assert mesh.uv is not None
    corner = uv_to_pixels(mesh.uv[:1], 1024, 819)[0]
    want = uv_to_pixels(mesh.uv[:1], *big)[0]
    shown = _pixels(summary.out / "big" / TEXTURE_NAME)[int(corner[1]), int(corner[0])]
    photo = np.asarray(_photo(big), dtype=np.float64)[int(want[1]), int(want[0])]
    assert np.abs(shown - photo).max() < 12.0


def test_textured_geometry_equals_untextured(tmp_path: Path) -> None:
    data = _yolo(tmp_path / "data", ["img"])
    textured = _mesh(data, tmp_path / "tex").out
    plain = _mesh(data, tmp_path / "plain", textures=False).out
    assert not list(plain.rglob("*.jpg"))
    assert {row["texture_path"] for row in _rows(plain, "img")} == {""}
    meshes = sorted(p.relative_to(textured) for p in textured.rglob("*.obj"))
    assert meshes == sorted(p.relative_to(plain) for p in plain.rglob("*.obj"))
    assert any(p.name.endswith("_convex.obj") for p in meshes)
    for relative in meshes:
        a, b = read_obj(textured / relative), read_obj(plain / relative)
        np.testing.assert_array_equal(a.vertices, b.vertices)
        np.testing.assert_array_equal(a.faces, b.faces)
        assert a.groups == b.groups
        assert b.uv is None
        assert (a.uv is None) == relative.name.endswith("_convex.obj")
        # the same file otherwise: without its vt lines and the /t of each corner
        text = (textured / relative).read_text()
        stripped = re.sub(r"(\d+)/\1\b", r"\1", re.sub(r"(?m)^vt .*\n", "", text))
        assert stripped == (plain / relative).read_text()


def _labelme(folder: Path, stem: str, *, image_data: str | None, image_path: str) -> Path:
    shapes = [
        {"label": ["concrete", "brick", "wood"][c], "points": [list(p) for p in pts]}
        for c, pts in PIECES
    ]
    doc = {
        "shapes": shapes,
        "imagePath": image_path,
        "imageData": image_data,
        "imageWidth": SIZE[0],
        "imageHeight": SIZE[1],
    }
    (folder / "labelme").mkdir(parents=True, exist_ok=True)
    (folder / "labelme" / f"{stem}.json").write_text(json.dumps(doc), encoding="utf-8")
    return folder


def test_labelme_image_data_is_the_photo(tmp_path: Path) -> None:
    buffer = io.BytesIO()
    _photo(seed=3).save(buffer, format="PNG")
    data = _labelme(
        tmp_path / "data",
        "emb",
        image_data=base64.b64encode(buffer.getvalue()).decode("ascii"),
        image_path="gone.png",
    )
    summary = _mesh(data, tmp_path / "out")
    assert summary.fmt == "labelme"
    assert dict(summary.textures) == {"photo": 1}
    entry = json.loads((summary.out / "emb" / "scene.json").read_text())["texture"]
    assert entry["photo"] == "labelme/emb.json imageData"
    texture = _pixels(summary.out / "emb" / TEXTURE_NAME)
    assert np.abs(texture - np.asarray(_photo(seed=3), dtype=np.float64)).mean() < 2.0


def test_a_missing_photo_gives_a_procedural_texture_and_a_warning(tmp_path: Path) -> None:
    data = _yolo(tmp_path / "data", ["img"], photo=None)
    summary = mesh_dataset(data, tmp_path / "out", MeshgenConfig(image_size_px=SIZE))
    assert summary.warned == {"photo_missing": 1}
    (notice,) = summary.notices
    assert notice.file == "labels/img.txt"
    assert "images/<stem>.*" in notice.detail
    report = summary.to_json()
    assert report["warned"] == {"photo_missing": 1}
    assert report["textures"] == {"procedural": 1}
    assert report["warnings"][0]["reason"] == "photo_missing"
    scene = json.loads((summary.out / "img" / "scene.json").read_text())
    assert scene["texture"]["source"] == "procedural"
    assert scene["warnings"][0]["reason"] == "photo_missing"
    texture = _pixels(summary.out / "img" / TEXTURE_NAME)
    height, width = texture.shape[:2]
    assert max(width, height) == 512
    # the texture shows each piece's class colour inside it, the (dark) belt outside
    scale = width / SIZE[0]
    for row in _rows(summary.out, "img"):
        index = int(row["object_id"].rsplit("_", 1)[1])
        u, v = (round(c * scale) for c in INSIDE_PX[index])
        window = texture[v - 2 : v + 3, u - 2 : u + 3].reshape(-1, 3)
        colour = 255.0 * np.array(CLASS_RGB[row["class_name"]])
        assert np.abs(window.mean(axis=0) - colour).max() < 40.0, row["class_name"]
    assert texture[5:20, 5:20].mean() < 60.0
    again = mesh_dataset(data, tmp_path / "again", MeshgenConfig(image_size_px=SIZE))
    same = (again.out / "img" / TEXTURE_NAME).read_bytes()
    assert same == (summary.out / "img" / TEXTURE_NAME).read_bytes()
    other = mesh_dataset(data, tmp_path / "other", MeshgenConfig(image_size_px=SIZE, seed=1))
    assert (other.out / "img" / TEXTURE_NAME).read_bytes() != same


def test_an_unusable_photo_falls_back_to_procedural_with_its_reason(tmp_path: Path) -> None:
    # labelme: the size is the document's; the embedded photo of one file is smaller, the
    # other file's photo (images/<stem>.jpg, its imagePath missing) is not an image at all
    small = io.BytesIO()
    _photo((640, 480)).save(small, format="PNG")
    data = _labelme(
        tmp_path / "data",
        "wrong",
        image_data=base64.b64encode(small.getvalue()).decode("ascii"),
        image_path="",
    )
    _labelme(data, "broken", image_data=None, image_path="nowhere/broken.png")
    (data / "images").mkdir()
    (data / "images" / "broken.jpg").write_bytes(b"\xff\xd8\xff\xe0 not really a JPEG")
    summary = mesh_dataset(data, tmp_path / "out", MeshgenConfig())
    reasons = {n.file: n.reason for n in summary.notices}
    assert reasons == {
        "labelme/broken.json": "photo_unreadable",
        "labelme/wrong.json": "photo_size_mismatch",
    }
    detail = next(n.detail for n in summary.notices if n.file == "labelme/wrong.json")
    assert "640x480" in detail
    assert "1000x800" in detail
    assert dict(summary.textures) == {"procedural": 2}
    assert summary.objects == 2 * len(PIECES)  # the meshes are written all the same
    for stem in ("wrong", "broken"):
        assert (summary.out / stem / TEXTURE_NAME).is_file()


def test_coco_file_name_finds_the_photo(tmp_path: Path) -> None:
    folder = tmp_path / "coco"
    _save(_photo(), folder / "images" / "pic.jpg", "JPEG")
    doc = {
        "images": [{"id": 7, "file_name": "pic.jpg", "width": SIZE[0], "height": SIZE[1]}],
        "annotations": [
            {"id": k, "image_id": 7, "category_id": c, "segmentation": [np.ravel(p).tolist()]}
            for k, (c, p) in enumerate(PIECES)
        ],
        "categories": [{"id": k, "name": n} for k, n in enumerate(("concrete", "brick", "wood"))],
    }
    (folder / "annotations").mkdir()
    (folder / "annotations" / "instances.json").write_text(json.dumps(doc), encoding="utf-8")
    listing = discover(folder)
    assert listing.fmt == "coco"
    ann, _ = load_source(listing.sources[0], folder)
    assert ann is not None
    assert ann.photo is not None
    assert ann.photo.name == "images/pic.jpg"
    summary = mesh_dataset(folder, tmp_path / "out", MeshgenConfig())
    assert dict(summary.textures) == {"photo": 1}


def test_cli_prints_warnings_that_do_not_fail_strict(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from twin.cli import main

    data = _yolo(tmp_path / "data", ["img"], photo=None)
    out = str(tmp_path / "out")
    code = main(["meshgen", str(data), "--out", out, "--image-size", "1000x800", "--strict"])
    captured = capsys.readouterr()
    assert code == 0
    assert "warning: labels/img.txt: photo_missing: no photo for image 'img'" in captured.err
    assert "warned     1  photo_missing" in captured.out


def test_a_jpeg_size_behind_a_large_header_block_is_found(tmp_path: Path) -> None:
    from meshgen.imagesize import read_image_size

    path = tmp_path / "big_header.jpg"
    _photo((64, 48)).save(path, format="JPEG", icc_profile=b"\0" * 100_000)
    assert path.stat().st_size > 100_000
    assert read_image_size(path) == (64, 48)
