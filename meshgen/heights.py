"""Heights of pieces from height images (``meshgen --heights``) instead of sampled ones.

A height image is a single-channel image of the annotation's size whose level grows with the
height above the belt (8-bit ``L``, or 16-bit/32-bit integer or float). Image ``stem``'s height
image is ``DIR/<stem>.*`` (any depth under ``DIR``; ``--heights auto`` takes ``DATASET/heights/``
beside ``images/``, when it exists).

A piece's height is ``(level - belt) * scale``:

- ``level`` is the :data:`HEIGHT_PERCENTILE`-th percentile of the levels inside the piece's
  footprint (the repaired outline meshgen extrudes), a robust top: it ignores the few
  brightest pixels (sensor spikes, a neighbour's edge) and the lower rim;
- ``belt`` is the median level of the image's pixels outside every annotated polygon (the
  belt; unlabelled small pieces barely move a median);
- ``scale`` is metres per level, :data:`HEIGHT_SCALE_M` unless ``--height-scale-m`` says
  otherwise.

A piece that lies on another gets the height of its top above the belt (its thickness plus
what is under it). A piece without any level above the belt keeps its sampled height (notice
``height_not_above_belt``), as do all pieces of an image whose height image is missing,
unreadable or of another size (a notice for the last two).

The default scale, 1 mm per level, comes from the 18 height images of the real sample
(``cdw_stacked_sample/heights``, 8-bit, belt at level 0-1): its 29 bricks cluster at 44-47
levels above the belt (a brick lying flat; 87-106 for two stacked: twice as many, so the levels
are linear in height from the belt), its 36 wood boards at 15-28 and its 6 concrete pieces at
28-123. At 1 mm per level the bricks are 44-47 mm high, the boards 15-28 mm and the concrete
28-123 mm: each class inside or at the edge of its class table range (brick 40-80, wood 20-60,
concrete 30-100 mm); a standard brick on its flat side (53 mm) would suggest 1.18 mm.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from PIL import Image, ImageDraw, UnidentifiedImageError

from meshgen.annotations import FloatArray, ImageAnnotation, Notice
from meshgen.errors import MeshgenError
from meshgen.imageframe import belt_to_pixels
from meshgen.imagesize import IMAGE_SUFFIXES

HEIGHT_SCALE_M = 0.001
"""Default metres per height-image level (see the module doc for how it was chosen)."""
HEIGHT_PERCENTILE = 90.0
"""Percentile of the levels inside a piece taken as its top."""
HEIGHTS_FOLDER = "heights"
"""The dataset folder ``--heights auto`` takes."""
_MODES = ("L", "I;16", "I;16L", "I;16B", "I", "F")
"""Pillow modes of single-channel images accepted as height images."""


def height_index(option: str, dataset: Path) -> dict[str, Path]:
    """The height images ``--heights option`` names, by stem (``{}`` when off).

    ``option`` is ``""`` (off), ``auto`` (``DATASET/heights/`` when it exists, else none) or a
    folder. Raises :class:`~meshgen.errors.MeshgenError` naming ``--heights`` when a folder
    given by name does not exist.
    """
    if not option:
        return {}
    if option == "auto":
        folder = dataset / HEIGHTS_FOLDER
        if not folder.is_dir():
            return {}
    else:
        folder = Path(option)
        if not folder.is_dir():
            msg = f"--heights: {option!r} is not a folder (give a folder of height images or auto)"
            raise MeshgenError(msg)
    found: dict[str, Path] = {}
    for path in sorted(folder.rglob("*")):
        if path.suffix.lower() in IMAGE_SUFFIXES and path.is_file():
            found.setdefault(path.stem, path)
    return found


@dataclass(frozen=True, slots=True, kw_only=True)
class HeightImage:
    """The levels of one height image, ``(h, w)`` in its own number type, and the belt's
    level."""

    levels: npt.NDArray[np.generic]
    belt_level: float


def _median(values: npt.NDArray[np.generic]) -> float:
    """The median of ``values`` (as :func:`numpy.median`); for 8- and 16-bit levels from their
    histogram, which is several times faster on a million pixels than a partial sort."""
    if values.dtype.kind == "u" and values.dtype.itemsize <= 2:
        cumulative = np.cumsum(np.bincount(values.ravel()))
        count = int(cumulative[-1])
        low = int(np.searchsorted(cumulative, (count - 1) // 2 + 1))
        high = int(np.searchsorted(cumulative, count // 2 + 1))
        return 0.5 * (low + high)
    return float(np.median(values.astype(np.float64)))


def _mask(shape: tuple[int, int], rings_px: Sequence[FloatArray]) -> npt.NDArray[np.bool_]:
    """``(h, w) bool``: True inside any of the ``(n, 2)`` pixel rings."""
    height, width = shape
    image = Image.new("L", (width, height), 0)
    draw = ImageDraw.Draw(image)
    for ring in rings_px:
        if len(ring) >= 3 and np.isfinite(ring).all():
            draw.polygon([(float(u), float(v)) for u, v in ring.tolist()], fill=1)
    return np.asarray(image, dtype=np.uint8) > 0


def read_height_image(
    path: Path, size_px: tuple[int, int], polygons_px: Sequence[FloatArray], name: str
) -> HeightImage | Notice:
    """The height image at ``path`` for an annotation of ``size_px`` ``(w, h)``, or a notice.

    ``polygons_px`` are all the image's annotated polygons (the belt is what lies outside
    them); ``name`` names the annotation file in a notice.
    """
    try:
        with Image.open(path) as image:
            if image.size != size_px:
                detail = (
                    f"{path.name} is {image.size[0]}x{image.size[1]} px, the annotation "
                    f"{size_px[0]}x{size_px[1]}: heights sampled"
                )
                return Notice(
                    file=name, where="", reason="height_image_size_mismatch", detail=detail
                )
            if image.mode not in _MODES:
                detail = f"{path.name}: mode {image.mode} is not a single-channel height image"
                return Notice(file=name, where="", reason="height_image_unreadable", detail=detail)
            levels = np.asarray(image)
    except (OSError, UnidentifiedImageError, ValueError, SyntaxError) as exc:
        detail = f"{path.name}: {str(exc).splitlines()[0][:120] if str(exc) else exc!r}"
        return Notice(file=name, where="", reason="height_image_unreadable", detail=detail)
    if levels.ndim != 2 or not levels.size:
        detail = f"{path.name}: not a two-dimensional image"
        return Notice(file=name, where="", reason="height_image_unreadable", detail=detail)
    outside = ~_mask((levels.shape[0], levels.shape[1]), polygons_px)
    belt = _median(levels[outside]) if outside.any() else float(levels.min())
    return HeightImage(levels=levels, belt_level=belt)


def piece_level(image: HeightImage, ring_px: FloatArray, percentile: float) -> float | None:
    """The ``percentile`` of the levels inside ``(n, 2)`` pixel ring ``ring_px`` above the belt.

    None when the ring covers no pixel centre.
    """
    height, width = image.levels.shape
    low = np.floor(ring_px.min(axis=0)).astype(int)
    high = np.ceil(ring_px.max(axis=0)).astype(int) + 1
    u0, v0 = max(int(low[0]), 0), max(int(low[1]), 0)
    u1, v1 = min(int(high[0]), width), min(int(high[1]), height)
    if u1 <= u0 or v1 <= v0:
        return None
    inside = _mask((v1 - v0, u1 - u0), [ring_px - np.array([u0, v0], dtype=np.float64)])
    values = image.levels[v0:v1, u0:u1][inside]
    if not len(values):
        return None
    return float(np.percentile(values.astype(np.float64), percentile)) - image.belt_level


def piece_heights_m(
    image: HeightImage,
    rings_px: Sequence[FloatArray],
    *,
    scale_m: float,
    percentile: float,
) -> list[float | None]:
    """Each ring's height in m from ``image`` (None where nothing lies above the belt)."""
    out: list[float | None] = []
    for ring in rings_px:
        level = piece_level(image, ring, percentile)
        out.append(level * scale_m if level is not None and level > 0.0 else None)
    return out


