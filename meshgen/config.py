"""Configuration of one meshgen run."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

from interfaces.materials import ClassTable, shipped_table
from meshgen.errors import MeshgenError
from meshgen.heights import HEIGHT_PERCENTILE, HEIGHT_SCALE_M
from meshgen.textures import TEXTURE_MAX_PX

BELT_WIDTH_RANGE_M = (1e-3, 100.0)
"""Accepted ``--belt-width`` values, in m: any real belt, and no width so extreme (inf, 1e300,
1e-300) that the metric coordinates overflow or underflow."""


@dataclass(frozen=True, slots=True, kw_only=True)
class MeshgenConfig:
    """Every knob of a run; the defaults are the CLI defaults.

    ``classes`` is the class table (:mod:`interfaces.materials`; the shipped one by default);
    a class's ``class_id`` in the outputs is its position in it (concrete 0, brick 1, wood 2,
    rubber 3 by default), whatever the input format, and -1 for a class it does not name (meshed
    with its ``default`` entry).
    ``textures`` writes each image's texture and the meshes' texture coordinates
    (:mod:`meshgen.textures`), a texture's long side at most ``texture_max_px``. ``heights``
    takes heights from height images (:mod:`meshgen.heights`): ``""`` off, ``auto``
    (``DATASET/heights/``) or a folder; ``height_scale_m`` metres per level,
    ``height_percentile`` the percentile of a piece's levels taken as its top.
    """

    fmt: str = "auto"
    belt_width_m: float = 0.6
    image_size_px: tuple[int, int] | None = None
    seed: int = 0
    simplify_mm: float = 1.0
    border_margin_px: float = 1.0
    min_area_mm2: float = 25.0
    up: str = "z"
    classes: ClassTable = field(default_factory=shipped_table)
    textures: bool = True
    texture_max_px: int = TEXTURE_MAX_PX
    heights: str = ""
    height_scale_m: float = HEIGHT_SCALE_M
    height_percentile: float = HEIGHT_PERCENTILE

    def __post_init__(self) -> None:
        """Reject values that cannot work, naming the option."""
        low, high = BELT_WIDTH_RANGE_M
        checks = (
            (
                low <= self.belt_width_m <= high,  # False for nan
                f"--belt-width must be a width in m from {low:g} to {high:g}, got "
                + str(self.belt_width_m),
            ),
            (
                0.0 <= self.simplify_mm < math.inf,
                f"--simplify-mm must be finite and >= 0, got {self.simplify_mm}",
            ),
            (
                0.0 <= self.border_margin_px < math.inf,
                f"--border-margin-px must be finite and >= 0, got {self.border_margin_px}",
            ),
            (
                0.0 <= self.min_area_mm2 < math.inf,
                f"--min-area-mm2 must be finite and >= 0, got {self.min_area_mm2}",
            ),
            (self.up in {"z", "y"}, f"--up must be z or y, got {self.up!r}"),
            (self.seed >= 0, f"--seed must be >= 0, got {self.seed}"),
            (
                16 <= self.texture_max_px <= 16384,
                f"--texture-max-px must be from 16 to 16384, got {self.texture_max_px}",
            ),
            (
                0.0 < self.height_scale_m <= 1.0,  # False for nan
                "--height-scale-m must be a height per level in m in (0, 1], got "
                + str(self.height_scale_m),
            ),
            (
                0.0 <= self.height_percentile <= 100.0,
                f"--height-percentile must lie in [0, 100], got {self.height_percentile}",
            ),
        )
        for ok, msg in checks:
            if not ok:
                raise MeshgenError(msg)
        if self.image_size_px is not None and min(self.image_size_px) <= 0:
            msg = f"--image-size must be positive, got {self.image_size_px}"
            raise MeshgenError(msg)

    def to_json(self) -> dict[str, Any]:
        """The configuration as plain JSON data (for summary.json)."""
        data = asdict(self)
        table = self.classes.to_data()
        data["classes"] = table["classes"]
        data["default_class"] = table["default"]
        return data


def parse_image_size(text: str) -> tuple[int, int]:
    """Parse ``WxH`` (e.g. ``1024x960``) into ``(width_px, height_px)``."""
    parts = text.lower().split("x")
    try:
        width, height = (int(p) for p in parts)
    except ValueError as exc:
        msg = f"--image-size: expected WxH such as 1024x960, got {text!r}"
        raise MeshgenError(msg) from exc
    if width <= 0 or height <= 0:
        msg = f"--image-size: width and height must be positive, got {text!r}"
        raise MeshgenError(msg)
    return width, height
