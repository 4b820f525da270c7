"""Parsed annotations: what a loader hands to the meshing pipeline, in pixels."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

SKIP_REASONS: dict[str, str] = {
    "unreadable_file": "the file cannot be read or decoded",
    "empty_file": "the file holds no annotations",
    "bad_file": "the file is not in the expected layout",
    "missing_image_size": "no image header, annotation size or --image-size for this image",
    "duplicate_image": "another annotation file already gave this image stem",
    "duplicate_image_id": "a COCO file gives one image id twice (the whole file is skipped)",
    "unknown_image_id": "a COCO annotation's image_id is not among the file's images",
    "odd_coordinates": "a polygon has an odd number of coordinates",
    "not_a_number": "a value is not a finite number",
    "bad_class_id": "the class field is not a non-negative integer",
    "unknown_class_id": "the class id is not in data.yaml / the COCO categories",
    "unknown_class": "the shape has no class label",
    "too_few_points": "fewer than 3 points",
    "not_a_polygon": "the shape is not a polygon",
    "out_of_range": "coordinates lie far outside the image",
    "border_truncated": "the object touches the image border and is cut off",
    "degenerate": "nothing of positive area is left after repair",
    "below_min_area": "the repaired footprint is smaller than --min-area-mm2",
}
"""Every skip reason the pipeline reports, with its meaning."""

WARNING_REASONS: dict[str, str] = {
    "photo_missing": "no photo found for the image: its pieces carry a procedural texture",
    "photo_unreadable": "the photo cannot be read or decoded: procedural texture instead",
    "photo_size_mismatch": "the photo's size is not the annotation's: procedural texture instead",
    "height_image_unreadable": "the height image cannot be read: the image's heights are sampled",
    "height_image_size_mismatch": "the height image's size is not the annotation's: sampled",
    "height_not_above_belt": "no level above the belt inside the piece: its height is sampled",
    "default_material": "the class table does not name the class: its pieces take the default",
}
"""Every warning reason: something was made differently than asked, but the meshes were written."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Skip:
    """One skipped object or file: where (file and line/shape) and why."""

    file: str
    where: str
    reason: str
    detail: str

    def message(self) -> str:
        """Human-readable warning line naming file, line and reason."""
        loc = f"{self.file}:{self.where}" if self.where else self.file
        return f"{loc}: skipped ({self.reason}): {self.detail}"


@dataclass(frozen=True, slots=True, kw_only=True)
class Notice:
    """One warning about an image or object: where (file and shape) and what was done instead.

    Unlike a :class:`Skip`, nothing is left out: the meshes are written (see
    :data:`WARNING_REASONS`).
    """

    file: str
    where: str
    reason: str
    detail: str

    def message(self) -> str:
        """Human-readable warning line naming file, place and reason."""
        loc = f"{self.file}:{self.where}" if self.where else self.file
        return f"{loc}: {self.reason}: {self.detail}"


@dataclass(frozen=True, slots=True, kw_only=True)
class PhotoRef:
    """Where the photo an annotation was drawn on is: a file, or bytes embedded in the annotation.

    Exactly one of ``path`` and ``data`` is set; ``name`` says where it came from in messages
    (a path relative to the dataset, or ``labelme/x.json imageData``).
    """

    name: str
    path: Path | None = None
    data: bytes | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class RawPolygon:
    """One annotated polygon as read from the source file.

    ``points_px`` is ``(n, 2) float``: column ``u`` (right) and row ``v`` (down) in pixels.
    ``index`` is the polygon's position in its source file, ``where`` names its line or shape.
    """

    index: int
    where: str
    class_name: str
    points_px: FloatArray


@dataclass(frozen=True, slots=True, kw_only=True)
class ImageAnnotation:
    """All polygons of one image plus the image size in pixels and the skips found while parsing.

    ``photo`` is the image's photo when the dataset has it (:mod:`meshgen.photos`), else None
    and ``photo_searched`` says where it was looked for.
    """

    stem: str
    source: str
    width_px: int
    height_px: int
    polygons: tuple[RawPolygon, ...]
    skips: tuple[Skip, ...] = field(default=())
    photo: PhotoRef | None = None
    photo_searched: str = ""
