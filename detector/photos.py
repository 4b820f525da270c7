"""A YOLO-seg photo dataset as frames with ground truth: photos, polygon masks, height images.

Layout (Ultralytics): ``DATASET/data.yaml`` (``names`` as a list or a mapping), photos
``DATASET/images/<stem>.{jpg,jpeg,png}``, labels ``DATASET/labels/<stem>.txt`` (one polygon a
line: ``class x1 y1 x2 y2 ...``, normalised), and optionally height images
``DATASET/heights/<stem>.png`` (8- or 16-bit, the same size as the photo; their levels are taken
as relative heights) and ``DATASET/manifest.csv`` whose ``file`` and ``subfolder`` columns name
each photo's subset (else the subset is the stem up to its first ``_``).

Each photo is resized to fit ``max_size_px`` (aspect kept) and its polygons are rasterised at
that size (Pillow's ``ImageDraw``) into an id image: instance ``k`` is the k-th polygon of the
label file, later polygons drawn over earlier ones where they overlap (a pixel belongs to one
instance, as a camera sees it). A photo without a label file is skipped (it has no ground truth);
a label line that cannot be read is an error naming the file and line.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from detector.errors import DatasetError
from interfaces.errors import ConfigError
from interfaces.yamlio import load_yaml_strict

PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png")
"""Photo file types read from ``images/``."""


@dataclass(frozen=True, kw_only=True, eq=False)
class Photo:
    """One photo with its ground truth, resized.

    ``rgb`` ``(H, W, 3) uint8``; ``truth_ids`` ``(H, W) int32`` (0: no label, ``k``: the k-th
    polygon); ``truth_classes[k - 1]`` its class; ``heights`` ``(H, W) float32`` (levels of the
    height image, relative) or ``None``; ``scale`` the resize factor from the original photo.
    """

    stem: str
    subset: str
    rgb: np.ndarray
    truth_ids: np.ndarray
    truth_classes: tuple[str, ...]
    heights: np.ndarray | None
    scale: float


@dataclass(frozen=True, kw_only=True, eq=False)
class PhotoDataset:
    """A dataset's class names (in id order) and its photos (sorted by stem)."""

    root: Path
    class_names: tuple[str, ...]
    photos: tuple[Photo, ...]


def load_class_names(root: Path) -> dict[int, str]:
    """Class ids to names from ``root/data.yaml``."""
    path = root / "data.yaml"
    if not path.is_file():
        msg = f"{path}: not found (a YOLO dataset names its classes there)"
        raise DatasetError(msg)
    try:
        data = load_yaml_strict(path.read_text(encoding="utf-8"), str(path))
    except (OSError, UnicodeDecodeError, ConfigError) as exc:
        msg = f"{path}: cannot read class names: {exc}"
        raise DatasetError(msg) from exc
    names = data.get("names") if isinstance(data, dict) else None
    if isinstance(names, list):
        return {i: str(n) for i, n in enumerate(names)}
    if isinstance(names, dict):
        out: dict[int, str] = {}
        for key, value in names.items():
            if isinstance(key, bool) or not isinstance(key, int | str) or not str(key).isdigit():
                msg = f"{path}: names: class id {key!r} is not a non-negative integer"
                raise DatasetError(msg)
            out[int(key)] = str(value)
        return out
    msg = f'{path}: field "names" must be a list or a mapping of class id to name'
    raise DatasetError(msg)


def _subsets(root: Path) -> dict[str, str]:
    """Stem to subset from ``manifest.csv`` (``file``, ``subfolder``), if there is one."""
    path = root / "manifest.csv"
    if not path.is_file():
        return {}
    with path.open(encoding="utf-8", newline="") as handle:
        reader = csv.DictReader(handle)
        if not reader.fieldnames or not {"file", "subfolder"} <= set(reader.fieldnames):
            return {}
        return {row["file"]: row["subfolder"] for row in reader}


def _fit(size: tuple[int, int], max_size_px: tuple[int, int]) -> tuple[tuple[int, int], float]:
    """The size that fits ``max_size_px`` with the aspect of ``size``, and the factor."""
    w, h = size
    scale = min(max_size_px[0] / w, max_size_px[1] / h)
    return (max(1, round(w * scale)), max(1, round(h * scale))), scale


