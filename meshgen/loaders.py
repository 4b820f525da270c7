"""Dataset discovery and parsing of YOLO-seg, COCO polygon and labelme annotations.

Layouts understood (``DATASET`` is the folder given on the command line):

- YOLO segmentation: ``DATASET/data.yaml`` (Ultralytics ``names`` as list or mapping) and label
  files ``DATASET/labels/**/*.txt`` (or ``DATASET/*.txt``), one object per line
  ``class x1 y1 x2 y2 ...`` normalised to [0, 1]. Image sizes come from an image with the same
  stem under ``DATASET/images/**`` or next to the label (header only), else from a labelme JSON
  with the same stem in the dataset, else from ``--image-size``.
- COCO: one JSON with ``images``, ``annotations`` (polygon ``segmentation``) and ``categories``
  at ``DATASET/*.json`` or ``DATASET/annotations/*.json``. A file with ``images`` and
  ``annotations`` whose ``images``, ``annotations`` or ``categories`` is not a list (or is
  null, or missing), or which gives one image id twice, is skipped whole with the reason; an
  annotation whose ``image_id`` is not among the images is skipped on its own.
- labelme: ``DATASET/labelme/**/*.json`` or ``DATASET/*.json`` with ``shapes``,
  ``imageWidth`` and ``imageHeight``.

``auto`` picks COCO (when some file is a COCO document: all three fields lists), then labelme
when ``DATASET/labelme/`` holds JSON (the pixel coordinates as annotated; a YOLO conversion
beside them is normalised and rounded), then YOLO with images, then labelme when some
``DATASET/*.json`` has ``shapes``, then YOLO without images, then labelme files that cannot be
decoded (to report them). A stray JSON that is neither, next to YOLO labels, is ignored.
Sizes are read per image from a real source, never assumed; an image file's header wins over an
annotation's size fields (a photo under ``DATASET/images/`` before any other image file of the
same stem; never a height image under ``DATASET/heights/``). A UTF-8 byte order mark at the
start of a label or JSON file is ignored.
Each annotation also says where its photo is (:mod:`meshgen.photos`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from itertools import chain
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from meshgen.annotations import ImageAnnotation, RawPolygon, Skip
from meshgen.errors import DatasetError
from meshgen.heights import HEIGHTS_FOLDER
from meshgen.imagesize import IMAGE_SUFFIXES, read_image_size
from meshgen.jsondoc import NOT_DECODED, loads_exact, without_bom
from meshgen.photos import beside_label, coco_photo, labelme_photo, photo_index, yolo_photo

FORMATS: tuple[str, ...] = ("auto", "yolo", "coco", "labelme")
OUT_OF_RANGE_FRACTION = 0.05
"""Coordinates further than this fraction of the image size outside it are rejected."""
NORMALISED_LIMIT = 1e6
"""YOLO values beyond this are out of range before they are scaled to pixels (so that the
scaling cannot overflow)."""
COCO_FIELDS: tuple[str, ...] = ("images", "annotations", "categories")
"""The top-level fields of a COCO document; each must be a list."""


@dataclass(frozen=True, slots=True, kw_only=True)
class ImageSource:
    """One unit of work: an annotation file still to parse, or an image COCO already parsed.

    ``photo`` is the image file found for the stem at discovery (:mod:`meshgen.photos`): a
    YOLO label's photo, a labelme file's last-resort photo.
    """

    fmt: str
    stem: str
    path: Path
    size_px: tuple[int, int] | None = None
    class_names: tuple[tuple[int, str], ...] = ()
    parsed: ImageAnnotation | None = None
    photo: Path | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class DatasetListing:
    """What discovery found: the resolved format, the images to process and file-level skips."""

    fmt: str
    sources: tuple[ImageSource, ...]
    skips: tuple[Skip, ...]


def _rel(path: Path, root: Path) -> str:
    try:
        return path.relative_to(root).as_posix()
    except ValueError:
        return path.as_posix()


def _image_index(dataset: Path) -> dict[str, Path]:
    """Every image file of the dataset by stem: the photos under ``images/`` first; never a
    height image (``heights/``, :mod:`meshgen.heights`)."""
    images: dict[str, Path] = photo_index(dataset)
    heights = dataset / HEIGHTS_FOLDER
    named = sorted(p for p in dataset.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES)
    for path in named:
        if path.is_file() and not path.is_relative_to(heights):
            images.setdefault(path.stem, path)
    return images


def _yolo_label_files(dataset: Path) -> list[Path]:
    labels = dataset / "labels"
    files = sorted(labels.rglob("*.txt")) if labels.is_dir() else []
    if not files:
        files = sorted(p for p in dataset.glob("*.txt") if p.is_file())
    return files


def _json_files(folder: Path, recursive: bool) -> list[Path]:
    if not folder.is_dir():
        return []
    found = folder.rglob("*.json") if recursive else folder.glob("*.json")
    return sorted(p for p in found if p.is_file())


def _peek_json(path: Path) -> Any:
    """The decoded JSON document at ``path`` (a leading BOM ignored), or None when unreadable."""
    try:
        data = loads_exact(without_bom(path.read_bytes()))
        if data is NOT_DECODED:
            data = json.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return data


_JSON_KINDS: dict[type, str] = {
    type(None): "null",
    bool: "a boolean",
    int: "a number",
    float: "a number",
    str: "a string",
    dict: "an object",
    list: "a list",
}


def coco_layout_problem(data: Any) -> str:
    """Why ``data`` is not a COCO document ("" when it is): each of ``COCO_FIELDS`` a list."""
    if not isinstance(data, dict):
        return "the top level is not a JSON object"
    for field in COCO_FIELDS:
        if field not in data:
            return f'field "{field}" is missing'
        value = data[field]
        if not isinstance(value, list):
            return f'field "{field}" is {_JSON_KINDS.get(type(value), "not a list")}, not a list'
    return ""


def _coco_candidates(dataset: Path) -> list[tuple[Path, bool]]:
    """JSON files with ``images`` and ``annotations``, each with whether it is a COCO document."""
    candidates = _json_files(dataset, False) + _json_files(dataset / "annotations", False)
    out = []
    for path in candidates:
        data = _peek_json(path)
        if isinstance(data, dict) and "annotations" in data and "images" in data:
            out.append((path, not coco_layout_problem(data)))
    return out


def _labelme_candidates(dataset: Path) -> tuple[list[Path], bool]:
    """The labelme files of ``dataset`` and whether any is a labelme document.

    Files under ``DATASET/labelme/`` count as labelme documents unread. At the top level, JSON
    with ``shapes`` is listed, and JSON that cannot be decoded too (so that parsing reports it),
    but only the former makes the dataset look like a labelme one.
    """
    files = _json_files(dataset / "labelme", True)
    if files:
        return files, True
    out = []
    documents = False
    for path in _json_files(dataset, False):
        data = _peek_json(path)
        if isinstance(data, dict) and "shapes" in data:
            out.append(path)
            documents = True
        elif data is None:
            out.append(path)
    return out, documents


def _labelme_files(dataset: Path) -> list[Path]:
    return _labelme_candidates(dataset)[0]


def load_yolo_names(dataset: Path) -> dict[int, str]:
    """Class names of a YOLO dataset from ``data.yaml`` (``names`` as a list or a mapping)."""
    import yaml

    for name in ("data.yaml", "dataset.yaml", "data.yml"):
        path = dataset / name
        if path.is_file():
            break
    else:
        msg = f"{dataset}: no data.yaml with class names found for the YOLO labels"
        raise DatasetError(msg)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        msg = f"{path}: cannot read class names: {exc}"
        raise DatasetError(msg) from exc
    names = data.get("names") if isinstance(data, dict) else None
    if isinstance(names, list):
        return {i: str(n) for i, n in enumerate(names)}
    if isinstance(names, dict):
        out: dict[int, str] = {}
        for key, value in names.items():
            try:
                out[int(key)] = str(value)
            except (TypeError, ValueError) as exc:
                msg = f"{path}: names: class id {key!r} is not an integer"
                raise DatasetError(msg) from exc
        return out
    msg = f'{path}: field "names" must be a list or a mapping of class id to name'
    raise DatasetError(msg)


def _labelme_size(path: Path) -> tuple[int, int] | None:
    data = _peek_json(path)
    if not isinstance(data, dict):
        return None
    width, height = data.get("imageWidth"), data.get("imageHeight")
    if isinstance(width, int) and isinstance(height, int) and width > 0 and height > 0:
        return width, height
    return None


def _detect(dataset: Path) -> tuple[str, list[Path]]:
    """The format ``auto`` resolves to, with the labelme files when that format is labelme."""
    if any(valid for _, valid in _coco_candidates(dataset)):
        return "coco", []
    in_folder = _json_files(dataset / "labelme", True)
    if in_folder:
        return "labelme", in_folder
    yolo = _yolo_label_files(dataset) if (dataset / "data.yaml").is_file() else []
    if yolo and _image_index(dataset):
        return "yolo", []
    labelme, documents = _labelme_candidates(dataset)
    if labelme and (documents or not yolo):
        return "labelme", labelme
    if yolo:
        return "yolo", []
    msg = (
        f"{dataset}: no annotations found (looked for COCO JSON, data.yaml + labels/*.txt, "
        "labelme/*.json)"
    )
    raise DatasetError(msg)


def discover(
    dataset: Path, fmt: str = "auto", image_size: tuple[int, int] | None = None
) -> DatasetListing:
    """List the images of ``dataset`` in ``fmt`` (``auto`` detects), sorted by stem."""
    if not dataset.is_dir():
        msg = f"{dataset}: dataset folder does not exist"
        raise DatasetError(msg)
    if fmt not in FORMATS:
        msg = f"--format: unknown format {fmt!r}, expected one of {', '.join(FORMATS)}"
        raise DatasetError(msg)
    resolved, labelme_files = _detect(dataset) if fmt == "auto" else (fmt, [])
    skips: list[Skip] = []
    sources: list[ImageSource] = []
    if resolved == "yolo":
        names = tuple(sorted(load_yolo_names(dataset).items()))
        images = _image_index(dataset)
        photos = photo_index(dataset)
        labelme = {p.stem: p for p in _labelme_files(dataset)}
        for path in _yolo_label_files(dataset):
            size = read_image_size(images[path.stem]) if path.stem in images else None
            if size is None and path.stem in labelme:
                size = _labelme_size(labelme[path.stem])
            sources.append(
                ImageSource(
                    fmt="yolo",
                    stem=path.stem,
                    path=path,
                    size_px=size or image_size,
                    class_names=names,
                    photo=photos.get(path.stem) or beside_label(path),
                )
            )
    elif resolved == "labelme":
        photos = photo_index(dataset)
        sources = [
            ImageSource(
                fmt="labelme", stem=p.stem, path=p, size_px=image_size, photo=photos.get(p.stem)
            )
            for p in labelme_files or _labelme_files(dataset)
        ]
    else:
        files = [path for path, _ in _coco_candidates(dataset)]
        if not files:
            msg = f'{dataset}: no COCO JSON (with "images" and "annotations") found'
            raise DatasetError(msg)
        images = _image_index(dataset)
        for path in files:
            parsed, file_skips = parse_coco(path, dataset, images, image_size)
            skips.extend(file_skips)
            sources.extend(
                ImageSource(fmt="coco", stem=a.stem, path=path, parsed=a) for a in parsed
            )
    if not sources and not skips:
        msg = f"{dataset}: no {resolved} annotation files found"
        raise DatasetError(msg)
    unique: dict[str, ImageSource] = {}
    for source in sorted(sources, key=lambda s: (s.stem, s.path.as_posix())):
        if source.stem in unique:
            first = _rel(unique[source.stem].path, dataset)
            skips.append(
                Skip(
                    file=_rel(source.path, dataset),
                    where="",
                    reason="duplicate_image",
                    detail=f"image stem {source.stem!r} already given by {first}",
                )
            )
            continue
        unique[source.stem] = source
    return DatasetListing(fmt=resolved, sources=tuple(unique.values()), skips=tuple(skips))


def _check_range(points: np.ndarray, width: int, height: int) -> str | None:
    if not np.isfinite(points).all():
        return "not_a_number"
    margin_u = OUT_OF_RANGE_FRACTION * width
    margin_v = OUT_OF_RANGE_FRACTION * height
    u, v = points[:, 0], points[:, 1]
    if (
        u.min() < -margin_u
        or u.max() > width + margin_u
        or v.min() < -margin_v
        or v.max() > height + margin_v
    ):
        return "out_of_range"
    return None


class _Bad(NamedTuple):
    """Why one polygon (a label line, a shape, an annotation) is skipped."""

    reason: str
    detail: str


def _yolo_text(source: ImageSource, name: str) -> tuple[str, tuple[int, int]] | Skip:
    """The text and image size of a YOLO label file, or the skip of the whole file."""
    try:
        text = source.path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        return Skip(file=name, where="", reason="unreadable_file", detail=str(exc))
    if not text.strip():
        return Skip(file=name, where="", reason="empty_file", detail="no label lines")
    if source.size_px is None:
        detail = "no image file, no labelme JSON with the same stem and no --image-size"
        return Skip(file=name, where="", reason="missing_image_size", detail=detail)
    return text, source.size_px


def _yolo_class(token: str, names: dict[int, str]) -> str | _Bad:
    """The class name of a label line's class field, or why it names none."""
    try:
        class_id = int(token)
    except ValueError:
        return _Bad("bad_class_id", f"class field {token!r} is not an integer")
    if class_id < 0:
        return _Bad("bad_class_id", f"class id {class_id} is negative")
    if class_id not in names:
        return _Bad("unknown_class_id", f"class id {class_id} not in data.yaml names")
    return names[class_id]


