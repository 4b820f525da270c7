"""Small helpers for the twin tests (polygons in pixels of a 1000x1000 px image = 0.6 m)."""

from __future__ import annotations

M_PER_PX = 0.6 / 1000.0


def box_px(cx: float, cy: float, length_px: float, width_px: float) -> list[tuple[float, float]]:
    """An axis-aligned rectangle: ``length_px`` along image rows (belt x), ``width_px`` across."""
    hl, hw = 0.5 * length_px, 0.5 * width_px
    return [(cx - hw, cy - hl), (cx + hw, cy - hl), (cx + hw, cy + hl), (cx - hw, cy + hl)]
