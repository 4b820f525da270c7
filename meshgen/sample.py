"""The built-in procedural sample: a YOLO-seg dataset of CDW outlines on a 0.6 m belt.

The footprints follow the real CDW sample's per-class distributions of length, width, area and
fill (:mod:`meshgen.sample_stats`, stored in ``meshgen/cdw_sample_stats.json``): the class mix
is the real one, each class's dimensions are drawn by :mod:`meshgen.sample_dims` and the
outlines (irregular, concave for rubber and some wood and concrete) are made by
:mod:`meshgen.sample_shapes`. Each image gets ``objects_per_image`` objects (3 to 7 by default:
with the objects cut by the border left out, as meshgen skips them, that is about the real
sample's 4.5 objects per image, hence its stream density). Every fourth image has one object cut
by the image border; its dimensions are drawn independently, as it is never measured. Image
sizes alternate between 1024x960 and 990x990 like the real sample. Heights are not part of
the sample: meshgen draws them from its class table. Written files: ``data.yaml``,
``images/<stem>.jpg``, ``labels/<stem>.txt``.

Each image is a photo of its labels: every object painted inside its polygon with its class's
pattern (:mod:`meshgen.paint`: speckled grey concrete, granular red-orange brick, grained
brown wood, matte near-black rubber) on a dark belt, as an RGB JPEG. meshgen textures the
meshed pieces from these photos, and a detector can be trained on them. The labels are drawn
first and from their own random stream (:func:`sample_labels`); the photos from other seeds
(``[seed, image, object, PIECE_STREAM]`` and ``[seed, image, BELT_STREAM]``), so the labels,
and the meshes made from them, do not depend on the photos.

Example::

    cdw-twin sample --out /tmp/sample            # DEFAULT_IMAGES images, seed 0
"""

from __future__ import annotations

import io
import math
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from interfaces.class_colours import class_rgb
from meshgen.annotations import FloatArray
from meshgen.errors import DatasetError, OutputError
from meshgen.paint import PaintedPiece, paint_picture
from meshgen.sample_dims import class_counts, draw_dimensions, draw_one
from meshgen.sample_shapes import outline
from meshgen.sample_stats import SampleStats, load_sample_stats

CLASS_NAMES: tuple[str, ...] = ("concrete", "brick", "wood", "rubber")
SIZES_PX: tuple[tuple[int, int], ...] = ((1024, 960), (990, 990))
BELT_WIDTH_M = 0.6
DEFAULT_IMAGES = 96
"""Images of the default sample: enough objects of every class (rubber, the rarest, gets about
60) that each class's length, width and area distributions stay within a Kolmogorov-Smirnov
distance of 0.15 of the real sample's."""
SAMPLE_VERSION = 3
"""Changes whenever the same arguments give a different sample (caches key on it). 3: the
images are photos of the pieces (the labels are those of version 2)."""
MARGIN_PX = 20
PHOTO_QUALITY = 90
"""JPEG quality of the sample's photos."""
PIECE_STREAM = 0x5A3F
"""Last element of an object's photo seed key."""
BELT_STREAM = 0xBE17
"""Last element of an image's belt seed key."""


@dataclass(frozen=True, slots=True, kw_only=True)
class SampleSummary:
    """What :func:`write_sample` wrote."""

    out: Path
    images: int
    objects: int
    border_objects: int