def _yolo_points(coords: list[str], width: int, height: int) -> np.ndarray | _Bad:
    """The ``(n, 2)`` pixel points of a label line's normalised coordinates, or why not."""
    if len(coords) % 2:
        return _Bad("odd_coordinates", f"{len(coords)} coordinates (must be x y pairs)")
    try:
        values = np.array(coords, dtype=np.float64)
    except ValueError:
        bad_tok = next(t for t in coords if not _is_float(t))
        return _Bad("not_a_number", f"value {bad_tok!r} is not a number")
    if len(values) < 6:
        return _Bad("too_few_points", f"{len(values) // 2} point(s), need at least 3")
    problem: str | None
    if not np.abs(values).max() <= NORMALISED_LIMIT:  # also true for nan
        problem = "out_of_range" if np.isfinite(values).all() else "not_a_number"
    else:
        points = values.reshape(-1, 2) * np.array([width, height], dtype=np.float64)
        problem = _check_range(points, width, height)
    if problem is None:
        return points
    detail = (
        "non-finite value"
        if problem == "not_a_number"
        else f"normalised coordinates span [{values.min():.4g}, {values.max():.4g}]"
    )
    return _Bad(problem, detail)


def _yolo_polygon(
    tokens: list[str], names: dict[int, str], width: int, height: int
) -> tuple[str, np.ndarray] | _Bad:
    """The class name and ``(n, 2)`` pixel points of one label line's tokens, or why not."""
    class_name = _yolo_class(tokens[0], names)
    if isinstance(class_name, _Bad):
        return class_name
    points = _yolo_points(tokens[1:], width, height)
    if isinstance(points, _Bad):
        return points
    return class_name, points


