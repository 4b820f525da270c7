"""The pictures drawn on the camera's meshes: photos read from disk, procedural grain.

A meshed piece carries its source photo when meshgen wrote one (``texture_path`` in
``scene.csv``, texture coordinates in the OBJ); one image per photo, read once and shared by its
pieces. Everything else (pieces without a photo, the belt, the floor) gets a tiled grain: a
smooth random pattern around 1 multiplied by the surface's colour, so colour still varies within
a piece as it does on a real surface. The grain of a name is the same on every machine and run.
"""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np

from twin.camera.errors import RenderError
from twin.camera.render_types import RGB

__all__ = ["GRAIN_PERIOD_M", "grain_texture", "read_rgb_image"]

GRAIN_PERIOD_M = 0.2
"""The size of one tile of a procedural grain on a surface (planar uv: x and y over it)."""

GRAIN_TEXELS = 64
"""Texels along a grain tile's side: 3 mm each at :data:`GRAIN_PERIOD_M`, about a pixel of the
reference camera at 1.2 m, so the blobs (a few texels) stay visible after filtering."""


def grain_texture(name: str, rgb: RGB, *, amplitude: float = 0.12) -> np.ndarray:
    """A tileable ``(GRAIN_TEXELS, GRAIN_TEXELS, 3) uint8`` texture of colour ``rgb`` (in
    [0, 1]) varied by a smooth grain of relative ``amplitude``, seeded by ``name``.

    White noise smoothed by a periodic box filter (so the tile wraps without a seam),
    normalised to zero mean and unit peak, then ``rgb * (1 + amplitude * grain)``.
    """
    rng = np.random.default_rng(zlib.crc32(name.encode("utf-8")))
    noise = rng.standard_normal((GRAIN_TEXELS, GRAIN_TEXELS))
    blobs = np.zeros_like(noise)
    for dy in range(-1, 2):
        for dx in range(-1, 2):
            blobs += np.roll(noise, (dy, dx), axis=(0, 1))
    smooth = 0.7 * blobs / 3.0 + 0.3 * noise  # blobs of a few texels, a little fine grain
    smooth -= smooth.mean()
    smooth /= max(float(np.abs(smooth).max()), 1e-9)
    colour = np.asarray(rgb, dtype=float).reshape(1, 1, 3)
    texture = colour * (1.0 + amplitude * smooth[:, :, None])
    return np.asarray(np.clip(np.round(texture * 255.0), 0, 255), dtype=np.uint8)


def read_rgb_image(path: Path) -> np.ndarray:
    """The image at ``path`` as ``(H, W, 3) uint8`` (row 0 at the top; grey and palette images
    converted, alpha dropped); :class:`RenderError` naming the file when it cannot be read."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            rgb = np.asarray(image.convert("RGB"), dtype=np.uint8)
    except FileNotFoundError:
        msg = f"{path}: no such texture image"
        raise RenderError(msg) from None
    except (OSError, UnidentifiedImageError, ValueError) as exc:
        msg = f"{path}: cannot read the texture image: {exc}"
        raise RenderError(msg) from None
    return rgb
