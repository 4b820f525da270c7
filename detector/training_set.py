"""What the colour classifier of a dataset learns from: its own photos' pieces, seen at the
camera's scale, or (without photos) the class table's colours.

Three sources, tried in this order by :func:`dataset_training_set`:

- **meshgen output** (a folder with ``index.csv`` and an image folder per photo): each image
  folder's ``scene.json`` names its texture (``texture.path``, usually ``texture.jpg``: the photo
  the annotation was drawn on, or a procedural picture of its pieces) and every piece's polygon
  in the annotation's pixels (``objects[].polygon_px``) and class. The texture is resized so one
  pixel covers ``belt_m_per_px`` (the cameras' pixel on the belt: colour texture depends on the
  scale it is seen at) and the polygons are rasterised at that size.
- **YOLO-seg photo dataset** (``data.yaml``, ``images/``, ``labels/``; :mod:`detector.photos`):
  every labelled photo, resized to fit 640x480 (no metric scale is known).
- **class table** (neither photos nor textures): flat patches of each class's colour
  (``rgb`` of :mod:`interfaces.materials`: the dataset's ``classes.yaml``, else the shipped
  table) under a range of brightness and speckle, seeded; the result says so in ``source``.

Pure logic: numpy and Pillow; no ``twin``, no rclpy.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFilter

from detector.errors import DatasetError
from detector.features import instance_features
from detector.photos import PHOTO_SUFFIXES, load_class_names, rasterise, read_polygons
from interfaces.errors import ConfigError
from interfaces.materials import ClassTable, dataset_table, shipped_table

Source = str
"""Where a training set came from: ``meshgen_textures``, ``photos`` or ``class_table``."""

MIN_SAMPLED_PX = 12
"""An instance with fewer sampled pixels (after resizing, at the feature stride) is left out."""

TABLE_PATCHES_PER_CLASS = 48
"""Patches of each class's colour in a class-table training set."""

_BELT_RGB = np.array([18, 18, 19], dtype=np.float64)

CAMERA_VIEW_GAIN = 0.95
"""Brightness of a piece's top face as the camera sees it, relative to its texture: a texture
sample is also taken at this gain (with :data:`CAMERA_VIEW_BLUR_PX`). The twin's renderer
lights a face by ``ambient + (1 - ambient) cos`` (:mod:`twin.camera.gl`: 0.45 ambient, the
light 25 degrees off the vertical), 0.95 on a level top face; a real camera's exposure varies
about as much."""

CAMERA_VIEW_BLUR_PX = 0.6
"""Gaussian blur (pixels at the camera's scale) of the camera-view copy of a texture: texture
filtering and optics soften the grain the texture shows sharp (local contrast and the darkest
percentile of L* are lower in renders than on the texture)."""


@dataclass(frozen=True, kw_only=True, eq=False)
class TrainingSet:
    """Samples for :func:`detector.classifier.fit_classifier`: ``features`` ``(n, F) float64``
    (columns :data:`detector.features.FEATURE_NAMES`), ``labels`` (n class names),
    ``class_names`` (the model's classes, in order), ``source`` and ``images`` (how many photos
    or textures contributed)."""

    features: np.ndarray
    labels: tuple[str, ...]
    class_names: tuple[str, ...]
    source: Source
    images: int


def is_meshgen_output(folder: Path) -> bool:
    """Whether ``folder`` looks like a meshgen output (an ``index.csv`` and some
    ``*/scene.json``)."""
    return (folder / "index.csv").is_file() and any(folder.glob("*/scene.json"))


def is_photo_dataset(folder: Path) -> bool:
    """Whether ``folder`` looks like a YOLO-seg photo dataset with photos."""
    images = folder / "images"
    return (
        (folder / "data.yaml").is_file()
        and images.is_dir()
        and any(p.suffix.lower() in PHOTO_SUFFIXES for p in images.iterdir())
    )


def _kept(labels: np.ndarray, n: int, stride: int) -> np.ndarray:
    """Which labels ``1..n`` have at least :data:`MIN_SAMPLED_PX` sampled pixels,
    ``(n,) bool``."""
    sampled = labels[::stride, ::stride]
    counts = np.bincount(sampled.ravel(), minlength=n + 1)[1 : n + 1]
    out: np.ndarray = counts >= MIN_SAMPLED_PX
    return out


def _read_scene(path: Path) -> dict[str, object]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        msg = f"{path}: cannot read a meshgen scene: {exc}"
        raise DatasetError(msg) from exc
    if not isinstance(data, dict):
        msg = f"{path}: not a meshgen scene (expected a JSON object)"
        raise DatasetError(msg)
    return data


def _positive(data: dict[str, object], key: str, where: Path) -> float:
    value = data.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
        msg = f"{where}: field {key!r} = {value!r}: expected a positive number"
        raise DatasetError(msg)
    return float(value)