def parse_yolo(source: ImageSource, root: Path) -> tuple[ImageAnnotation | None, list[Skip]]:
    """Parse one YOLO-seg label file; bad lines become skips, good lines polygons."""
    name = _rel(source.path, root)
    loaded = _yolo_text(source, name)
    if isinstance(loaded, Skip):
        return None, [loaded]
    text, (width, height) = loaded
    names = dict(source.class_names)
    polygons: list[RawPolygon] = []
    skips: list[Skip] = []
    index = -1
    for lineno, line in enumerate(text.splitlines(), start=1):
        tokens = line.split()
        if not tokens:
            continue
        index += 1
        where = f"line {lineno}"
        found = _yolo_polygon(tokens, names, width, height)
        if isinstance(found, _Bad):
            skips.append(Skip(file=name, where=where, reason=found.reason, detail=found.detail))
            continue
        class_name, points = found
        polygons.append(
            RawPolygon(index=index, where=where, class_name=class_name, points_px=points)
        )
    photo, searched = yolo_photo(source.photo, root)
    annotation = ImageAnnotation(
        stem=source.stem,
        source=name,
        width_px=width,
        height_px=height,
        polygons=tuple(polygons),
        skips=tuple(skips),
        photo=photo,
        photo_searched=searched,
    )
    return annotation, []


