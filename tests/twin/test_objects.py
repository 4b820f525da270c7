"""Loading a meshgen output: textures, and no path or mesh the twin should not trust."""

from __future__ import annotations

import csv
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from twin.errors import SceneError
from twin.objects import (
    MAX_MESH_FACES,
    MeshLimits,
    check_mesh_size,
    load_dataset,
    read_mesh,
)

BOXES = {
    "img": [
        (1, [(400, 400), (600, 400), (600, 550), (400, 550)]),
        (2, [(100, 100), (300, 100), (300, 160), (160, 160), (160, 300), (100, 300)]),
    ]
}


def _rewrite(scene: Path, field: str, value: str, row: int = 0) -> None:
    """Set ``field`` of data row ``row`` of a CSV file (adding the column when missing)."""
    with scene.open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    rows[row][field] = value
    with scene.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


@pytest.fixture
def meshes(mesh_polygons: Callable[..., Path]) -> Path:
    """A meshgen output of two pieces (one concave: it has convex pieces)."""
    return mesh_polygons(BOXES)


def test_texture_paths_are_loaded(meshes: Path) -> None:
    (layout,) = load_dataset(meshes)
    for spec in layout.objects:
        assert spec.texture_path == (meshes / "img" / "texture.jpg").resolve()
        assert spec.texture_path.is_file()


def test_outputs_without_the_texture_column_still_load(meshes: Path) -> None:
    scene = meshes / "img" / "scene.csv"
    with scene.open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    fields = [f for f in rows[0] if f not in ("texture_path", "height_source")]
    with scene.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    (layout,) = load_dataset(meshes)
    assert [spec.texture_path for spec in layout.objects] == [None, None]


@pytest.mark.parametrize("field", ["mesh_path", "convex_path", "texture_path"])
def test_a_path_out_of_the_dataset_is_refused(meshes: Path, tmp_path: Path, field: str) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    scene = meshes / "img" / "scene.csv"
    with scene.open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    row = next(i for i, r in enumerate(rows) if r["convex_path"])
    victim = outside / f"victim{Path(rows[row][field]).suffix}"
    shutil.copy(meshes / "img" / rows[row][field], victim)  # a real file: only its place is wrong
    escape = "../" * (len(scene.parent.parts) - 1) + victim.as_posix().lstrip("/")
    _rewrite(scene, field, escape, row)
    line = row + 2
    with pytest.raises(
        SceneError, match=rf"scene\.csv:{line}: field '{field}' = '(\.\./)+.*victim.*outside the"
    ):
        load_dataset(meshes)
    _rewrite(scene, field, str(victim), row)  # an absolute path elsewhere
    with pytest.raises(SceneError, match=rf"scene\.csv:{line}: field '{field}'.*outside the"):
        load_dataset(meshes)


def test_a_symbolic_link_out_of_the_dataset_is_refused(meshes: Path, tmp_path: Path) -> None:
    scene = meshes / "img" / "scene.csv"
    with scene.open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    name = rows[0]["mesh_path"]
    target = tmp_path / "elsewhere.obj"
    shutil.move(meshes / "img" / name, target)
    (meshes / "img" / name).symlink_to(target)
    with pytest.raises(SceneError, match=r"scene\.csv:2: field 'mesh_path' = .*outside the"):
        load_dataset(meshes)
    # a link that stays inside the dataset is fine
    (meshes / "img" / name).unlink()
    shutil.move(target, meshes / "img" / "moved.obj")
    (meshes / "img" / name).symlink_to(meshes / "img" / "moved.obj")
    assert load_dataset(meshes)


def test_a_scene_file_out_of_the_dataset_is_refused(meshes: Path, tmp_path: Path) -> None:
    shutil.copytree(meshes / "img", tmp_path / "stolen")
    _rewrite(meshes / "index.csv", "scene_csv", "../stolen/scene.csv")
    with pytest.raises(SceneError, match=r"index\.csv:2: field 'scene_csv' = .*outside the"):
        load_dataset(meshes)


def test_a_huge_mesh_is_refused_with_its_name_before_it_is_read(meshes: Path) -> None:
    scene = meshes / "img" / "scene.csv"
    with scene.open(newline="", encoding="utf-8") as handle:
        name = next(csv.DictReader(handle))["mesh_path"]
    mesh = meshes / "img" / name
    # 3 vertices and more faces than any mesh may have: short lines, a small file
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n" + "f 1 2 3\n" * (MAX_MESH_FACES + 1))
    with pytest.raises(SceneError, match=rf"{name}: {MAX_MESH_FACES + 1} faces, more than the"):
        load_dataset(meshes)
    with pytest.raises(SceneError, match=rf"{name}: {MAX_MESH_FACES + 1} faces"):
        read_mesh(mesh)
    # one face of millions of corners in a small file: as costly as millions of faces
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf " + "1 2 3 " * 300_000 + "\n")
    with pytest.raises(SceneError, match=rf"{name}: \d+ bytes in 5 lines, more than 256 bytes"):
        load_dataset(meshes)


def test_mesh_limits_are_configurable(meshes: Path) -> None:
    (layout,) = load_dataset(meshes)
    path = layout.objects[0].mesh_path
    vertices = len(read_mesh(path).vertices)
    with pytest.raises(SceneError, match=rf"{path.name}: {vertices} vertices, more than the 4"):
        load_dataset(meshes, mesh_limits=MeshLimits(max_vertices=4))
    small = MeshLimits(max_bytes=100)
    with pytest.raises(SceneError, match=rf"{path.name}: \d+ bytes, more than the 100 .*unread"):
        check_mesh_size(path, small)
    most = max(len(read_mesh(p).vertices) for p in (meshes / "img").glob("*.obj"))
    assert load_dataset(meshes, mesh_limits=MeshLimits(max_vertices=most))