def scene_samples(
    scene_path: Path, *, belt_m_per_px: float, stride: int
) -> tuple[np.ndarray, list[str]] | None:
    """Features ``(2k, F)`` and classes of the ``k`` pieces of one meshgen image folder, its
    texture resized to ``belt_m_per_px``, each piece twice: as the texture shows it and as the
    camera sees it (:func:`camera_view`) (``None``: the scene has no texture or no pieces)."""
    data = _read_scene(scene_path)
    texture = data.get("texture")
    objects = data.get("objects")
    if not isinstance(texture, dict) or not texture.get("path"):
        return None
    if not isinstance(objects, list) or not objects:
        return None
    image_path = scene_path.parent / str(texture["path"])
    if not image_path.is_file():
        return None
    width_px = _positive(data, "width_px", scene_path)
    height_px = _positive(data, "height_px", scene_path)
    scale = _positive(data, "m_per_px", scene_path) / belt_m_per_px
    size = (max(1, round(width_px * scale)), max(1, round(height_px * scale)))
    try:
        with Image.open(image_path) as image:
            image.draft("RGB", size)
            rgb = np.asarray(image.convert("RGB").resize(size, Image.Resampling.BOX))
    except OSError as exc:
        msg = f"{image_path}: cannot read the texture: {exc}"
        raise DatasetError(msg) from exc
    canvas = Image.new("I", size, 0)
    draw = ImageDraw.Draw(canvas)
    classes: list[str] = []
    for k, obj in enumerate(objects, start=1):
        where = f"{scene_path}: objects[{k - 1}]"
        if not isinstance(obj, dict) or not isinstance(obj.get("class_name"), str):
            msg = f"{where}: expected an object with a class_name"
            raise DatasetError(msg)
        points = obj.get("polygon_px")
        if not isinstance(points, list):
            msg = f"{where}.polygon_px = {points!r}: expected a list of [u, v] pixels"
            raise DatasetError(msg)
        try:
            polygon = [(float(u) * scale, float(v) * scale) for u, v in points]
        except (TypeError, ValueError) as exc:
            msg = f"{where}.polygon_px: expected [u, v] pairs of numbers: {exc}"
            raise DatasetError(msg) from exc
        if len(polygon) >= 3:
            draw.polygon(polygon, fill=k, outline=k)
        classes.append(obj["class_name"])
    labels = np.asarray(canvas, dtype=np.int32)
    n = len(classes)
    keep = _kept(labels, n, stride)
    if not keep.any():
        return None
    lut = np.zeros(n + 1, dtype=np.int32)
    lut[1:][keep] = np.arange(1, int(keep.sum()) + 1)
    ids = lut[labels]
    features = np.concatenate(
        (instance_features(rgb, ids, stride), instance_features(camera_view(rgb), ids, stride))
    )
    kept = [c for c, k in zip(classes, keep, strict=True) if k]
    return features, kept + kept


def camera_view(rgb: np.ndarray) -> np.ndarray:
    """``rgb`` ``(H, W, 3) uint8`` as the camera sees a top face: scaled by
    :data:`CAMERA_VIEW_GAIN` and blurred by :data:`CAMERA_VIEW_BLUR_PX`."""
    blurred = Image.fromarray(rgb).filter(ImageFilter.GaussianBlur(CAMERA_VIEW_BLUR_PX))
    scaled = np.asarray(blurred, dtype=np.float32) * CAMERA_VIEW_GAIN + 0.5
    out: np.ndarray = np.clip(scaled, 0.0, 255.0).astype(np.uint8)
    return out


def model_class_names(folder: Path, found: Sequence[str]) -> tuple[str, ...]:
    """The model's classes: the dataset's class table order (meshgen's ``classes.yaml``),
    then any class found that it does not name."""
    try:
        order = list(dataset_table(folder).names)
    except ConfigError:
        order = []
    names = dict.fromkeys(order)
    names.update(dict.fromkeys(found))
    return tuple(names)


def meshgen_training_set(folder: Path, *, belt_m_per_px: float, stride: int) -> TrainingSet | None:
    """The training set of a meshgen output's textures (``None``: none has labelled pieces)."""
    parts: list[np.ndarray] = []
    labels: list[str] = []
    images = 0
    for scene in sorted(folder.glob("*/scene.json")):
        found = scene_samples(scene, belt_m_per_px=belt_m_per_px, stride=stride)
        if found is None:
            continue
        parts.append(found[0])
        labels.extend(found[1])
        images += 1
    if not labels:
        return None
    return TrainingSet(
        features=np.concatenate(parts),
        labels=tuple(labels),
        class_names=model_class_names(folder, labels),
        source="meshgen_textures",
        images=images,
    )


def _photo_rgb(path: Path, max_size_px: tuple[int, int]) -> np.ndarray:
    """A photo resized to fit ``max_size_px`` (aspect kept), ``(H, W, 3) uint8`` (decoded at a
    reduced scale where the format allows: JPEG)."""
    try:
        with Image.open(path) as image:
            w, h = image.size
            scale = min(max_size_px[0] / w, max_size_px[1] / h)
            size = (max(1, round(w * scale)), max(1, round(h * scale)))
            image.draft("RGB", size)
            out = np.asarray(image.convert("RGB").resize(size, Image.Resampling.BILINEAR))
    except OSError as exc:
        msg = f"{path}: cannot read the photo: {exc}"
        raise DatasetError(msg) from exc
    return out


