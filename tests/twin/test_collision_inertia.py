"""Collision-piece merging and mesh inertia: geometric invariants, and agreement with trimesh."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import shapely

from twin.collision import merge_pieces, merged_collision_file, pieces_obj_text, read_pieces
from twin.errors import SceneError
from twin.objects import read_obj_triangles, unit_mass_inertia


def _prism(ring: list[tuple[float, float]], z_lo: float = -0.01, z_hi: float = 0.01) -> np.ndarray:
    xy = np.asarray(ring, dtype=float)
    return np.vstack(
        [
            np.column_stack([xy, np.full(len(xy), z_lo)]),
            np.column_stack([xy, np.full(len(xy), z_hi)]),
        ]
    )


def _footprint(piece: np.ndarray) -> shapely.Polygon:
    return shapely.Polygon(piece[: len(piece) // 2, :2])


# An L of two 10 cm x 2 cm arms, plus two 1 mm slivers along the outer edge of the long arm.
L_PIECES = [
    _prism([(0.0, 0.0), (0.10, 0.0), (0.10, 0.02), (0.0, 0.02)]),
    _prism([(0.0, 0.02), (0.02, 0.02), (0.02, 0.10), (0.0, 0.10)]),
    _prism([(0.0, -0.001), (0.05, -0.001), (0.05, 0.0), (0.0, 0.0)]),
    _prism([(0.05, -0.001), (0.10, -0.001), (0.10, 0.0), (0.05, 0.0)]),
]


def test_slivers_merge_and_the_notch_stays() -> None:
    merged = merge_pieces(L_PIECES, tolerance=0.1, max_pieces=6)
    assert len(merged) == 2
    union = shapely.union_all([_footprint(p) for p in merged])
    exact = shapely.union_all([_footprint(p) for p in L_PIECES])
    assert union.contains(exact.buffer(-1e-9))
    assert union.area == pytest.approx(exact.area, rel=1e-9)
    assert not union.contains(shapely.Point(0.06, 0.06)), "the L's notch must stay empty"
    for piece in merged:
        footprint = _footprint(piece)
        assert footprint.is_valid
        assert shapely.is_ccw(footprint.exterior)
        assert footprint.area == pytest.approx(footprint.convex_hull.area, rel=1e-12)
        assert set(np.round(piece[:, 2], 12)) == {-0.01, 0.01}


def test_max_pieces_overrides_the_tolerance() -> None:
    merged = merge_pieces(L_PIECES, tolerance=0.0, max_pieces=1)
    assert len(merged) == 1
    hull = shapely.MultiPolygon([_footprint(p) for p in L_PIECES]).convex_hull
    assert _footprint(merged[0]).area == pytest.approx(hull.area, rel=1e-12)


def test_zero_tolerance_keeps_the_exact_decomposition() -> None:
    merged = merge_pieces(L_PIECES[:2], tolerance=0.0, max_pieces=10)
    assert len(merged) == 2


def test_flat_pieces_only_or_none_is_an_error() -> None:
    flat = _prism([(0.0, 0.0), (0.1, 0.0), (0.2, 0.0)])
    with pytest.raises(SceneError, match="positive area"):
        merge_pieces([flat], tolerance=0.1, max_pieces=6)
    with pytest.raises(SceneError, match="positive area"):
        merge_pieces([], tolerance=0.1, max_pieces=6)


def _box_obj(path: Path, a: float, b: float, c: float, offset: tuple[float, float, float]) -> None:
    import trimesh

    box = trimesh.creation.box(extents=(a, b, c))
    box.apply_translation(offset)
    path.write_text(trimesh.exchange.obj.export_obj(box), encoding="utf-8")


def test_merged_file_is_keyed_by_content_so_a_shared_cache_is_never_stale(
    tmp_path: Path,
) -> None:
    cache = tmp_path / "cache"
    cache.mkdir()
    source = tmp_path / "obj_1_convex.obj"
    source.write_text(pieces_obj_text(L_PIECES, source.name))
    first = merged_collision_file(source, cache, tolerance=0.1, max_pieces=6)
    expected = merge_pieces(L_PIECES, tolerance=0.1, max_pieces=6)
    got = read_pieces(first)
    assert len(got) == len(expected) == 2
    for a, b in zip(got, expected, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)
    # a second episode (any process) reuses the file: nothing is merged or written again
    stamp = first.stat().st_mtime_ns
    assert merged_collision_file(source, cache, tolerance=0.1, max_pieces=6) == first
    assert first.stat().st_mtime_ns == stamp
    # other merge parameters, or a mesh rewritten at the same path, never read the old file
    exact = merged_collision_file(source, cache, tolerance=0.0, max_pieces=100)
    assert exact != first
    assert len(read_pieces(exact)) == len(merge_pieces(L_PIECES, 0.0, 100)) == 3
    source.write_text(pieces_obj_text(L_PIECES[:2], source.name))
    changed = merged_collision_file(source, cache, tolerance=0.1, max_pieces=6)
    assert changed != first
    assert len(read_pieces(changed)) == 2
    assert sorted(p.name for p in cache.iterdir()) == sorted({first.name, exact.name, changed.name})


def test_a_cache_that_cannot_be_written_is_a_clear_error(tmp_path: Path) -> None:
    source = tmp_path / "obj_2_convex.obj"
    source.write_text(pieces_obj_text(L_PIECES, source.name))
    not_a_folder = tmp_path / "cache"
    not_a_folder.write_text("")
    with pytest.raises(
        SceneError, match=r"cannot write the merged collision shape.*CDW_TWIN_CACHE"
    ):
        merged_collision_file(source, not_a_folder, tolerance=0.1, max_pieces=6)


def test_a_missing_pieces_file_is_named(tmp_path: Path) -> None:
    missing = tmp_path / "gone_convex.obj"
    with pytest.raises(SceneError, match=r"gone_convex\.obj"):
        merged_collision_file(missing, tmp_path, tolerance=0.1, max_pieces=6)


def test_box_inertia_is_the_textbook_one(tmp_path: Path) -> None:
    a, b, c = 0.3, 0.2, 0.05
    path = tmp_path / "box.obj"
    _box_obj(path, a, b, c, (0.1, -0.2, 0.3))
    volume, com, tensor = unit_mass_inertia(read_obj_triangles(path))
    assert volume == pytest.approx(a * b * c, rel=1e-12)
    np.testing.assert_allclose(com, (0.1, -0.2, 0.3), atol=1e-12)
    expected = np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) / 12.0
    np.testing.assert_allclose(tensor, expected, atol=1e-12)


def test_inertia_of_a_concave_prism_matches_trimesh(tmp_path: Path) -> None:
    import trimesh

    outline = shapely.Polygon(
        [(0, 0), (0.2, 0), (0.2, 0.05), (0.05, 0.05), (0.05, 0.15), (0, 0.15)]
    )
    mesh = trimesh.creation.extrude_polygon(outline, height=0.04)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(0.4, (0.3, 0.2, 1.0)))
    path = tmp_path / "l.obj"
    path.write_text(trimesh.exchange.obj.export_obj(mesh), encoding="utf-8")
    mesh = trimesh.load(path, force="mesh", process=False)
    mesh.density = 1.0 / mesh.volume
    volume, com, tensor = unit_mass_inertia(read_obj_triangles(path))
    assert volume == pytest.approx(mesh.volume, rel=1e-9)
    np.testing.assert_allclose(com, mesh.center_mass, atol=1e-9)
    np.testing.assert_allclose(tensor, mesh.moment_inertia, atol=1e-9)


def test_inward_wound_mesh_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "box.obj"
    _box_obj(path, 0.1, 0.1, 0.1, (0.0, 0.0, 0.0))
    triangles = read_obj_triangles(path)[:, ::-1]
    with pytest.raises(SceneError, match="not positive"):
        unit_mass_inertia(triangles)


def test_malformed_obj_line_is_named(tmp_path: Path) -> None:
    path = tmp_path / "bad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 one 0\nf 1 2 3\n", encoding="utf-8")
    with pytest.raises(SceneError, match=r"bad\.obj:3: malformed line"):
        read_obj_triangles(path)
    path.write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n", encoding="utf-8")
    with pytest.raises(SceneError, match=r"bad\.obj:3: face 'f 1 2 9' refers to a vertex"):
        read_obj_triangles(path)
