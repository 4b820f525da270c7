"""Procedural pictures of waste pieces: one surface pattern per class, pieces painted on a belt.

Two users: the built-in sample draws its photos with it (:mod:`meshgen.sample`), and meshgen
textures the pieces of an image without a photo with it (:mod:`meshgen.textures`). Every
pattern is drawn from its own ``numpy.random.Generator``, so equal seeds give equal pixels
(with the same numpy and Pillow). Feature sizes are physical (millimetres, through
``mm_per_px``), so a piece looks the same at any image scale.

Patterns (base colour: the class's ``rgb``, :data:`interfaces.class_colours.CLASS_RGB` for
the four CDW classes):

- ``concrete``: grey, mottled over about 12 mm, speckled with dark and light aggregate;
- ``brick``: red-orange, granular (grains of 1-2 mm, more orange and darker ones), mottled;
- ``wood``: brown with grain: dark lines every 3-6 mm along a random direction, wavy;
- ``rubber``: near-black and matte (faint noise only);
- any other class: its colour with mottling and fine noise.

The belt behind the pieces is dark grey (:data:`BELT_RGB`) with faint noise.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from PIL import Image, ImageDraw

from meshgen.annotations import FloatArray

RGB = tuple[float, float, float]
F32 = npt.NDArray[np.float32]

BELT_RGB: RGB = (0.13, 0.13, 0.14)
"""The belt's colour behind the pieces: a dark rubber conveyor belt."""


@dataclass(frozen=True, slots=True, kw_only=True)
class PaintedPiece:
    """One piece to paint: its class, colour, outline and the seed of its pattern.

    ``points_px`` is the ``(n, 2) float`` outline in the picture's pixels (``u`` right, ``v``
    down); ``seed_key`` seeds ``numpy.random.default_rng`` for its pattern.
    """

    class_name: str
    rgb: RGB
    points_px: FloatArray
    seed_key: tuple[int, ...]


def _white(rng: np.random.Generator, shape: tuple[int, int]) -> F32:
    """Standard normal noise, ``shape`` float32."""
    return rng.standard_normal(shape, dtype=np.float32)


def _smooth(rng: np.random.Generator, shape: tuple[int, int], cell_px: float) -> F32:
    """Noise that varies over about ``cell_px`` pixels (a coarse grid, bilinearly enlarged)."""
    height, width = shape
    rows = max(2, math.ceil(height / max(cell_px, 1.0)) + 1)
    cols = max(2, math.ceil(width / max(cell_px, 1.0)) + 1)
    coarse = rng.standard_normal((rows, cols), dtype=np.float32)
    big = Image.fromarray(coarse, mode="F").resize((width, height), Image.Resampling.BILINEAR)
    return np.asarray(big, dtype=np.float32)


def _concrete(rng: np.random.Generator, shape: tuple[int, int], mm: float) -> tuple[F32, F32]:
    """Luminance offset and colour tint weight of concrete: mottled and speckled."""
    lum = 9.0 * _smooth(rng, shape, 12.0 / mm) + 4.0 * _smooth(rng, shape, 3.0 / mm)
    lum += 6.0 * _white(rng, shape)
    draw = rng.random(shape, dtype=np.float32)
    lum[draw < 0.05] -= 45.0
    lum[draw > 0.975] += 30.0
    return lum, np.zeros(shape, dtype=np.float32)


def _brick(rng: np.random.Generator, shape: tuple[int, int], mm: float) -> tuple[F32, F32]:
    """Luminance offset and orange tint of brick: granular grains of 1-2 mm, mottled."""
    grains = _smooth(rng, shape, 1.5 / mm)
    lum = 10.0 * _smooth(rng, shape, 15.0 / mm) + 12.0 * grains + 7.0 * _white(rng, shape)
    tint = 14.0 * _smooth(rng, shape, 6.0 / mm) - 8.0 * grains
    return lum, tint


def _wood(rng: np.random.Generator, shape: tuple[int, int], mm: float) -> tuple[F32, F32]:
    """Luminance offset of wood: dark grain lines every 3-6 mm along a random direction."""
    height, width = shape
    angle = rng.uniform(0.0, math.pi)
    period_px = rng.uniform(3.0, 6.0) / mm
    v, u = np.mgrid[0:height, 0:width].astype(np.float32)
    across = u * math.sin(angle) - v * math.cos(angle)
    across += (2.5 / mm) * _smooth(rng, shape, 20.0 / mm)
    phase = np.sin(across * np.float32(2.0 * math.pi / period_px))
    lines = ((phase + 1.0) * 0.5) ** 6
    lum = -38.0 * lines + 6.0 * _smooth(rng, shape, 25.0 / mm) + 4.0 * _white(rng, shape)
    return lum.astype(np.float32), np.zeros(shape, dtype=np.float32)


def _rubber(rng: np.random.Generator, shape: tuple[int, int], mm: float) -> tuple[F32, F32]:
    """Luminance offset of rubber: matte, faint noise only."""
    lum = 2.0 * _smooth(rng, shape, 10.0 / mm) + 2.5 * _white(rng, shape)
    return lum, np.zeros(shape, dtype=np.float32)


