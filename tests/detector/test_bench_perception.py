"""``cdw-twin bench perception``: real photos and the twin's renders of the same pieces, side by
side (the renders need the twin's OpenGL renderer: skipped where EGL is missing)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from detector import bench_perception as bp
from detector.errors import DatasetError
from interfaces.camera import RgbdCameraSpec, project
from meshgen.config import MeshgenConfig
from meshgen.pipeline import mesh_dataset
from meshgen.sample import write_sample
from tests.gl_support import require_gl


@pytest.fixture(scope="module")
def sample(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A procedural YOLO-seg dataset of eight photos (four subsets of two)."""
    root = tmp_path_factory.mktemp("perception") / "sample"
    write_sample(root, images=8, seed=5)
    return root


def test_pieces_are_drawn_where_the_photo_has_them(sample: Path, tmp_path: Path) -> None:
    require_gl()
    meshes = tmp_path / "meshes"
    mesh_dataset(sample, meshes, MeshgenConfig(seed=5))
    scene = sorted(meshes.glob("*/scene.json"))[0]
    pieces = bp.lay_out(scene)
    assert pieces
    assert all(p.base_m >= 0.0 for p in pieces)
    camera = RgbdCameraSpec()
    renderer = bp.PieceRenderer(camera, 0.0)
    try:
        frame = renderer.frame(pieces, np.random.default_rng(0))
    finally:
        renderer.close()
    assert frame.instance_ids is not None
    hits = checked = 0
    for k, piece in enumerate(pieces, start=1):
        # the centre of its top face, projected, shows the piece at its top's depth (unless
        # a piece stacked on it hides that point)
        top_z = piece.base_m + piece.height_m
        top = (
            camera.position_m[0] + piece.centroid_m[0],
            camera.position_m[1] + piece.centroid_m[1],
            top_z,
        )
        uv, depth = project(np.array([top]), camera.intrinsics, camera.worldMoptical())
        u, v = round(float(uv[0, 0])), round(float(uv[0, 1]))
        checked += 1
        if frame.instance_ids[v, u] == k:
            hits += 1
            seen = float(np.nanmedian(frame.depth_m[v - 1 : v + 2, u - 1 : u + 2]))
            assert seen == pytest.approx(float(depth[0]), abs=0.01)
    assert checked == len(pieces)
    assert hits >= 0.8 * checked


def test_the_bench_scores_both_sides_and_says_which_mode(sample: Path, tmp_path: Path) -> None:
    require_gl()
    result = bp.bench_perception(sample, seed=0)
    json.dumps(result, allow_nan=False)  # plain JSON
    rows = {(r["source"], r["mode"]): r for r in result["side_by_side"]}
    assert set(rows) == {
        ("real_photos", "colour"),
        ("rendered", "depth"),
        ("rendered", "colour"),
    }
    assert result["split"]["train_photos"] + result["split"]["test_photos"] == 8
    rendered = rows[("rendered", "depth")]
    assert rendered["frames"] == result["split"]["test_photos"]
    assert rendered["recall"] >= 0.9
    assert rendered["class_accuracy"] >= 0.9
    assert rendered["centroid_unit"] == "m"
    assert rendered["centroid_error_median"] < 0.005
    real = rows[("real_photos", "colour")]
    assert real["centroid_unit"] == "px"
    assert real["recall"] > 0.5
    policy = result["real_photos"]["modes"]["colour"]["all"]["precision_policy"]
    assert "unassessed" in policy
    assert result["rendered"]["modes"]["depth"]["precision_policy"].startswith("every detection")


def test_a_meshgen_output_or_a_missing_folder_is_refused(sample: Path, tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="no such dataset folder"):
        bp.bench_perception(tmp_path / "missing")
    meshes = tmp_path / "meshes"
    mesh_dataset(sample, meshes, MeshgenConfig(seed=5))
    with pytest.raises(DatasetError, match="a meshgen output; give the annotated dataset"):
        bp.bench_perception(meshes)
