"""The texture of each image's pieces: its photo, else a procedural picture of its pieces.

One texture per image, in the image's output folder (:data:`TEXTURE_NAME`), shared by all its
pieces: each piece's OBJ gives every vertex the texture coordinate of its pixel in the photo,
``(u / W, 1 - v / H)`` (:mod:`meshgen.imageframe`), so the texture may have any size.

- **Photo.** The photo the annotation was drawn on (:mod:`meshgen.photos`), as an RGB JPEG
  whose long side is at most ``max_px`` (:data:`TEXTURE_MAX_PX` by default): re-encoded with
  Pillow (quality :data:`JPEG_QUALITY`, downscaled when larger, EXIF dropped). A photo that
  already is exactly that (a baseline or progressive RGB JPEG within the size bound, complete
  up to its end marker, without an EXIF rotation) is copied byte for byte instead: re-encoding
  it would give the same kind of file at about 10 ms per photo, most of a run's time.
- **Procedural.** When the image has no photo, or its photo cannot be decoded, or its size is
  not the annotation's (a notice says which), the texture is a picture of the image's pieces,
  each painted inside its polygon with its class's pattern (:mod:`meshgen.paint`) on the belt,
  long side at most :data:`PROCEDURAL_MAX_PX`. Its pixels are seeded by the run's seed tree:
  piece ``k`` of image ``stem`` by ``[seed, crc32(stem), k, TEXTURE_STREAM]``, the belt by
  ``[seed, crc32(stem), BELT_STREAM]``, so equal seeds give equal textures.

Pixels are taken as stored (an EXIF orientation is not applied), as the sizes meshgen reads
come from the image header.
"""

from __future__ import annotations

import io
import warnings
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from meshgen.annotations import ImageAnnotation, Notice, PhotoRef
from meshgen.errors import MeshgenError
from meshgen.paint import RGB, PaintedPiece, paint_picture

TEXTURE_NAME = "texture.jpg"
"""File name of an image's texture in its output folder."""
TEXTURE_MAX_PX = 1024
"""Default bound on a texture's long side, in pixels (larger photos are downscaled)."""
PROCEDURAL_MAX_PX = 512
"""Long side of a procedural texture, in pixels (about 1.2 mm per pixel on a 0.6 m belt)."""
JPEG_QUALITY = 90
"""JPEG quality of re-encoded and procedural textures."""
TEXTURE_STREAM = 0x7E47
"""Last element of a piece's texture seed key (keeps it apart from the height keys)."""
BELT_STREAM = 0xBE17
"""Last element of an image's belt seed key."""
GROW_PX = 2
"""Procedural pieces are painted this many pixels beyond their outline (filtering margin)."""
_JPEG_END = b"\xff\xd9"
_EXIF_ORIENTATION = 0x0112


@dataclass(frozen=True, slots=True, kw_only=True)
class Texture:
    """The texture file of one image and where it came from.

    ``data`` is the JPEG file, or ``copy_of`` the photo file to copy as it is (then ``data``
    is empty); ``source`` is ``photo`` or ``procedural``; ``photo`` names the photo used
    (``""`` for a procedural texture); ``size_px`` is the texture's ``(w, h)``; ``notice``
    says why a procedural texture replaced the photo (None otherwise).
    """

    data: bytes
    source: str
    photo: str
    size_px: tuple[int, int]
    notice: Notice | None = None
    copy_of: Path | None = None


def _tail(photo: PhotoRef) -> bytes:
    """The last bytes of the photo (where a complete JPEG has its end marker)."""
    if photo.data is not None:
        return photo.data[-64:]
    if photo.path is None:
        return b""
    with photo.path.open("rb") as handle:
        size = handle.seek(0, io.SEEK_END)
        handle.seek(max(0, size - 64))
        return handle.read()


def _copyable(image: Image.Image, photo: PhotoRef, max_px: int) -> bool:
    """True when the photo already is what re-encoding would give in kind (see module doc)."""
    if image.format != "JPEG" or image.mode != "RGB" or max(image.size) > max_px:
        return False
    if not _tail(photo).rstrip(b"\0\r\n ").endswith(_JPEG_END):
        return False
    orientation = image.getexif().get(_EXIF_ORIENTATION, 1)
    return orientation in (0, 1)