def _is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _points_from_json(raw: Any, fast: bool) -> tuple[np.ndarray | None, str, str]:
    """Convert a JSON point list to ``(n, 2) float``; on failure return (None, reason, detail).

    ``fast`` may be set when the file has no ``true``/``false`` literals: a numeric ``(n, 2)``
    array then needs no per-value checks.
    """
    if fast and isinstance(raw, list):
        try:
            arr = np.array(raw)
        except ValueError:
            arr = None
        if arr is not None and arr.ndim == 2 and arr.shape[1] == 2 and arr.dtype.kind in "if":
            if len(arr) < 3:
                return None, "too_few_points", f"{len(arr)} point(s), need at least 3"
            if not np.isfinite(arr).all():
                return None, "not_a_number", "a coordinate is not finite"
            return arr.astype(np.float64), "", ""
    if not isinstance(raw, list):
        return None, "bad_file", "points is not a list"
    flat: list[float] = []
    for item in raw:
        if not isinstance(item, list) or len(item) != 2:
            return None, "odd_coordinates", f"point {item!r} is not an [x, y] pair"
        for value in item:
            if isinstance(value, bool) or not isinstance(value, int | float):
                return None, "not_a_number", f"value {value!r} is not a number"
            if not math.isfinite(value):
                return None, "not_a_number", f"value {value!r} is not finite"
            flat.append(float(value))
    if len(flat) < 6:
        return None, "too_few_points", f"{len(flat) // 2} point(s), need at least 3"
    return np.array(flat, dtype=np.float64).reshape(-1, 2), "", ""


