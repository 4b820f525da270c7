"""The built-in sample's photos: its pieces drawn on a dark belt, labels and meshes unchanged."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from interfaces.class_colours import CLASS_RGB
from meshgen.config import MeshgenConfig
from meshgen.objfile import read_obj
from meshgen.pipeline import DatasetSummary, mesh_dataset
from meshgen.sample import SIZES_PX, label_text, png_bytes, sample_labels
from meshgen.textures import TEXTURE_NAME

IMAGES = 8
SEED = 3


def test_labels_are_those_the_label_function_gives(sample_dir: Path) -> None:
    labels = sample_labels(IMAGES, SEED)
    written = sorted((sample_dir / "labels").glob("*.txt"))
    assert [p.stem for p in written] == [f"sample_{i:03d}" for i in range(IMAGES)]
    for path, objects in zip(written, labels, strict=True):
        assert path.read_text(encoding="utf-8") == label_text(objects)
        for label, line in zip(objects, path.read_text().splitlines(), strict=True):
            # each line is its polygon, normalised by its image's size
            values = np.array(line.split()[1:], dtype=np.float64).reshape(-1, 2)
            size = np.array(SIZES_PX[int(path.stem[-3:]) % len(SIZES_PX)])
            np.testing.assert_allclose(values * size, label.points_px, atol=1e-6 * size.max())


def _inside(points: np.ndarray, size: tuple[int, int], shrink: int) -> np.ndarray:
    """``(h, w) bool``: pixels at least ``shrink`` px inside the polygon (a negative ``shrink``
    grows it by that much)."""
    mask = Image.new("L", size, 0)
    outline = [(float(u), float(v)) for u, v in points.tolist()]
    draw = ImageDraw.Draw(mask)
    draw.polygon(outline, fill=255)
    if shrink < 0:
        draw.line([*outline, outline[0]], fill=255, width=1 - 2 * shrink)
    inside = np.asarray(mask) > 0
    for _ in range(shrink):
        inside = inside & np.roll(inside, 1, 0) & np.roll(inside, -1, 0)
        inside = inside & np.roll(inside, 1, 1) & np.roll(inside, -1, 1)
    return inside


def test_photos_show_every_piece_in_its_class_colour_on_a_dark_belt(sample_dir: Path) -> None:
    labels = sample_labels(IMAGES, SEED)
    for i, objects in enumerate(labels):
        with Image.open(sample_dir / "images" / f"sample_{i:03d}.jpg") as image:
            assert image.format == "JPEG"
            assert image.mode == "RGB"
            assert image.size == SIZES_PX[i % len(SIZES_PX)]
            pixels = np.asarray(image, dtype=np.float64)
        covered = np.zeros(pixels.shape[:2], dtype=bool)
        for k, label in enumerate(objects):
            inside = _inside(label.points_px, image.size, 3)
            later = np.zeros_like(inside)  # pieces painted after this one cover it
            for other in objects[k + 1 :]:
                later |= _inside(other.points_px, image.size, 0)
            visible = inside & ~later
            if visible.sum() < 50:
                continue
            mean = pixels[visible].mean(axis=0)
            colour = 255.0 * np.array(CLASS_RGB[label.class_name])
            assert np.abs(mean - colour).max() < 30.0, (i, k, label.class_name, mean)
        for label in objects:
            covered |= _inside(label.points_px, image.size, -4)
        belt = pixels[~covered]
        assert belt.mean() < 60.0  # the belt is dark
        assert belt.std() < 10.0


def _geometry(out: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    meshes = {}
    for path in sorted(out.rglob("*.obj")):
        mesh = read_obj(path)
        meshes[path.relative_to(out).as_posix()] = (mesh.vertices, mesh.faces)
    return meshes


def test_meshes_do_not_depend_on_the_photos(
    sample_dir: Path, meshed: DatasetSummary, tmp_path: Path
) -> None:
    # meshgen textures the sample's pieces from the sample's own photos
    assert dict(meshed.textures) == {"photo": meshed.images}
    assert meshed.notices == ()
    for folder in meshed.out.iterdir():
        if folder.is_dir():
            texture = folder / TEXTURE_NAME
            assert (
                texture.read_bytes() == (sample_dir / "images" / f"{folder.name}.jpg").read_bytes()
            )
    # the same labels with flat grey images of the same sizes give the same meshes
    grey = tmp_path / "grey"
    (grey / "images").mkdir(parents=True)
    (grey / "labels").mkdir()
    (grey / "data.yaml").write_bytes((sample_dir / "data.yaml").read_bytes())
    for label in sorted((sample_dir / "labels").glob("*.txt")):
        (grey / "labels" / label.name).write_bytes(label.read_bytes())
        with Image.open(sample_dir / "images" / f"{label.stem}.jpg") as image:
            size = image.size
        (grey / "images" / f"{label.stem}.png").write_bytes(png_bytes(*size))
    plain = mesh_dataset(grey, tmp_path / "out", MeshgenConfig(seed=7))
    want, got = _geometry(meshed.out), _geometry(plain.out)
    assert want.keys() == got.keys()
    assert want
    for name, (vertices, faces) in want.items():
        np.testing.assert_array_equal(got[name][0], vertices)
        np.testing.assert_array_equal(got[name][1], faces)


def test_without_photos_the_labels_are_the_same(sample_dir: Path, tmp_path: Path) -> None:
    from meshgen.sample import write_sample

    write_sample(tmp_path / "flat", images=IMAGES, seed=SEED, photos=False)
    for label in sorted((sample_dir / "labels").glob("*.txt")):
        assert (tmp_path / "flat" / "labels" / label.name).read_bytes() == label.read_bytes()
        with Image.open(tmp_path / "flat" / "images" / f"{label.stem}.png") as image:
            assert image.size == SIZES_PX[int(label.stem[-3:]) % len(SIZES_PX)]
    assert not list((tmp_path / "flat" / "images").glob("*.jpg"))
