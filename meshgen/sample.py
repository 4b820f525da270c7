"""The built-in procedural sample: a YOLO-seg dataset of CDW outlines on a 0.6 m belt.

The footprints follow the real CDW sample's per-class distributions of length, width, area and
fill (:mod:`meshgen.sample_stats`, stored in ``meshgen/cdw_sample_stats.json``): the class mix
is the real one, each class's dimensions are drawn by :mod:`meshgen.sample_dims` and the
outlines (irregular, concave for rubber and some wood and concrete) are made by
:mod:`meshgen.sample_shapes`. Each image gets ``objects_per_image`` objects (3 to 7 by default:
with the objects cut by the border left out, as meshgen skips them, that is about the real
sample's 4.5 objects per image, hence its stream density). Every fourth image has one object cut
by the image border; its dimensions are drawn independently, as it is never measured. Image
sizes alternate between 1024x960 and 990x990 like the real sample, and each image is written as
a small blank grayscale PNG so that its size is read from the header. Heights are not part of
the sample: meshgen draws them from its class table. Written files: ``data.yaml``,
``images/<stem>.png``, ``labels/<stem>.txt``.

Example::

    cdw-twin sample --out /tmp/sample            # DEFAULT_IMAGES images, seed 0
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshgen.errors import DatasetError, OutputError
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
SAMPLE_VERSION = 2
"""Changes whenever the same arguments give a different sample (caches key on it)."""
MARGIN_PX = 20


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


def _label_line(
    rng: np.random.Generator, cls_id: int, ring_m: np.ndarray, size_px: tuple[int, int], cut: bool
) -> str:
    """The YOLO-seg line of one outline, turned and placed in the image (or on its border)."""
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
    return f"{cls_id} " + " ".join(f"{v:.6f}" for v in norm.ravel())


def write_sample(
    out: Path,
    images: int = DEFAULT_IMAGES,
    seed: int = 0,
    objects_per_image: tuple[int, int] = (3, 7),
    stats: SampleStats | None = None,
) -> SampleSummary:
    """Write the procedural YOLO-seg sample to ``out`` (created; files replaced atomically).

    Each image holds between ``objects_per_image[0]`` and ``objects_per_image[1]`` objects;
    ``stats`` defaults to the stored real-sample statistics.
    """
    if images < 1:
        msg = f"--images must be >= 1, got {images}"
        raise OutputError(msg)
    lo, hi = objects_per_image
    if not 1 <= lo <= hi:
        msg = f"objects per image must satisfy 1 <= min <= max, got {objects_per_image}"
        raise OutputError(msg)
    stats = load_sample_stats() if stats is None else stats
    class_ids = {name: i for i, name in enumerate(CLASS_NAMES)}
    unknown = sorted(set(stats.classes) - set(class_ids))
    if unknown or not stats.classes:
        msg = f"sample statistics {stats.source!r}: classes {unknown} are not among {CLASS_NAMES}"
        raise DatasetError(msg)
    out = Path(out)
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "labels").mkdir(parents=True, exist_ok=True)
    table = "\n".join(f"  {i}: {n}" for i, n in enumerate(CLASS_NAMES))
    _atomic(out / "data.yaml", f"# cdw-twin procedural sample\npath: .\nnames:\n{table}\n".encode())
    rng = np.random.default_rng(seed)
    slots = _slots(rng, images, lo, hi)
    measured = iter(_measured_objects(rng, stats, sum(not s.cut for s in slots)))
    names = list(stats.classes)
    mix = np.array([stats.classes[n].objects for n in names], dtype=np.float64)
    lines: list[list[str]] = [[] for _ in range(images)]
    for slot in slots:
        if slot.cut:
            name = names[int(rng.choice(len(names), p=mix / mix.sum()))]
            length, width, fill = draw_one(rng, stats.classes[name]).tolist()
        else:
            name, length, width, fill = next(measured)
        ring = outline(rng, name, length, width, fill)
        size = SIZES_PX[slot.image % len(SIZES_PX)]
        lines[slot.image].append(_label_line(rng, class_ids[name], ring, size, slot.cut))
    for i in range(images):
        stem = f"sample_{i:03d}"
        width, height = SIZES_PX[i % len(SIZES_PX)]
        _atomic(out / "labels" / f"{stem}.txt", ("\n".join(lines[i]) + "\n").encode())
        _atomic(out / "images" / f"{stem}.png", png_bytes(width, height))
    cuts = sum(s.cut for s in slots)
    return SampleSummary(out=out, images=images, objects=len(slots), border_objects=cuts)


def _atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(data)
    tmp.replace(path)