def points_one_by_one(
    raws: list[Any], fast: bool, width: int, height: int
) -> list[tuple[np.ndarray | None, str, str]]:
    """Each point list converted and checked on its own: ``(points or None, reason, detail)``."""
    out: list[tuple[np.ndarray | None, str, str]] = []
    for raw in raws:
        pts, reason, detail = _points_from_json(raw, fast)
        if pts is not None:
            problem = _check_range(pts, width, height)
            if problem is not None:
                pts, reason = None, problem
                detail = f"pixel coordinates outside the {width}x{height} image"
        out.append((pts, reason, detail))
    return out


def _checked_points(
    raws: list[Any], fast: bool, width: int, height: int
) -> list[tuple[np.ndarray | None, str, str]]:
    """:func:`_points_from_json` and :func:`_check_range` of every point list of one file.

    Returns per list its ``(n, 2) float`` points or ``(None, reason, detail)``. With ``fast``
    (see :func:`_points_from_json`), when all lists together form one numeric ``(N, 2)`` array,
    that array is built with one numpy call and the per-list checks (at least 3 points, all
    finite, inside the image) are vectorised over it; the lists' points are views of it.
    Otherwise (some list is malformed) each list is converted and checked on its own, with
    the same results.
    """
    points = _numeric_pairs(raws) if fast and raws else None
    if points is None:
        return points_one_by_one(raws, fast, width, height)
    sizes = np.fromiter(map(len, raws), dtype=np.int64, count=len(raws))
    ends = np.cumsum(sizes)
    starts = ends - sizes
    live = sizes > 0
    finite = np.ones(len(raws), dtype=bool)
    inside = np.ones(len(raws), dtype=bool)
    if live.any():
        at = starts[live]
        if points.dtype.kind == "f":
            both = np.isfinite(points[:, 0]) & np.isfinite(points[:, 1])
            finite[live] = np.logical_and.reduceat(both, at)
        margin = np.array([OUT_OF_RANGE_FRACTION * width, OUT_OF_RANGE_FRACTION * height])
        low = np.minimum.reduceat(points, at) >= -margin
        high = np.maximum.reduceat(points, at) <= np.array([width, height]) + margin
        within = low & high
        inside[live] = within[:, 0] & within[:, 1]
    as_float = points.astype(np.float64)
    out: list[tuple[np.ndarray | None, str, str]] = []
    for start, end, size, ok, within in zip(
        starts.tolist(),
        ends.tolist(),
        sizes.tolist(),
        finite.tolist(),
        inside.tolist(),
        strict=True,
    ):
        if size < 3:
            out.append((None, "too_few_points", f"{size} point(s), need at least 3"))
        elif not ok:
            out.append((None, "not_a_number", "a coordinate is not finite"))
        elif not within:
            detail = f"pixel coordinates outside the {width}x{height} image"
            out.append((None, "out_of_range", detail))
        else:
            out.append((as_float[start:end], "", ""))
    return out