def _other(rng: np.random.Generator, shape: tuple[int, int], mm: float) -> tuple[F32, F32]:
    """Luminance offset of any other class: mottling and fine noise."""
    lum = 8.0 * _smooth(rng, shape, 10.0 / mm) + 6.0 * _white(rng, shape)
    return lum, np.zeros(shape, dtype=np.float32)


_PATTERNS = {"concrete": _concrete, "brick": _brick, "wood": _wood, "rubber": _rubber}
TINT_RGB = (0.6, 0.25, -0.35)
"""How a pattern's tint moves red, green and blue (brick's orange and darker grains)."""


def class_pattern(
    class_name: str,
    rgb: RGB,
    rng: np.random.Generator,
    shape: tuple[int, int],
    mm_per_px: float,
) -> Image.Image:
    """The surface pattern of ``class_name`` in colour ``rgb`` (module doc), an RGB image of
    ``shape`` ``(h, w)``; ``mm_per_px`` sets the pixel size of its features.

    Built channel by channel (contiguous ``(h, w)`` arrays, merged by Pillow).
    """
    pattern = _PATTERNS.get(class_name, _other)
    lum, tint = pattern(rng, shape, max(mm_per_px, 1e-3))
    tinted = bool(tint.any())
    channels = []
    for base, weight in zip(rgb, TINT_RGB, strict=True):
        channel = lum + np.float32(base * 255.0 + 0.5)
        if tinted:
            channel += np.float32(weight) * tint
        np.clip(channel, 0.0, 255.0, out=channel)
        channels.append(Image.fromarray(channel.astype(np.uint8), mode="L"))
    return Image.merge("RGB", channels)


def belt_background(
    rng: np.random.Generator, shape: tuple[int, int], mm_per_px: float
) -> Image.Image:
    """The belt behind the pieces, an RGB image of ``shape`` ``(h, w)``: :data:`BELT_RGB`
    with faint noise.

    Built as one grey channel (a full-size picture is a million pixels): shades over about
    40 mm (a coarse grid enlarged bilinearly) plus a 64-pixel tile of fine noise repeated; the
    colour's channels are that grey shifted.
    """
    height, width = shape
    cell = 40.0 / max(mm_per_px, 1e-3)
    rows = max(2, math.ceil(height / cell) + 1)
    cols = max(2, math.ceil(width / cell) + 1)
    base = np.round(np.array(BELT_RGB) * 255.0).astype(int)
    low = int(base.min()) - 3
    shades = np.clip(low + 3.0 * rng.standard_normal((rows, cols)) + 0.5, 0.0, 240.0)
    coarse = Image.fromarray(shades.astype(np.uint8), mode="L")
    grey = np.array(coarse.resize((width, height), Image.Resampling.BILINEAR), dtype=np.uint8)
    tile = rng.integers(0, 7, (64, 64), dtype=np.uint8)
    grey += np.tile(tile, (height // 64 + 1, width // 64 + 1))[:height, :width]
    channels = [Image.fromarray(grey + np.uint8(int(b) - low - 3), mode="L") for b in base]
    return Image.merge("RGB", channels)


def paint_pieces(
    canvas: Image.Image, pieces: Sequence[PaintedPiece], mm_per_px: float, grow_px: int = 0
) -> None:
    """Paint every piece's pattern inside its outline onto RGB image ``canvas``, in order.

    Later pieces cover earlier ones where they overlap (a piece lying on another). Only each
    piece's bounding box is drawn. ``grow_px`` widens every outline by that many pixels (a
    texture's margin, so that filtering at a piece's edge reads the piece, not the belt).
    """
    width, height = canvas.size
    for piece in pieces:
        points = np.asarray(piece.points_px, dtype=np.float64)
        if len(points) < 3 or not np.isfinite(points).all():
            continue
        low = np.floor(points.min(axis=0)).astype(int) - grow_px - 1
        high = np.ceil(points.max(axis=0)).astype(int) + grow_px + 2
        u0, v0 = max(int(low[0]), 0), max(int(low[1]), 0)
        u1, v1 = min(int(high[0]), width), min(int(high[1]), height)
        if u1 <= u0 or v1 <= v0:
            continue
        mask = Image.new("L", (u1 - u0, v1 - v0), 0)
        outline = [(float(u) - u0, float(v) - v0) for u, v in points.tolist()]
        draw = ImageDraw.Draw(mask)
        draw.polygon(outline, fill=255)
        if grow_px > 0:
            draw.line([*outline, outline[0]], fill=255, width=2 * grow_px + 1, joint="curve")
        rng = np.random.default_rng(list(piece.seed_key))
        pattern = class_pattern(piece.class_name, piece.rgb, rng, (v1 - v0, u1 - u0), mm_per_px)
        canvas.paste(pattern, (u0, v0), mask)


def paint_picture(
    size_px: tuple[int, int],
    pieces: Sequence[PaintedPiece],
    *,
    mm_per_px: float,
    background_key: tuple[int, ...],
    grow_px: int = 0,
) -> Image.Image:
    """An RGB picture of ``size_px`` ``(w, h)``: the pieces on the belt.

    ``background_key`` seeds the belt's noise; each piece's pattern has its own seed.
    """
    width, height = size_px
    rng = np.random.default_rng(list(background_key))
    canvas = belt_background(rng, (height, width), mm_per_px)
    paint_pieces(canvas, pieces, mm_per_px, grow_px)
    return canvas