def photo_training_set(
    folder: Path, *, stride: int, max_size_px: tuple[int, int] = (640, 480)
) -> TrainingSet:
    """The training set of every labelled photo of a YOLO-seg dataset (each resized to fit
    ``max_size_px``, as :func:`detector.photos.read_photo_dataset` does)."""
    names = load_class_names(folder)
    parts: list[np.ndarray] = []
    labels: list[str] = []
    images = 0
    for path in sorted((folder / "images").iterdir()):
        label_file = folder / "labels" / f"{path.stem}.txt"
        if path.suffix.lower() not in PHOTO_SUFFIXES or not label_file.is_file():
            continue
        polygons = read_polygons(label_file, names)
        rgb = _photo_rgb(path, max_size_px)
        truth = rasterise(polygons, (rgb.shape[1], rgb.shape[0]))
        n = len(polygons)
        keep = _kept(truth, n, stride)
        lut = np.zeros(n + 1, dtype=np.int32)
        lut[1:][keep] = np.arange(1, int(keep.sum()) + 1)
        parts.append(instance_features(rgb, lut[truth], stride))
        labels.extend(name for (name, _), k in zip(polygons, keep, strict=True) if k)
        images += 1
    if not labels:
        msg = f"{folder}: no labelled piece in any photo to train the colour classifier on"
        raise DatasetError(msg)
    return TrainingSet(
        features=np.concatenate(parts),
        labels=tuple(labels),
        class_names=tuple(names[k] for k in sorted(names)),
        source="photos",
        images=images,
    )


def class_table_of(folder: Path) -> ClassTable:
    """The class table of a dataset folder: a meshgen output's own (``classes.yaml``), a
    YOLO dataset's classes (``data.yaml``) over the shipped table, else the shipped table."""
    try:
        return dataset_table(folder)
    except ConfigError:
        pass
    if (folder / "data.yaml").is_file():
        names = load_class_names(folder)
        return shipped_table().restricted(names[k] for k in sorted(names))
    return shipped_table()


def table_training_set(table: ClassTable, *, stride: int, seed: int = 0) -> TrainingSet:
    """Samples of each class's colour in ``table``: :data:`TABLE_PATCHES_PER_CLASS` patches
    (24x24 px on the belt's colour) per class, brightness 0.6-1.25 and speckle 4-16 levels,
    drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    names = table.names
    if not names:
        msg = "class table: no classes to train the colour classifier on"
        raise DatasetError(msg)
    side, margin = 24, 6
    per_row = 8
    count = len(names) * TABLE_PATCHES_PER_CLASS
    rows = -(-count // per_row)
    cell = side + margin
    image = np.broadcast_to(_BELT_RGB, (rows * cell, per_row * cell, 3)).copy()
    labels = np.zeros(image.shape[:2], dtype=np.int32)
    classes: list[str] = []
    for k in range(count):
        name = names[k // TABLE_PATCHES_PER_CLASS]
        r0, c0 = (k // per_row) * cell + margin // 2, (k % per_row) * cell + margin // 2
        base = np.array(table.material(name).colour) * 255.0 * rng.uniform(0.6, 1.25)
        noise = rng.normal(0.0, rng.uniform(4.0, 16.0), (side, side, 1))
        image[r0 : r0 + side, c0 : c0 + side] = base + noise
        labels[r0 : r0 + side, c0 : c0 + side] = k + 1
        classes.append(name)
    rgb = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    return TrainingSet(
        features=instance_features(rgb, labels, stride),
        labels=tuple(classes),
        class_names=names,
        source="class_table",
        images=0,
    )


def dataset_training_set(folder: Path, *, belt_m_per_px: float, stride: int) -> TrainingSet:
    """The training set of dataset ``folder``: a meshgen output's textures, a YOLO dataset's
    photos, else (a meshgen output without textures, a YOLO dataset without photos) its class
    table's colours, ``source`` ``class_table`` (see the module). :class:`DatasetError` when
    ``folder`` is neither a meshgen output nor a YOLO dataset."""
    if not folder.is_dir():
        msg = f"{folder}: not a dataset folder (no such folder)"
        raise DatasetError(msg)
    if is_meshgen_output(folder):
        found = meshgen_training_set(folder, belt_m_per_px=belt_m_per_px, stride=stride)
        if found is not None:
            return found
    elif is_photo_dataset(folder):
        return photo_training_set(folder, stride=stride)
    elif not (folder / "data.yaml").is_file():
        msg = (
            f"{folder}: neither a meshgen output (index.csv, */scene.json) nor a YOLO dataset "
            "(data.yaml, images/, labels/): nothing to train the colour classifier on"
        )
        raise DatasetError(msg)
    return table_training_set(class_table_of(folder), stride=stride)


__all__ = [
    "MIN_SAMPLED_PX",
    "TABLE_PATCHES_PER_CLASS",
    "TrainingSet",
    "class_table_of",
    "dataset_training_set",
    "is_meshgen_output",
    "is_photo_dataset",
    "meshgen_training_set",
    "model_class_names",
    "photo_training_set",
    "scene_samples",
    "table_training_set",
]