def png_bytes(width_px: int, height_px: int, gray: int = 96) -> bytes:
    """A valid 8-bit grayscale PNG of one flat colour."""
    row = b"\x00" + bytes([gray]) * width_px
    raw = zlib.compress(row * height_px, 9)

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    ihdr = struct.pack(">IIBBBBB", width_px, height_px, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", raw) + chunk(b"IEND", b"")


@dataclass(frozen=True, slots=True)
class _Slot:
    """One object to place: its image, its index there and whether the border cuts it."""

    image: int
    index: int
    cut: bool


def _slots(rng: np.random.Generator, images: int, lo: int, hi: int) -> list[_Slot]:
    slots = []
    for i in range(images):
        n_obj = int(rng.integers(lo, hi + 1))
        slots += [_Slot(image=i, index=k, cut=i % 4 == 3 and k == 0) for k in range(n_obj)]
    return slots


def _measured_objects(
    rng: np.random.Generator, stats: SampleStats, n: int
) -> list[tuple[str, float, float, float]]:
    """Class and (length, width, fill) of the ``n`` measured objects, in random order."""
    objects = []
    for name, count in class_counts(stats, n).items():
        dims = draw_dimensions(rng, stats.classes[name], count)
        objects += [(name, float(row[0]), float(row[1]), float(row[2])) for row in dims]
    return [objects[k] for k in rng.permutation(len(objects))]


@dataclass(frozen=True, slots=True, kw_only=True)
class SampleLabel:
    """One object of the sample: its class, its ``(n, 2) float`` polygon in pixels, its line.

    ``text`` is the YOLO-seg label line (no line end); ``points_px`` the polygon it was
    written from (before rounding to 6 decimals of the normalised coordinates).
    """

    class_id: int
    class_name: str
    points_px: FloatArray
    text: str


def _label_line(
    rng: np.random.Generator, cls_id: int, ring_m: np.ndarray, size_px: tuple[int, int], cut: bool
) -> tuple[str, FloatArray]:
    """The YOLO-seg line of one outline, turned and placed in the image (or on its border), and
    its ``(n, 2)`` pixel polygon."""
    width, height = size_px
    m_per_px = BELT_WIDTH_M / width
    yaw = rng.uniform(-math.pi, math.pi)
    c, s = math.cos(yaw), math.sin(yaw)
    pts_px = ring_m @ np.array([[c, s], [-s, c]]) / m_per_px
    ext_u, ext_v = np.ptp(pts_px[:, 0]), np.ptp(pts_px[:, 1])
    if cut:
        cu, cv = rng.uniform(0.3, 0.7) * width, 0.0
    else:
        cu = rng.uniform(ext_u / 2 + MARGIN_PX, width - ext_u / 2 - MARGIN_PX)
        cv = rng.uniform(ext_v / 2 + MARGIN_PX, height - ext_v / 2 - MARGIN_PX)
    px = pts_px - 0.5 * (pts_px.max(axis=0) + pts_px.min(axis=0)) + np.array([cu, cv])
    px[:, 0] = px[:, 0].clip(0, width - 1)
    px[:, 1] = px[:, 1].clip(0, height - 1)
    norm = px / np.array([width, height])
    return f"{cls_id} " + " ".join(f"{v:.6f}" for v in norm.ravel()), px


def _check(images: int, objects_per_image: tuple[int, int], stats: SampleStats) -> None:
    """Refuse arguments no sample can be drawn from, naming them."""
    if images < 1:
        msg = f"--images must be >= 1, got {images}"
        raise OutputError(msg)
    lo, hi = objects_per_image
    if not 1 <= lo <= hi:
        msg = f"objects per image must satisfy 1 <= min <= max, got {objects_per_image}"
        raise OutputError(msg)
    unknown = sorted(set(stats.classes) - set(CLASS_NAMES))
    if unknown or not stats.classes:
        msg = f"sample statistics {stats.source!r}: classes {unknown} are not among {CLASS_NAMES}"
        raise DatasetError(msg)


def sample_labels(
    images: int = DEFAULT_IMAGES,
    seed: int = 0,
    objects_per_image: tuple[int, int] = (3, 7),
    stats: SampleStats | None = None,
) -> list[list[SampleLabel]]:
    """The objects of every image of the sample :func:`write_sample` writes, in label order.

    All randomness of the labels comes from ``numpy.random.default_rng(seed)``, drawn here
    and nowhere else.
    """
    stats = load_sample_stats() if stats is None else stats
    _check(images, objects_per_image, stats)
    lo, hi = objects_per_image
    class_ids = {name: i for i, name in enumerate(CLASS_NAMES)}
    rng = np.random.default_rng(seed)
    slots = _slots(rng, images, lo, hi)
    measured = iter(_measured_objects(rng, stats, sum(not s.cut for s in slots)))
    names = list(stats.classes)
    mix = np.array([stats.classes[n].objects for n in names], dtype=np.float64)
    labels: list[list[SampleLabel]] = [[] for _ in range(images)]
    for slot in slots:
        if slot.cut:
            name = names[int(rng.choice(len(names), p=mix / mix.sum()))]
            length, width, fill = draw_one(rng, stats.classes[name]).tolist()
        else:
            name, length, width, fill = next(measured)
        ring = outline(rng, name, length, width, fill)
        size = SIZES_PX[slot.image % len(SIZES_PX)]
        text, points = _label_line(rng, class_ids[name], ring, size, slot.cut)
        labels[slot.image].append(
            SampleLabel(class_id=class_ids[name], class_name=name, points_px=points, text=text)
        )
    return labels


def label_text(labels: list[SampleLabel]) -> str:
    """The label file of one image: one line per object."""
    return "\n".join(label.text for label in labels) + "\n"


def sample_photo(
    labels: list[SampleLabel], size_px: tuple[int, int], seed: int, image: int
) -> bytes:
    """The JPEG photo of one image of ``size_px`` ``(w, h)``: its objects on the belt."""
    mm_per_px = 1e3 * BELT_WIDTH_M / size_px[0]
    pieces = [
        PaintedPiece(
            class_name=label.class_name,
            rgb=class_rgb(label.class_name),
            points_px=label.points_px,
            seed_key=(seed, image, k, PIECE_STREAM),
        )
        for k, label in enumerate(labels)
    ]
    picture = paint_picture(
        size_px, pieces, mm_per_px=mm_per_px, background_key=(seed, image, BELT_STREAM)
    )
    buffer = io.BytesIO()
    picture.save(buffer, format="JPEG", quality=PHOTO_QUALITY)
    return buffer.getvalue()


def write_sample(
    out: Path,
    images: int = DEFAULT_IMAGES,
    seed: int = 0,
    objects_per_image: tuple[int, int] = (3, 7),
    stats: SampleStats | None = None,
    *,
    photos: bool = True,
) -> SampleSummary:
    """Write the procedural YOLO-seg sample to ``out`` (created; files replaced atomically).

    Each image holds between ``objects_per_image[0]`` and ``objects_per_image[1]`` objects
    (:func:`sample_labels`) and is written with its photo (:func:`sample_photo`); ``stats``
    defaults to the stored real-sample statistics. A flat grey ``images/<stem>.png`` left by an
    older version of the sample is removed. ``photos=False`` writes that flat grey PNG
    instead of the photo (the same labels, several times faster: for work on the outlines).
    """
    stats = load_sample_stats() if stats is None else stats
    labels = sample_labels(images, seed, objects_per_image, stats)
    out = Path(out)
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "labels").mkdir(parents=True, exist_ok=True)
    table = "\n".join(f"  {i}: {n}" for i, n in enumerate(CLASS_NAMES))
    _atomic(out / "data.yaml", f"# cdw-twin procedural sample\npath: .\nnames:\n{table}\n".encode())
    for i, objects in enumerate(labels):
        stem = f"sample_{i:03d}"
        size = SIZES_PX[i % len(SIZES_PX)]
        _atomic(out / "labels" / f"{stem}.txt", label_text(objects).encode())
        if photos:
            _atomic(out / "images" / f"{stem}.jpg", sample_photo(objects, size, seed, i))
            (out / "images" / f"{stem}.png").unlink(missing_ok=True)
        else:
            _atomic(out / "images" / f"{stem}.png", png_bytes(*size))
            (out / "images" / f"{stem}.jpg").unlink(missing_ok=True)
    count = sum(len(objects) for objects in labels)
    cuts = sum(1 for i in range(images) if i % 4 == 3)
    return SampleSummary(out=out, images=images, objects=count, border_objects=cuts)


def _atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(data)
    tmp.replace(path)