def read_polygons(path: Path, names: dict[int, str]) -> list[tuple[str, np.ndarray]]:
    """The polygons of one YOLO label file: class name and ``(n, 2)`` normalised points."""
    out = []
    text = path.read_text(encoding="utf-8-sig")
    for number, line in enumerate(text.splitlines(), start=1):
        tokens = line.split()
        if not tokens:
            continue
        where = f"{path}:{number}"
        try:
            class_id = int(tokens[0])
            coords = np.array([float(t) for t in tokens[1:]], dtype=np.float64)
        except ValueError as exc:
            msg = f"{where}: expected 'class x1 y1 x2 y2 ...' numbers: {exc}"
            raise DatasetError(msg) from exc
        if class_id not in names:
            msg = f"{where}: class id {class_id} is not in data.yaml's names"
            raise DatasetError(msg)
        if coords.size < 6 or coords.size % 2 or not np.isfinite(coords).all():
            msg = f"{where}: a polygon needs at least 3 finite (x, y) pairs, got {coords.size}"
            raise DatasetError(msg)
        out.append((names[class_id], coords.reshape(-1, 2)))
    return out


def rasterise(polygons: list[tuple[str, np.ndarray]], size: tuple[int, int]) -> np.ndarray:
    """An id image ``(H, W) int32`` of normalised polygons at ``size`` (width, height)."""
    w, h = size
    canvas = Image.new("I", (w, h), 0)
    draw = ImageDraw.Draw(canvas)
    for k, (_, points) in enumerate(polygons, start=1):
        xy = [(float(x) * w, float(y) * h) for x, y in points]
        draw.polygon(xy, fill=k, outline=k)
    return np.asarray(canvas, dtype=np.int32)


def _read_image(path: Path, mode: str) -> Image.Image:
    try:
        with Image.open(path) as image:
            image.load()
            return image.convert(mode) if image.mode != mode else image.copy()
    except OSError as exc:
        msg = f"{path}: cannot read the image: {exc}"
        raise DatasetError(msg) from exc


def read_photo(
    root: Path,
    photo_path: Path,
    names: dict[int, str],
    subset: str,
    max_size_px: tuple[int, int],
) -> Photo | None:
    """One photo of the dataset at ``root`` resized, with its ground truth (``None`` without a
    label file)."""
    stem = photo_path.stem
    label = root / "labels" / f"{stem}.txt"
    if not label.is_file():
        return None
    image = _read_image(photo_path, "RGB")
    size, scale = _fit(image.size, max_size_px)
    rgb = np.asarray(image.resize(size, Image.Resampling.BILINEAR), dtype=np.uint8)
    polygons = read_polygons(label, names)
    heights = None
    height_path = root / "heights" / f"{stem}.png"
    if height_path.is_file():
        height_image = _read_image(height_path, "F")
        if height_image.size != image.size:
            msg = f"{height_path}: size {height_image.size} differs from the photo's {image.size}"
            raise DatasetError(msg)
        heights = np.asarray(height_image.resize(size, Image.Resampling.BILINEAR), np.float32)
    return Photo(
        stem=stem,
        subset=subset,
        rgb=rgb,
        truth_ids=rasterise(polygons, size),
        truth_classes=tuple(name for name, _ in polygons),
        heights=heights,
        scale=scale,
    )


def read_photo_dataset(root: Path, *, max_size_px: tuple[int, int] = (640, 480)) -> PhotoDataset:
    """Every labelled photo of the YOLO dataset at ``root``, resized to fit ``max_size_px``."""
    root = Path(root)
    names = load_class_names(root)
    folder = root / "images"
    if not folder.is_dir():
        msg = f"{folder}: not found (the photos of a YOLO dataset live there)"
        raise DatasetError(msg)
    subsets = _subsets(root)
    photos = []
    for path in sorted(folder.iterdir()):
        if path.suffix.lower() not in PHOTO_SUFFIXES:
            continue
        subset = subsets.get(path.stem, path.stem.split("_", 1)[0])
        photo = read_photo(root, path, names, subset, max_size_px)
        if photo is not None:
            photos.append(photo)
    if not photos:
        msg = f"{folder}: no photo with a label file in {root / 'labels'}"
        raise DatasetError(msg)
    return PhotoDataset(
        root=root,
        class_names=tuple(names[k] for k in sorted(names)),
        photos=tuple(photos),
    )


__all__ = [
    "PHOTO_SUFFIXES",
    "Photo",
    "PhotoDataset",
    "load_class_names",
    "rasterise",
    "read_photo",
    "read_photo_dataset",
    "read_polygons",
]
