"""From the belt frame of an image back to its pixels and to texture coordinates.

The belt frame of an image (:mod:`meshgen.footprint`) has its origin at the image centre, +x
along the direction of travel (image down), +y image right, in metres at ``m_per_px``. Pixel
``(u, v)`` (``u`` right, ``v`` down) lies at ``x = (v - H / 2) m``, ``y = (u - W / 2) m``;
:func:`belt_to_pixels` is the inverse. The texture coordinate of a pixel is
``(u / W, 1 - v / H)``: OBJ and OpenGL put ``v = 0`` at the bottom of a texture, the image's
last row.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from meshgen.annotations import FloatArray


def belt_to_pixels(
    points_m: FloatArray, width_px: int, height_px: int, m_per_px: float
) -> FloatArray:
    """``(n, 2)`` belt-frame points ``(x, y)`` in m as ``(n, 2)`` pixel points ``(u, v)``."""
    out = np.empty_like(points_m)
    out[:, 0] = points_m[:, 1] / m_per_px + 0.5 * width_px
    out[:, 1] = points_m[:, 0] / m_per_px + 0.5 * height_px
    return out


def belt_to_uv(points_m: FloatArray, width_px: int, height_px: int, m_per_px: float) -> FloatArray:
    """``(n, 2)`` belt-frame points ``(x, y)`` in m as ``(n, 2)`` texture coordinates.

    ``(u / W, 1 - v / H)`` of their pixel ``(u, v)``.
    """
    pixels = belt_to_pixels(points_m, width_px, height_px, m_per_px)
    out = np.empty_like(pixels)
    out[:, 0] = pixels[:, 0] / width_px
    out[:, 1] = 1.0 - pixels[:, 1] / height_px
    return out


def uv_to_pixels(uv: FloatArray, width_px: int, height_px: int) -> FloatArray:
    """``(n, 2)`` texture coordinates as ``(n, 2)`` pixel points ``(u, v)`` of the photo."""
    out = np.empty_like(uv)
    out[:, 0] = uv[:, 0] * width_px
    out[:, 1] = (1.0 - uv[:, 1]) * height_px
    return out


def rings_uv(rings: Sequence[tuple[FloatArray, int, int]], belt_width_m: float) -> FloatArray:
    """The ``(P, 2)`` texture coordinates of many belt-frame rings, concatenated.

    Each ring is ``((n, 2) float ring in m, image width px, image height px)``; its image's
    ``m_per_px`` is ``belt_width_m / width``.
    """
    if not rings:
        return np.zeros((0, 2), dtype=np.float64)
    return np.concatenate(
        [belt_to_uv(ring, w, h, belt_width_m / w) for ring, w, h in rings], axis=0
    )