def _numeric_pairs(raws: list[Any]) -> np.ndarray | None:
    """All point lists of ``raws`` as one ``(N, 2)`` int or float array, or None if malformed.

    Every point must be a list of two numbers. Their numbers go to ``np.array`` as one flat
    list, which numpy converts several times faster than the nested lists, with the same values
    and dtype. Every point has length two (checked in one C-level pass); anything else of
    length two that JSON gives (a string, an object's keys) flattens to strings, which the
    dtype check rejects, and a number or ``null`` has no length.
    """
    if not all(type(raw) is list for raw in raws):
        return None
    points: list[Any] = []
    for raw in raws:
        points += raw
    try:
        if set(map(len, points)) != {2}:
            return None  # also when there are no points at all (as np.array([]) is 1-D)
        arr = np.array(list(chain.from_iterable(points)))
    except (ValueError, TypeError, OverflowError):
        return None
    if arr.ndim != 1 or arr.dtype.kind not in "if":
        return None
    return arr.reshape(-1, 2)


def _read_labelme(path: Path, name: str) -> tuple[Any, bool] | Skip:
    """The decoded document of a labelme file and whether it is free of ``true``/``false``.

    A file that cannot be read, is blank or is not JSON gives its file-level skip instead.
    orjson decodes the file when it gives what ``json`` gives
    (:func:`meshgen.jsondoc.loads_exact`); everything else, errors included, goes the standard
    way (``read_text``, ``json.loads``). The literal check is the ``fast`` flag of
    :func:`_points_from_json`.
    """
    try:
        raw = path.read_bytes()
    except OSError:
        raw = b""  # the standard route below reports the error
    data = loads_exact(without_bom(raw)) if raw else NOT_DECODED
    if data is not NOT_DECODED:
        return data, b"true" not in raw and b"false" not in raw
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        return Skip(file=name, where="", reason="unreadable_file", detail=str(exc))
    if not text.strip():
        return Skip(file=name, where="", reason="empty_file", detail="file is empty")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        detail = f"invalid JSON at line {exc.lineno} column {exc.colno}: {exc.msg}"
        return Skip(file=name, where="", reason="unreadable_file", detail=detail)
    return data, "true" not in text and "false" not in text


def _labelme_image_size(data: dict[str, Any], source: ImageSource) -> tuple[int, int] | None:
    """The image size of a labelme document: its image file, its size fields, ``--image-size``.

    The header of the image file named by ``imagePath`` wins over ``imageWidth`` and
    ``imageHeight``; ``source.size_px`` (``--image-size``) is the last resort.
    """
    size: tuple[int, int] | None = None
    image_path = data.get("imagePath")
    if isinstance(image_path, str) and image_path:
        candidate = source.path.parent / image_path
        if candidate.is_file():
            size = read_image_size(candidate)
    if size is None:
        width, height = data.get("imageWidth"), data.get("imageHeight")
        if isinstance(width, int) and isinstance(height, int) and width > 0 and height > 0:
            size = (width, height)
    return size or source.size_px


def _labelme_label(shape: Any) -> str | _Bad:
    """The class label of one entry of ``shapes``, or why it is no polygon of a class."""
    if not isinstance(shape, dict):
        return _Bad("bad_file", "not an object")
    shape_type = shape.get("shape_type", "polygon")
    if shape_type != "polygon":
        return _Bad("not_a_polygon", f"shape_type {shape_type!r}")
    label = shape.get("label")
    if not isinstance(label, str) or not label:
        return _Bad("unknown_class", f"label {label!r} is not a class name")
    return label


def _labelme_polygons(
    shapes: list[Any], name: str, fast: bool, size: tuple[int, int]
) -> tuple[list[RawPolygon], list[Skip]]:
    """The polygons of a labelme ``shapes`` list and the skips of the rest, in shape order.

    Shapes are sorted out one by one (:func:`_labelme_label`); the point lists of the ones with
    a class label are then converted and checked together (:func:`_checked_points`).
    """
    labels = [_labelme_label(shape) for shape in shapes]
    pending = [
        shape.get("points")
        for shape, label in zip(shapes, labels, strict=True)
        if not isinstance(label, _Bad)
    ]
    checked = iter(_checked_points(pending, fast, size[0], size[1]))
    polygons: list[RawPolygon] = []
    skips: list[Skip] = []
    for index, label in enumerate(labels):
        where = f"shape {index}"
        if isinstance(label, _Bad):
            skips.append(Skip(file=name, where=where, reason=label.reason, detail=label.detail))
            continue
        points, reason, detail = next(checked)
        if points is None:
            skips.append(Skip(file=name, where=where, reason=reason, detail=detail))
        else:
            polygons.append(
                RawPolygon(index=index, where=where, class_name=label, points_px=points)
            )
    return polygons, skips


