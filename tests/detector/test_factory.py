"""The factory: a detector per dataset and camera set, its classifier trained on the dataset's own
textures (or photos, or class colours), cached on disk by content and in the process."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest

from detector import factory
from detector.errors import DatasetError, DetectorConfigError
from detector.factory import CACHE_NAME, belt_m_per_px, classifier_for, detector_for
from detector.training_set import scene_samples
from interfaces.cache import cache_root
from interfaces.camera import RgbdCameraSpec
from meshgen.config import MeshgenConfig
from meshgen.pipeline import mesh_dataset
from meshgen.sample import write_sample

SHARED_SAMPLE = Path(__file__).resolve().parents[3] / "shared" / "datasets" / "cdw_stacked_sample"
CAMERA = RgbdCameraSpec()


def _meshed(root: Path, *, seed: int, images: int = 6) -> Path:
    write_sample(root / "sample", images=images, seed=seed)
    mesh_dataset(root / "sample", root / "meshes", MeshgenConfig(seed=seed))
    return root / "meshes"


@pytest.fixture(scope="module")
def meshed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A six-photo meshgen output of the procedural sample (textures and polygons)."""
    return _meshed(tmp_path_factory.mktemp("factory"), seed=3)


@pytest.fixture(autouse=True)
def _fresh(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("CDW_TWIN_CACHE", str(tmp_path / "user-cache"))
    factory.clear_process_cache()


def test_the_cameras_pixel_on_the_belt_sets_the_training_scale() -> None:
    # looking straight down from 1.2 m: a pixel covers distance / focal length
    fx_px = CAMERA.intrinsics.fx_px
    assert belt_m_per_px([CAMERA], belt_z_m=0.0) == pytest.approx(1.2 / fx_px, rel=1e-6)
    assert belt_m_per_px([CAMERA], belt_z_m=0.2) == pytest.approx(1.0 / fx_px, rel=1e-6)
    with pytest.raises(DetectorConfigError, match="cameras: empty"):
        belt_m_per_px([], belt_z_m=0.0)
    upwards = RgbdCameraSpec(name="side", rpy_rad=(0.0, -np.pi / 2, 0.0))
    with pytest.raises(DetectorConfigError, match=r"cameras\.side"):
        belt_m_per_px([upwards], belt_z_m=0.0)


def test_the_classifier_learns_the_textures_and_names_pieces_of_unseen_photos(
    meshed: Path, tmp_path: Path
) -> None:
    detector = detector_for(meshed, belt_z_m=0.0, cameras=[CAMERA])
    classifier = detector.segmenter.classifier  # type: ignore[attr-defined]
    assert classifier.training["source"] == "meshgen_textures"
    assert classifier.training["images"] == 6
    assert set(classifier.class_names) >= {"concrete", "brick", "wood"}
    # photos of another seed, never trained on, seen at the camera's scale
    other = _meshed(tmp_path / "other", seed=4)
    m_per_px = belt_m_per_px([CAMERA], belt_z_m=0.0)
    right = total = 0
    for scene in sorted(other.glob("*/scene.json")):
        found = scene_samples(scene, belt_m_per_px=m_per_px, stride=2)
        assert found is not None
        names, _ = classifier.predict(found[0])
        right += sum(a == b for a, b in zip(names, found[1], strict=True))
        total += len(names)
    assert total >= 15
    assert right / total >= 0.85


def test_one_detector_per_dataset_and_camera_set_in_a_process(meshed: Path) -> None:
    first = detector_for(meshed, belt_z_m=0.0, cameras=[CAMERA])
    assert detector_for(meshed, belt_z_m=0.0, cameras=(CAMERA,)) is first
    other_camera = RgbdCameraSpec(name="zone2", position_m=(0.3, 0.5, 1.2))
    second = detector_for(meshed, belt_z_m=0.0, cameras=[other_camera])
    assert second is not first
    assert second.belt_z_m == first.belt_z_m == 0.0


def test_training_is_deterministic_and_cached_by_content(
    meshed: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    data = tmp_path / "meshes"
    shutil.copytree(meshed, data)
    m_per_px = belt_m_per_px([CAMERA], belt_z_m=0.0)
    first = classifier_for(data, m_per_px=m_per_px)
    cache = data / CACHE_NAME
    assert cache.is_file()
    key = json.loads(cache.read_text(encoding="utf-8"))["training"]["content_key"]
    fresh = classifier_for(data, m_per_px=m_per_px, use_cache=False)
    np.testing.assert_array_equal(first.weights, fresh.weights)
    np.testing.assert_array_equal(first.bias, fresh.bias)

    def no_training(*args: object, **kwargs: object) -> None:
        raise AssertionError("trained again although the cache matched")

    monkeypatch.setattr(factory, "dataset_training_set", no_training)
    loaded = classifier_for(data, m_per_px=m_per_px)
    np.testing.assert_allclose(loaded.weights, first.weights)
    monkeypatch.undo()
    monkeypatch.setenv("CDW_TWIN_CACHE", str(tmp_path / "user-cache"))
    # another texture: another key, trained again and the file replaced
    texture = sorted(data.glob("*/texture.jpg"))[0]
    texture.write_bytes(sorted(meshed.glob("*/texture.jpg"))[1].read_bytes())
    classifier_for(data, m_per_px=m_per_px)
    new_key = json.loads(cache.read_text(encoding="utf-8"))["training"]["content_key"]
    assert new_key != key
    # another camera scale: another key as well
    assert classifier_for(data, m_per_px=m_per_px * 2).training["content_key"] != new_key


def test_without_textures_it_falls_back_to_the_class_colours_and_says_so(
    meshed: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    data = tmp_path / "meshes"
    shutil.copytree(meshed, data)
    for texture in data.glob("*/texture.jpg"):
        texture.unlink()
    with caplog.at_level(logging.WARNING, logger="detector.factory"):
        detector = detector_for(data, belt_z_m=0.0, cameras=[CAMERA])
    assert "no photos and no textures" in caplog.text
    assert str(data) in caplog.text
    classifier = detector.segmenter.classifier  # type: ignore[attr-defined]
    assert classifier.training["source"] == "class_table"
    # the class table's colours: grey concrete, red brick, brown wood, near-black rubber
    from detector.training_set import class_table_of, table_training_set

    table = class_table_of(data)
    samples = table_training_set(table, stride=2, seed=7)
    names, _ = classifier.predict(samples.features)
    agree = np.mean([a == b for a, b in zip(names, samples.labels, strict=True)])
    assert agree >= 0.9


def test_a_folder_that_is_no_dataset_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="neither a meshgen output"):
        detector_for(tmp_path, belt_z_m=0.0, cameras=[CAMERA])
    with pytest.raises(DatasetError, match="no such folder"):
        detector_for(tmp_path / "missing", belt_z_m=0.0, cameras=[CAMERA])
    with pytest.raises(DetectorConfigError, match="belt_z_m"):
        detector_for(tmp_path, belt_z_m=float("nan"), cameras=[CAMERA])


def test_a_broken_scene_names_its_file_and_field(meshed: Path, tmp_path: Path) -> None:
    data = tmp_path / "meshes"
    shutil.copytree(meshed, data)
    scene = sorted(data.glob("*/scene.json"))[0]
    doc = json.loads(scene.read_text(encoding="utf-8"))
    doc["objects"][0]["polygon_px"] = "nope"
    scene.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(DatasetError, match=r"scene\.json: objects\[0\]\.polygon_px"):
        classifier_for(data, m_per_px=0.002, use_cache=False)


@pytest.mark.skipif(not SHARED_SAMPLE.is_dir(), reason="../shared/datasets not present")
def test_a_source_photo_dataset_is_never_written_to() -> None:
    before = sorted(p.name for p in SHARED_SAMPLE.iterdir())
    classifier = classifier_for(SHARED_SAMPLE, m_per_px=0.002)
    assert classifier.training["source"] == "photos"
    assert classifier.training["images"] == 60
    assert sorted(p.name for p in SHARED_SAMPLE.iterdir()) == before
    assert list((cache_root() / "detector").glob("classifier-*.json"))