def measured_heights_m(
    anns: Sequence[ImageAnnotation],
    pieces: Sequence[tuple[int, str, FloatArray]],
    height_images: Mapping[str, Path],
    *,
    belt_width_m: float,
    scale_m: float,
    percentile: float,
) -> tuple[list[float | None], list[list[Notice]]]:
    """Each piece's height in m from its image's height image, and each image's notices.

    ``pieces`` are ``(image index into anns, polygon's place in its file, (n, 2) belt-frame
    footprint ring in m)``. A piece's height is None (it keeps its sampled height) when its
    image has no usable height image or nothing of it lies above the belt (a notice says so).
    """
    found: list[float | None] = [None] * len(pieces)
    notices: list[list[Notice]] = [[] for _ in anns]
    per_image: dict[int, list[int]] = {}
    for k, (img, _, _) in enumerate(pieces):
        if anns[img].stem in height_images:
            per_image.setdefault(img, []).append(k)
    for img, members in per_image.items():
        ann = anns[img]
        image = read_height_image(
            height_images[ann.stem],
            (ann.width_px, ann.height_px),
            [poly.points_px for poly in ann.polygons],
            ann.source,
        )
        if isinstance(image, Notice):
            notices[img].append(image)
            continue
        m_per_px = belt_width_m / ann.width_px
        rings = [
            belt_to_pixels(pieces[k][2], ann.width_px, ann.height_px, m_per_px) for k in members
        ]
        heights = piece_heights_m(image, rings, scale_m=scale_m, percentile=percentile)
        for k, height in zip(members, heights, strict=True):
            found[k] = height
            if height is None:
                detail = f"nothing above the belt level {image.belt_level:g} inside the polygon"
                notices[img].append(
                    Notice(
                        file=ann.source,
                        where=pieces[k][1],
                        reason="height_not_above_belt",
                        detail=detail,
                    )
                )
    return found, notices
