"""Where the photo of each annotated image is: the lookup rules of every annotation format.

meshgen textures every piece with the pixels of the photo its polygon was drawn on
(:mod:`meshgen.textures`). The photo is found, per format:

- YOLO: an image file with the label file's stem under ``DATASET/images/`` (any depth: the
  Ultralytics ``images/`` beside ``labels/``), else next to the label file;
- COCO: the image entry's ``file_name`` relative to the JSON file, to the dataset folder or to
  ``DATASET/images/``; else an image with the same stem under ``DATASET/images/``;
- labelme: the embedded ``imageData`` (base64) when it is not null (labelme's own order), else
  ``imagePath`` relative to the JSON file, else an image with the JSON file's stem under
  ``DATASET/images/``.

Only files with an image suffix (:data:`meshgen.imagesize.IMAGE_SUFFIXES`) count, and nothing
under ``DATASET/heights/`` (height images, :mod:`meshgen.heights`) is ever taken for a photo.
Finding a photo reads no pixels: whether it can be decoded and has the annotation's size is
checked when its texture is made.
"""

from __future__ import annotations

import base64
import binascii
import os
from pathlib import Path
from typing import Any

from meshgen.annotations import PhotoRef
from meshgen.imagesize import IMAGE_SUFFIXES

PHOTOS_FOLDER = "images"
"""The dataset's folder of photos (Ultralytics layout)."""


def _rel(path: Path, root: Path) -> str:
    """``path`` relative to ``root`` as a POSIX string (a plain prefix test first: this runs
    once per image, and ``Path.relative_to`` costs several times more)."""
    text, prefix = str(path), str(root) + os.sep
    if text.startswith(prefix):
        return Path(text[len(prefix) :]).as_posix()
    try:
        return path.relative_to(root).as_posix()
    except ValueError:
        return path.as_posix()


def photo_index(dataset: Path) -> dict[str, Path]:
    """Every image file under ``DATASET/images/`` by stem (the first in path order wins)."""
    folder = dataset / PHOTOS_FOLDER
    if not folder.is_dir():
        return {}
    named: list[str] = []
    for parent, _, files in os.walk(folder):
        named += [
            os.path.join(parent, name)
            for name in files
            if os.path.splitext(name)[1].lower() in IMAGE_SUFFIXES
        ]
    found: dict[str, Path] = {}
    for text in sorted(named):
        path = Path(text)
        found.setdefault(path.stem, path)
    return found


def _file_photo(path: Path, dataset: Path) -> PhotoRef | None:
    """A photo reference to ``path`` when it is an image file, else None."""
    if path.suffix.lower() in IMAGE_SUFFIXES and path.is_file():
        return PhotoRef(name=_rel(path, dataset), path=path)
    return None


def beside_label(label: Path) -> Path | None:
    """An image file next to a YOLO label file with its stem, or None."""
    for suffix in IMAGE_SUFFIXES:
        for candidate in (label.with_suffix(suffix), label.with_suffix(suffix.upper())):
            if candidate.is_file():
                return candidate
    return None


def yolo_photo(photo: Path | None, dataset: Path) -> tuple[PhotoRef | None, str]:
    """The photo of a YOLO label (found at discovery: ``images/`` or beside the label).

    Returns the reference, or None and where it was looked for.
    """
    if photo is not None:
        return PhotoRef(name=_rel(photo, dataset), path=photo), ""
    return None, f"no {PHOTOS_FOLDER}/<stem>.* beside labels/ and no image beside the label"


def coco_photo(
    file_name: Any, json_path: Path, dataset: Path, index: dict[str, Path]
) -> tuple[PhotoRef | None, str]:
    """The photo of a COCO image entry: its ``file_name`` in the usual places, else by stem."""
    tried: list[str] = []
    if isinstance(file_name, str) and file_name:
        relative = Path(file_name)
        for base in (json_path.parent, dataset, dataset / PHOTOS_FOLDER):
            found = _file_photo(base / relative, dataset)
            if found is not None:
                return found, ""
        tried.append(f"file_name {file_name[:80]!r} (relative to the JSON, the dataset, images/)")
        by_stem = index.get(relative.stem)
        if by_stem is not None:
            return PhotoRef(name=_rel(by_stem, dataset), path=by_stem), ""
        tried.append(f"{PHOTOS_FOLDER}/{relative.stem[:80]}.*")
    else:
        tried.append("no file_name")
    return None, "; ".join(tried)


def decode_image_data(text: str, where: str) -> PhotoRef:
    """The photo embedded in a labelme file's ``imageData`` (base64).

    Undecodable base64 gives a reference with empty ``data``, which the texture step reports as
    an unreadable photo.
    """
    try:
        data = base64.b64decode(text, validate=False)
    except (binascii.Error, ValueError):
        data = b""
    return PhotoRef(name=f"{where} imageData", data=data)


def labelme_photo(
    data: dict[str, Any], json_path: Path, dataset: Path, by_stem: Path | None
) -> tuple[PhotoRef | None, str]:
    """The photo of a labelme document: ``imageData``, ``imagePath``, or ``images/<stem>.*``.

    ``by_stem`` is the image with the JSON file's stem under ``DATASET/images/`` (or None).
    """
    name = _rel(json_path, dataset)
    embedded = data.get("imageData")
    if isinstance(embedded, str) and embedded:
        return decode_image_data(embedded, name), ""
    tried: list[str] = []
    image_path = data.get("imagePath")
    if isinstance(image_path, str) and image_path:
        found = _file_photo(json_path.parent / image_path, dataset)
        if found is not None:
            return found, ""
        tried.append(f"imagePath {image_path[:80]!r} (relative to the JSON)")
    else:
        tried.append("no imagePath or imageData")
    if by_stem is not None:
        return PhotoRef(name=_rel(by_stem, dataset), path=by_stem), ""
    tried.append(f"{PHOTOS_FOLDER}/{json_path.stem[:80]}.*")
    return None, "; ".join(tried)
