"""The grasp geometry the detector reports (suction point, radius, tilt, centroid) against the
truth on rendered frames of known meshed pieces (``detector.bench_grasp``), and the camera-view
copy of the classifier's texture samples (skipped where EGL is missing)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from detector.bench_grasp import bench_grasp
from detector.features import FEATURE_NAMES
from detector.training_set import camera_view, scene_samples
from meshgen.config import MeshgenConfig
from meshgen.pipeline import mesh_dataset
from meshgen.sample import write_sample
from tests.gl_support import require_gl


@pytest.fixture(scope="module")
def sample(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A procedural YOLO-seg dataset of four photos."""
    root = tmp_path_factory.mktemp("grasp") / "sample"
    write_sample(root, images=4, seed=7)
    return root


def test_suction_radius_tilt_and_point_are_close_to_the_meshes_truth(sample: Path) -> None:
    require_gl()
    result = bench_grasp(sample)
    assert result["frames"] == 4
    assert result["matched_pieces"] >= 8
    radius = result["suction_radius_error_m"]
    assert radius["count"] >= 6
    # unbiased to a millimetre and a half (it was 2.5 mm too small before the offset fix)
    assert abs(radius["median"]) <= 0.0015
    assert radius["p10"] >= -0.004
    assert radius["p90"] <= 0.004
    tilt = result["suction_tilt_error_rad"]
    assert 0.0 <= tilt["median"] <= 0.0095  # noise only adds tilt (0.0105 with the narrower fit)
    # the detected point may sit elsewhere on a long face's midline, but the lip it leaves fits
    assert result["suction_clearance_loss_m"]["median"] <= 0.003
    assert result["centroid_error_m"]["median"] <= 0.003


def test_each_texture_sample_is_also_taken_as_the_camera_sees_it(tmp_path: Path) -> None:
    root = tmp_path / "sample"
    write_sample(root, images=2, seed=3)
    meshes = tmp_path / "meshes"
    mesh_dataset(root, meshes, MeshgenConfig(seed=0))
    scene = sorted(meshes.glob("*/scene.json"))[0]
    found = scene_samples(scene, belt_m_per_px=0.002, stride=2)
    assert found is not None
    features, classes = found
    k = len(classes) // 2
    assert k >= 1
    assert classes[:k] == classes[k:]
    lightness = FEATURE_NAMES.index("L_mean")
    contrast = FEATURE_NAMES.index("contrast_mean")
    # the camera-view copy is darker and softer than the texture, piece by piece
    assert (features[k:, lightness] < features[:k, lightness]).all()
    assert (features[k:, contrast] <= features[:k, contrast] + 1e-9).all()
    rgb = np.full((8, 8, 3), 200, dtype=np.uint8)
    assert int(camera_view(rgb)[4, 4, 0]) == 190
