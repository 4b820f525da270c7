"""The detector of a dataset and a set of cameras: what the twin and the detector node build.

:func:`detector_for` gives the baseline :class:`detector.detector.Detector` whose colour
classifier is trained on the dataset's own photos (:mod:`detector.training_set`: a meshgen
output's textures resized to the cameras' pixel on the belt, a YOLO dataset's photos, else the
class table's colours, which the classifier's ``training["source"]`` and a logged warning say).

- **Deterministic**: the same dataset and cameras give the same classifier (the fit has no
  randomness, the class-table patches are seeded).
- **Cached on disk**: the classifier is written (atomically) to :data:`CACHE_NAME` in a meshgen
  output folder, keyed by a hash of the dataset's content (its scenes and textures, or its
  labels and photos) and of the recipe (feature names, stride, the cameras' pixel on the belt);
  a folder that cannot be written, and a source photo dataset (never written to), keep it under
  ``$CDW_TWIN_CACHE/detector/`` instead. A stale file (other key) is retrained and replaced.
- **Cached per process**: one detector per dataset folder, belt height and camera set (each
  keeps its own view of the belt, so give each camera its own when they differ).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import stat
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from detector.belt_view import BeltView
from detector.classifier import DEFAULT_L2, ColourClassifier, fit_classifier
from detector.config import DetectorConfig
from detector.detector import Detector
from detector.errors import DetectorConfigError, ModelFileError
from detector.features import FEATURE_NAMES
from detector.training_set import dataset_training_set, is_meshgen_output, is_photo_dataset
from interfaces.cache import cache_root
from interfaces.camera import RgbdCameraSpec

__all__ = [
    "CACHE_NAME",
    "RECIPE_VERSION",
    "belt_m_per_px",
    "classifier_for",
    "clear_process_cache",
    "content_key",
    "detector_for",
]

CACHE_NAME = "detector_classifier.json"
"""The classifier cache file in a dataset folder."""

RECIPE_VERSION = 3
"""Version of how the factory trains; part of the cache key (bump it when training changes)."""

L2 = DEFAULT_L2
"""The classifier's L2 penalty (as :func:`detector.bench_photos.train_on_photos`)."""

_LOG = logging.getLogger(__name__)
_LOCK = threading.Lock()
_DETECTORS: dict[tuple[object, ...], Detector] = {}


def belt_m_per_px(cameras: Sequence[RgbdCameraSpec], *, belt_z_m: float) -> float:
    """The median over ``cameras`` of the size of a pixel on the belt at the image centre, m
    (:class:`detector.errors.DetectorConfigError` naming a camera that does not see the belt)."""
    if not cameras:
        msg = "cameras: empty; the detector needs at least one camera (RgbdCameraSpec)"
        raise DetectorConfigError(msg)
    sizes = []
    for spec in cameras:
        view = BeltView(
            intrinsics=spec.intrinsics, worldMoptical=spec.worldMoptical(), belt_z_m=belt_z_m
        )
        size = view.belt_metres_per_px
        if not (math.isfinite(size) and size > 0):
            msg = (
                f"cameras.{spec.name}: its central ray does not meet the belt plane "
                f"z = {belt_z_m:g} m"
            )
            raise DetectorConfigError(msg)
        sizes.append(size)
    return float(np.median(sizes))


def _content_files(folder: Path) -> Iterator[Path]:
    """The files whose bytes a dataset's classifier depends on, in a fixed order."""
    if is_meshgen_output(folder):
        yield from (folder / name for name in ("classes.yaml", "materials.mtl"))
        for scene in sorted(folder.glob("*/scene.json")):
            yield scene
            yield scene.parent / "texture.jpg"
    elif is_photo_dataset(folder):
        yield folder / "data.yaml"
        for sub in ("labels", "images"):
            yield from sorted((folder / sub).iterdir())
    else:
        yield from (folder / name for name in ("classes.yaml", "data.yaml"))


def content_key(folder: Path, *, m_per_px: float, stride: int) -> str:
    """A hash of dataset ``folder``'s content (names and bytes of the files its classifier is
    trained on) and of the recipe (:data:`RECIPE_VERSION`, features, ``stride``, ``m_per_px``
    to 0.01 mm), hex."""
    digest = hashlib.sha256()
    recipe = {
        "recipe": RECIPE_VERSION,
        "features": list(FEATURE_NAMES),
        "stride": stride,
        "m_per_px": round(m_per_px, 5),
        "l2": L2,
    }
    digest.update(json.dumps(recipe, sort_keys=True).encode())
    for path in _content_files(folder):
        if not path.is_file():
            continue
        digest.update(str(path.relative_to(folder)).encode() + b"\0")
        digest.update(hashlib.sha256(path.read_bytes()).digest())
    return digest.hexdigest()