def parse_labelme(source: ImageSource, root: Path) -> tuple[ImageAnnotation | None, list[Skip]]:
    """Parse one labelme JSON file; bad shapes become skips, good shapes polygons."""
    name = _rel(source.path, root)
    loaded = _read_labelme(source.path, name)
    if isinstance(loaded, Skip):
        return None, [loaded]
    data, fast = loaded
    if not isinstance(data, dict) or not isinstance(data.get("shapes"), list):
        detail = 'no "shapes" list at the top level'
        return None, [Skip(file=name, where="", reason="bad_file", detail=detail)]
    if not data["shapes"]:
        return None, [Skip(file=name, where="", reason="empty_file", detail='"shapes" is empty')]
    size = _labelme_image_size(data, source)
    if size is None:
        detail = "no image file, no imageWidth/imageHeight and no --image-size"
        return None, [Skip(file=name, where="", reason="missing_image_size", detail=detail)]
    polygons, skips = _labelme_polygons(data["shapes"], name, fast, size)
    photo, searched = labelme_photo(data, source.path, root, source.photo)
    annotation = ImageAnnotation(
        stem=source.stem,
        source=name,
        width_px=size[0],
        height_px=size[1],
        polygons=tuple(polygons),
        skips=tuple(skips),
        photo=photo,
        photo_searched=searched,
    )
    return annotation, []


def _coco_image_ids(images: list[Any], name: str) -> dict[int, int] | Skip:
    """Image id -> position in ``images``, or the skip of the file when an id is given twice."""
    known: dict[int, int] = {}
    for j, image in enumerate(images):
        if isinstance(image, dict) and isinstance(image.get("id"), int):
            first = known.setdefault(image["id"], j)
            if first != j:
                detail = f"image id {image['id']} is also the id of images[{first}]"
                return Skip(
                    file=name, where=f"images[{j}]", reason="duplicate_image_id", detail=detail
                )
    return known


def _coco_by_image(
    annotations: list[Any], known: dict[int, int], name: str, skips: list[Skip]
) -> dict[int, list[tuple[int, dict[str, Any]]]]:
    """The annotations of each known image id as ``(position, annotation)``, in file order.

    An annotation without an integer ``image_id``, or with one that no image has, is added to
    ``skips``.
    """
    per_image: dict[int, list[tuple[int, dict[str, Any]]]] = {}
    for i, ann in enumerate(annotations):
        where = f"annotations[{i}]"
        if not isinstance(ann, dict) or not isinstance(ann.get("image_id"), int):
            detail = "annotation without an integer image_id"
            skips.append(Skip(file=name, where=where, reason="bad_file", detail=detail))
            continue
        if ann["image_id"] not in known:
            detail = f"image_id {ann['image_id']} is not the id of any entry of images"
            skips.append(Skip(file=name, where=where, reason="unknown_image_id", detail=detail))
            continue
        per_image.setdefault(ann["image_id"], []).append((i, ann))
    return per_image


def _coco_image_size(
    image: dict[str, Any], stem: str, images: dict[str, Path], image_size: tuple[int, int] | None
) -> tuple[int, int] | None:
    """The size of a COCO image: its image file's header, its ``width``/``height``, the option."""
    size = read_image_size(images[stem]) if stem in images else None
    if size is None:
        width, height = image.get("width"), image.get("height")
        if isinstance(width, int) and isinstance(height, int) and width > 0 and height > 0:
            size = (width, height)
    return size or image_size


def _coco_segmentation(seg: Any) -> np.ndarray | _Bad:
    """The largest polygon (at least 3 points) of a ``segmentation`` as ``(n, 2) float``.

    Every part must be a list of an even number of finite numbers; RLE masks are refused.
    """
    if not isinstance(seg, list) or not seg:
        return _Bad("not_a_polygon", "segmentation is not a polygon list (RLE is not supported)")
    parts = seg if isinstance(seg[0], list) else [seg]
    best: np.ndarray | None = None
    for part in parts:
        if not isinstance(part, list) or len(part) % 2:
            return _Bad("odd_coordinates", "segmentation polygon is malformed")
        if not all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for v in part
        ):
            return _Bad("not_a_number", "segmentation polygon is malformed")
        pts = np.array(part, dtype=np.float64).reshape(-1, 2)
        if len(pts) >= 3 and (best is None or len(pts) > len(best)):
            best = pts
    if best is None:
        return _Bad("too_few_points", "no segmentation polygon with at least 3 points")
    return best


