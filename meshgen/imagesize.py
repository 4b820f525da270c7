"""Image width and height from the file header only (PNG, JPEG, BMP, GIF), without decoding."""

from __future__ import annotations

import struct
from pathlib import Path

IMAGE_SUFFIXES: tuple[str, ...] = (".png", ".jpg", ".jpeg", ".bmp", ".gif")

_FIRST_READ = 16384
_LAST_READ = 262144
_JPEG_SOF = frozenset(
    {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
)


def _jpeg_size(head: bytes) -> tuple[int, int] | None:
    pos = 2
    while pos + 9 < len(head):
        if head[pos] != 0xFF:
            return None
        marker = head[pos + 1]
        if marker == 0xFF:
            pos += 1
            continue
        length = struct.unpack(">H", head[pos + 2 : pos + 4])[0]
        if marker in _JPEG_SOF:
            height, width = struct.unpack(">HH", head[pos + 5 : pos + 9])
            return int(width), int(height)
        pos += 2 + length
    return None


def read_image_size(path: Path) -> tuple[int, int] | None:
    """Return ``(width_px, height_px)`` from the header of ``path``, or None if unknown.

    Reads the first 16 KiB, and up to 256 KiB only for a JPEG whose frame header comes later
    (after a large EXIF block): a photo is not read whole to learn its size.
    """
    try:
        with path.open("rb") as fh:
            head = fh.read(_FIRST_READ)
            if head[:2] == b"\xff\xd8" and _jpeg_size(head) is None:
                head += fh.read(_LAST_READ - _FIRST_READ)
    except OSError:
        return None
    size: tuple[int, int] | None = None
    if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
        width, height = struct.unpack(">II", head[16:24])
        size = (int(width), int(height))
    elif head[:2] == b"\xff\xd8":
        size = _jpeg_size(head)
    elif head[:2] == b"BM" and len(head) >= 26:
        width, height = struct.unpack("<ii", head[18:26])
        size = (int(width), abs(int(height)))
    elif head[:6] in {b"GIF87a", b"GIF89a"}:
        width, height = struct.unpack("<HH", head[6:10])
        size = (int(width), int(height))
    if size is None or size[0] <= 0 or size[1] <= 0:
        return None
    return size