def _encode(image: Image.Image, max_px: int) -> tuple[bytes, tuple[int, int]]:
    """``image`` as an RGB JPEG whose long side is at most ``max_px``."""
    width, height = image.size
    scale = min(1.0, max_px / max(width, height))
    target = (max(1, round(width * scale)), max(1, round(height * scale)))
    if scale < 1.0 and image.format == "JPEG":
        image.draft("RGB", target)
    rgb = image.convert("RGB")
    if rgb.size != target:
        rgb = rgb.resize(target, Image.Resampling.LANCZOS, reducing_gap=2.0)
    buffer = io.BytesIO()
    rgb.save(buffer, format="JPEG", quality=JPEG_QUALITY)
    return buffer.getvalue(), target


class PhotoUnusableError(MeshgenError):
    """A photo that cannot give the texture: ``reason`` (a warning reason) and ``detail``."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


def photo_texture(
    photo: PhotoRef, size_px: tuple[int, int], max_px: int = TEXTURE_MAX_PX
) -> tuple[bytes | Path, tuple[int, int]]:
    """The texture of ``photo`` (module doc) and its ``(w, h)``: the JPEG file's bytes, or the
    photo's path when the file itself is the texture (copied as it is).

    ``size_px`` is the annotation's ``(w, h)``. Raises :class:`PhotoUnusableError` for a photo of
    another size (``photo_size_mismatch``) or one that cannot be opened or decoded
    (``photo_unreadable``).
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            source = photo.path if photo.data is None and photo.path is not None else None
            with Image.open(source or io.BytesIO(photo.data or b"")) as image:
                if image.size != size_px:
                    found = f"{image.size[0]}x{image.size[1]}"
                    detail = f"{photo.name} is {found} px, the annotation {size_px[0]}x{size_px[1]}"
                    raise PhotoUnusableError("photo_size_mismatch", detail)
                if _copyable(image, photo, max_px):
                    return (source or photo.data or b""), image.size
                return _encode(image, max_px)
    except (OSError, UnidentifiedImageError, ValueError, SyntaxError, Warning) as exc:
        text = str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__
        raise PhotoUnusableError("photo_unreadable", f"{photo.name}: {text}") from None
    except Image.DecompressionBombError as exc:
        raise PhotoUnusableError("photo_unreadable", f"{photo.name}: {str(exc)[:120]}") from None


def procedural_texture(
    ann: ImageAnnotation, colours: Mapping[str, RGB], *, seed: int, belt_width_m: float
) -> tuple[bytes, tuple[int, int]]:
    """The procedural texture of ``ann`` (module doc) and its ``(w, h)``.

    ``colours`` gives each class's base colour (a class missing from it is grey);
    ``belt_width_m`` (the image's width on the belt) sets the pattern's scale.
    """
    scale = min(1.0, PROCEDURAL_MAX_PX / max(ann.width_px, ann.height_px))
    size = (max(1, round(ann.width_px * scale)), max(1, round(ann.height_px * scale)))
    to_texture = np.array([size[0] / ann.width_px, size[1] / ann.height_px])
    crc = zlib.crc32(ann.stem.encode())
    pieces = [
        PaintedPiece(
            class_name=poly.class_name,
            rgb=colours.get(poly.class_name, (0.5, 0.5, 0.5)),
            points_px=poly.points_px * to_texture,
            seed_key=(seed, crc, poly.index, TEXTURE_STREAM),
        )
        for poly in ann.polygons
    ]
    picture = paint_picture(
        size,
        pieces,
        mm_per_px=1e3 * belt_width_m / size[0],
        background_key=(seed, crc, BELT_STREAM),
        grow_px=GROW_PX,
    )
    buffer = io.BytesIO()
    picture.save(buffer, format="JPEG", quality=JPEG_QUALITY)
    return buffer.getvalue(), size


def image_texture(
    ann: ImageAnnotation,
    colours: Mapping[str, RGB],
    *,
    seed: int,
    belt_width_m: float,
    max_px: int = TEXTURE_MAX_PX,
) -> Texture:
    """The texture of one image: its photo when usable, else procedural with a notice why."""
    if ann.photo is None:
        detail = f"no photo for image {ann.stem!r} (looked for: {ann.photo_searched})"
        notice = Notice(file=ann.source, where="", reason="photo_missing", detail=detail)
    else:
        try:
            made, size = photo_texture(ann.photo, (ann.width_px, ann.height_px), max_px)
        except PhotoUnusableError as exc:
            notice = Notice(file=ann.source, where="", reason=exc.reason, detail=exc.detail)
        else:
            if isinstance(made, Path):
                return Texture(
                    data=b"", source="photo", photo=ann.photo.name, size_px=size, copy_of=made
                )
            return Texture(data=made, source="photo", photo=ann.photo.name, size_px=size)
    data, size = procedural_texture(ann, colours, seed=seed, belt_width_m=belt_width_m)
    return Texture(data=data, source="procedural", photo="", size_px=size, notice=notice)