def _coco_polygon(
    ann: dict[str, Any], categories: dict[int, str], size: tuple[int, int]
) -> tuple[str, np.ndarray] | _Bad:
    """The class name and ``(n, 2)`` pixel points of one COCO annotation, or why not."""
    category = ann.get("category_id")
    if category not in categories:
        return _Bad("unknown_class_id", f"category_id {category!r} not in categories")
    points = _coco_segmentation(ann.get("segmentation"))
    if isinstance(points, _Bad):
        return points
    range_problem = _check_range(points, size[0], size[1])
    if range_problem is not None:
        return _Bad(range_problem, f"pixel coordinates outside the {size[0]}x{size[1]} image")
    return categories[category], points


def _coco_polygons(
    anns: list[tuple[int, dict[str, Any]]],
    categories: dict[int, str],
    size: tuple[int, int],
    name: str,
    skips: list[Skip],
) -> list[RawPolygon]:
    """The polygons of one image's ``(position, annotation)`` list; the rest go to ``skips``."""
    polygons: list[RawPolygon] = []
    for k, (i, ann) in enumerate(anns):
        where = f"annotations[{i}]"
        found = _coco_polygon(ann, categories, size)
        if isinstance(found, _Bad):
            skips.append(Skip(file=name, where=where, reason=found.reason, detail=found.detail))
            continue
        class_name, points = found
        polygons.append(RawPolygon(index=k, where=where, class_name=class_name, points_px=points))
    return polygons


def parse_coco(
    path: Path, root: Path, images: dict[str, Path], image_size: tuple[int, int] | None
) -> tuple[list[ImageAnnotation], list[Skip]]:
    """Parse a COCO polygon JSON into one annotation per image listed in it.

    A file that is not a COCO document (:func:`coco_layout_problem`) or gives an image id twice
    is skipped whole; annotations are skipped one by one (unknown image or category, bad
    segmentation).
    """
    name = _rel(path, root)
    data = _peek_json(path)
    if not isinstance(data, dict):
        return [], [Skip(file=name, where="", reason="unreadable_file", detail="invalid JSON")]
    problem = coco_layout_problem(data)
    if problem:
        return [], [Skip(file=name, where="", reason="bad_file", detail=problem)]
    known = _coco_image_ids(data["images"], name)
    if isinstance(known, Skip):
        return [], [known]
    categories = {
        cat["id"]: str(cat.get("name"))
        for cat in data["categories"]
        if isinstance(cat, dict) and isinstance(cat.get("id"), int)
    }
    skips: list[Skip] = []
    per_image = _coco_by_image(data["annotations"], known, name, skips)
    photos = photo_index(root)
    out: list[ImageAnnotation] = []
    for j, image in enumerate(data["images"]):
        if not isinstance(image, dict) or not isinstance(image.get("id"), int):
            detail = "image entry without an integer id"
            skips.append(Skip(file=name, where=f"images[{j}]", reason="bad_file", detail=detail))
            continue
        stem = Path(str(image.get("file_name", image["id"]))).stem
        size = _coco_image_size(image, stem, images, image_size)
        if size is None:
            detail = f"image {stem!r}: no image file, no width/height and no --image-size"
            skips.append(
                Skip(file=name, where=f"images[{j}]", reason="missing_image_size", detail=detail)
            )
            continue
        polygons = _coco_polygons(per_image.get(image["id"], []), categories, size, name, skips)
        photo, searched = coco_photo(image.get("file_name"), path, root, photos)
        out.append(
            ImageAnnotation(
                stem=stem,
                source=name,
                width_px=size[0],
                height_px=size[1],
                polygons=tuple(polygons),
                photo=photo,
                photo_searched=searched,
            )
        )
    return out, skips


def load_source(source: ImageSource, root: Path) -> tuple[ImageAnnotation | None, list[Skip]]:
    """Parse one image source (COCO sources are already parsed)."""
    if source.parsed is not None:
        return source.parsed, []
    if source.fmt == "yolo":
        return parse_yolo(source, root)
    return parse_labelme(source, root)
