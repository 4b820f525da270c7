"""Invariants of every generated mesh, convex decomposition and scene record."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
import shapely
import trimesh

from meshgen.export import INDEX_COLUMNS, SCENE_COLUMNS
from meshgen.pipeline import DatasetSummary
from tests.meshgen.reference_text import obj_meshes


def _scenes(out: Path) -> list[tuple[Path, dict[str, object]]]:
    scenes = []
    with (out / "index.csv").open() as fh:
        for row in csv.DictReader(fh):
            scene_csv = out / row["scene_csv"]
            data = json.loads((scene_csv.parent / "scene.json").read_text())
            scenes.append((scene_csv.parent, data))
    return scenes


def test_layout_and_columns(meshed: DatasetSummary) -> None:
    out = meshed.out
    assert meshed.objects > 0
    assert (out / "materials.mtl").read_text().count("newmtl") == 4
    with (out / "index.csv").open() as fh:
        reader = csv.reader(fh)
        assert tuple(next(reader)) == INDEX_COLUMNS
        rows = list(reader)
    assert len(rows) == meshed.images
    total = 0
    for row in rows:
        scene = out / row[-1]
        with scene.open() as fh:
            reader = csv.reader(fh)
            assert tuple(next(reader)) == SCENE_COLUMNS
            records = list(reader)
        assert len(records) == int(row[4])
        total += len(records)
        for rec in records:
            assert (scene.parent / rec[SCENE_COLUMNS.index("mesh_path")]).is_file()
    assert total == meshed.objects
    assert json.loads((out / "summary.json").read_text())["objects"] == meshed.objects


def test_every_mesh_is_a_correct_prism(meshed: DatasetSummary) -> None:
    checked = 0
    for folder, scene in _scenes(meshed.out):
        for obj in scene["objects"]:  # type: ignore[attr-defined]
            mesh = trimesh.load(folder / obj["mesh_path"], force="mesh", process=False)
            mesh.merge_vertices()
            footprint = shapely.Polygon(obj["footprint_m"])
            height = obj["height_m"]
            assert footprint.is_valid
            assert mesh.is_watertight
            assert mesh.is_winding_consistent
            assert mesh.volume > 0
            assert math.isclose(obj["area_m2"], footprint.area, rel_tol=1e-6)
            assert math.isclose(mesh.volume, obj["area_m2"] * height, rel_tol=1e-3)
            assert math.isclose(obj["volume_m3"], obj["area_m2"] * height, rel_tol=1e-12)
            assert math.isclose(obj["mass_kg"], obj["volume_m3"] * obj["density_kg_m3"])
            assert np.allclose(mesh.center_mass, 0.0, atol=2e-6)
            cx, cy = obj["centroid_x_m"], obj["centroid_y_m"]
            minx, miny, maxx, maxy = footprint.bounds
            expected = np.array(
                [[minx - cx, miny - cy, -height / 2], [maxx - cx, maxy - cy, height / 2]]
            )
            assert np.allclose(mesh.bounds, expected, atol=2e-6)
            assert obj["length_m"] >= obj["width_m"] > 0
            assert -math.pi / 2 < obj["yaw_rad"] <= math.pi / 2
            checked += 1
    assert checked == meshed.objects


def test_convex_pieces_are_convex_and_tile_the_footprint(meshed: DatasetSummary) -> None:
    concave = 0
    for folder, scene in _scenes(meshed.out):
        for obj in scene["objects"]:  # type: ignore[attr-defined]
            footprint = shapely.Polygon(obj["footprint_m"])
            cx, cy = obj["centroid_x_m"], obj["centroid_y_m"]
            if not obj["convex_path"]:
                assert math.isclose(footprint.convex_hull.area, footprint.area, rel_tol=1e-6)
                continue
            concave += 1
            pieces = obj_meshes((folder / obj["convex_path"]).read_text())
            assert len(pieces) == obj["n_convex_pieces"] >= 2
            shapes = []
            for piece in pieces:
                piece.merge_vertices()
                assert piece.is_watertight
                assert piece.is_convex
                top = piece.vertices[piece.vertices[:, 2] > 0][:, :2] + (cx, cy)
                shapes.append(shapely.MultiPoint(top).convex_hull)
            union = shapely.union_all(shapes)
            assert math.isclose(sum(s.area for s in shapes), footprint.area, rel_tol=1e-4)
            assert union.symmetric_difference(footprint).area < 1e-4 * footprint.area
    assert concave > 0


@pytest.mark.parametrize("up", ["z", "y"])
def test_up_axis(sample_dir: Path, tmp_path: Path, up: str) -> None:
    from meshgen.config import MeshgenConfig
    from meshgen.pipeline import mesh_dataset

    summary = mesh_dataset(sample_dir, tmp_path / "out", MeshgenConfig(up=up))
    folder, scene = _scenes(summary.out)[0]
    obj = scene["objects"][0]  # type: ignore[index]
    mesh = trimesh.load(folder / obj["mesh_path"], force="mesh", process=False)
    half = obj["height_m"] / 2
    axis = 2 if up == "z" else 1
    assert np.allclose([mesh.bounds[0, axis], mesh.bounds[1, axis]], [-half, half], atol=2e-6)
    assert mesh.volume > 0