def _writable(folder: Path) -> bool:
    """Whether ``folder`` is meant to be written: its owner may write it (the mode's bit,
    which root's access check would ignore) and this process may."""
    try:
        mode = folder.stat().st_mode
    except OSError:
        return False
    return bool(mode & stat.S_IWUSR) and os.access(folder, os.W_OK)


def _cache_paths(folder: Path, key: str) -> tuple[Path, ...]:
    """Where the classifier of ``folder`` is kept: in a meshgen output the process may write
    (regenerable data), else the user's cache (a source dataset is never written to)."""
    user = cache_root() / "detector" / f"classifier-{key[:32]}.json"
    if is_meshgen_output(folder) and _writable(folder):
        return folder / CACHE_NAME, user
    return (user,)


def _load_cached(paths: Sequence[Path], key: str) -> ColourClassifier | None:
    for path in paths:
        if not path.is_file():
            continue
        try:
            model = ColourClassifier.load(path)
        except ModelFileError as exc:
            _LOG.warning("%s: ignoring an unreadable classifier cache: %s", path, exc)
            continue
        if model.training.get("content_key") == key:
            return model
    return None


def _save(model: ColourClassifier, paths: Sequence[Path]) -> None:
    for path in paths:
        try:
            model.save(path)
        except OSError as exc:
            _LOG.debug("%s: cannot write the classifier cache: %s", path, exc)
            continue
        return
    _LOG.warning("no writable place for the classifier cache (%s)", ", ".join(map(str, paths)))


def classifier_for(
    dataset_dir: Path, *, m_per_px: float, stride: int = 2, use_cache: bool = True
) -> ColourClassifier:
    """The colour classifier of ``dataset_dir`` for cameras whose pixel on the belt is
    ``m_per_px`` (loaded from its cache file when its key matches, else trained and cached)."""
    folder = Path(dataset_dir).resolve()
    key = content_key(folder, m_per_px=m_per_px, stride=stride) if folder.is_dir() else ""
    paths = _cache_paths(folder, key)
    if use_cache and key:
        cached = _load_cached(paths, key)
        if cached is not None:
            return cached
    found = dataset_training_set(folder, belt_m_per_px=m_per_px, stride=stride)
    if found.source == "class_table":
        _LOG.warning(
            "%s: no photos and no textures; the colour classifier is trained on the class "
            "table's colours (%s)",
            folder,
            ", ".join(found.class_names),
        )
    model = fit_classifier(
        found.features,
        found.labels,
        class_names=found.class_names,
        l2=L2,
        feature_stride=stride,
        training={
            "dataset": str(folder),
            "source": found.source,
            "images": found.images,
            "instances": len(found.labels),
            "belt_m_per_px": round(m_per_px, 6),
            "content_key": key,
        },
    )
    if use_cache and key:
        _save(model, paths)
    return model


def _index_stamp(folder: Path) -> tuple[int, ...]:
    """A cheap mark of a dataset folder's version (meshgen replaces the folder whole)."""
    stamps = []
    for name in ("index.csv", "data.yaml", "classes.yaml"):
        try:
            stamps.append((folder / name).stat().st_mtime_ns)
        except OSError:
            stamps.append(0)
    return tuple(stamps)


def detector_for(
    dataset_dir: Path,
    *,
    belt_z_m: float,
    cameras: Sequence[RgbdCameraSpec],
    config: DetectorConfig | None = None,
    use_cache: bool = True,
) -> Detector:
    """The baseline detector of ``dataset_dir``'s classes for ``cameras`` over a belt whose
    surface is at ``belt_z_m`` (see the module): one per process for each dataset, belt
    height, camera set and ``config``; ``use_cache`` ``False`` neither reads nor writes the
    classifier's cache file (the per-process cache still holds).

    Errors: :class:`detector.errors.DetectorConfigError` for no camera or one that misses the
    belt, :class:`detector.errors.DatasetError` naming a folder that is not a dataset.
    """
    if not math.isfinite(belt_z_m):
        msg = f"belt_z_m = {belt_z_m!r}: must be finite"
        raise DetectorConfigError(msg)
    folder = Path(dataset_dir).resolve()
    cfg = config or DetectorConfig()
    specs = tuple(cameras)
    key = (folder, _index_stamp(folder), float(belt_z_m), specs, cfg, use_cache)
    with _LOCK:
        found = _DETECTORS.get(key)
        if found is not None:
            return found
        m_per_px = belt_m_per_px(specs, belt_z_m=belt_z_m)
        classifier = classifier_for(
            folder, m_per_px=m_per_px, stride=cfg.work_stride, use_cache=use_cache
        )
        made = Detector(config=cfg, classifier=classifier, belt_z_m=belt_z_m)
        _DETECTORS[key] = made
        return made


def clear_process_cache() -> None:
    """Forget the detectors built in this process (tests; a dataset rewritten in place)."""
    with _LOCK:
        _DETECTORS.clear()
