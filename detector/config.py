"""The detector's settings: how it segments (depth or colour), measures and classifies.

One frozen tree, :class:`DetectorConfig`, built once when the detector starts (from code, or from
YAML/JSON through :func:`interfaces.dataclass_io.from_data`, which names any wrong key); every
field has a unit in its name. The defaults suit the shipped cells' overhead camera (640x480,
1.2 m over the belt, about 2.2 mm per pixel on the belt) and photos of about 640x480.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from detector.errors import DetectorConfigError

Mode = Literal["depth", "colour"]
"""Which signal found the instances: heights above the belt, or colour against the belt."""

ModeChoice = Literal["auto", "depth", "colour"]
"""What a detector is asked to use; ``auto``: depth where the frame has it, else colour."""


def _check(ok: bool, key: str, value: object, what: str) -> None:
    if not ok:
        msg = f"detector.{key} = {value!r}: {what}"
        raise DetectorConfigError(msg)


def _positive(owner: object, prefix: str, *keys: str) -> None:
    for key in keys:
        value = getattr(owner, key)
        _check(math.isfinite(value) and value > 0, f"{prefix}.{key}", value, "must be > 0")


def _ratio(owner: object, prefix: str, *keys: str) -> None:
    for key in keys:
        value = getattr(owner, key)
        _check(0.0 < value < 1.0, f"{prefix}.{key}", value, "must lie in (0, 1)")


@dataclass(frozen=True, kw_only=True)
class SplitConfig:
    """How touching pieces are split (distance transform, markers, growing, merging).

    A marker is a local maximum of the distance to the region's outline at least
    ``min_peak_radius`` from it; two regions grown from neighbouring markers are
    merged again when the widest passage between them (the saddle of the distance) is at least
    ``merge_ratio`` times the smaller one's peak: a neck that wide is one piece, not two.
    """

    merge_ratio: float = 0.7

    def __post_init__(self) -> None:
        _ratio(self, "split", "merge_ratio")


@dataclass(frozen=True, kw_only=True)
class DepthConfig:
    """Instances from heights above the belt plane.

    ``min_height_m``: a pixel higher than this above the belt is foreground (above the depth
    noise after filtering); ``jump_m``: a height difference across a working pixel's 3x3
    neighbourhood larger than this is a wall between two levels (a piece's edge on another
    piece), never the inside of a face; ``min_area_m2``: smaller footprints are dropped as
    fragments; ``min_peak_radius_m``: the smallest piece half-width a marker stands for;
    ``split.merge_ratio`` 0.6 (the twin's concave pieces have waists; pieces of one height that
    touch have narrower necks, and pieces of two heights a wall between them).
    """

    min_height_m: float = 0.005
    jump_m: float = 0.012
    min_area_m2: float = 3e-4
    min_peak_radius_m: float = 0.008
    split: SplitConfig = field(default_factory=lambda: SplitConfig(merge_ratio=0.6))

    def __post_init__(self) -> None:
        _positive(self, "depth", "min_height_m", "jump_m", "min_area_m2", "min_peak_radius_m")


@dataclass(frozen=True, kw_only=True)
class ColourConfig:
    """Instances from colour and texture against a dark belt (no depth).

    Each cue's belt level and spread are estimated on a coarse grid (cells of
    ``background_cell_px`` working pixels, a median over ``background_window_cells`` cells, so
    lighting gradients and bright bands along the belt are the belt's, not pieces; a spread is
    at least ``min_spread``, so a perfectly smooth belt's JPEG blocks do not stand out); a
    pixel's saliency is its largest robust z-score (brightness off the belt's, colourfulness,
    local texture), averaged over ``smooth_px``; ``threshold_z`` above it is foreground, which
    is then eroded by ``shrink_px`` working pixels (the cues' windows spread the saliency a
    little beyond the piece).
    ``min_area_px`` (pixels of the input image) and ``min_peak_radius_px`` (working pixels) as
    in depth mode; two touching regions whose mean colours (RGB in [0, 1]) differ by more than
    ``colour_tolerance`` are never merged.

    The defaults were tuned on the shared sample's 60 real photos resized to fit 640x480
    (:mod:`detector.bench_photos`).
    """

    background_cell_px: int = 8
    background_window_cells: int = 15
    smooth_px: int = 3
    shrink_px: int = 1
    threshold_z: float = 2.5
    min_area_px: float = 150.0
    min_peak_radius_px: float = 6.0
    colour_tolerance: float = 0.2
    min_spread: float = 0.01
    split: SplitConfig = field(default_factory=SplitConfig)

    def __post_init__(self) -> None:
        _positive(
            self,
            "colour",
            "threshold_z",
            "min_area_px",
            "min_peak_radius_px",
            "colour_tolerance",
            "min_spread",
        )
        for key in ("background_cell_px", "background_window_cells", "smooth_px"):
            value = getattr(self, key)
            _check(isinstance(value, int) and value >= 1, f"colour.{key}", value, "an int >= 1")
        _check(
            isinstance(self.shrink_px, int) and self.shrink_px >= 0,
            "colour.shrink_px",
            self.shrink_px,
            "an int >= 0",
        )


@dataclass(frozen=True, kw_only=True)
class GeometryConfig:
    """How an instance's world geometry is measured (depth mode).

    A pixel is on a wall, not on a face, when the surface normal there (from its neighbours'
    world points) is tilted more than ``wall_slope_deg`` from up, or a speck when its height
    lies more than ``face_outlier_m`` from the mean of the face around it; a pixel just outside
    the face counts as its rim (the top's last pixel before the edge) when its height lies
    within ``slope_noise_m`` of the face next to it; the
    underside is the ``underside_percentile`` of the heights in a ring ``ring_inner_px`` to
    ``ring_outer_px`` pixels around the instance (the belt, or what the piece lies on); the top
    is the ``top_percentile`` of its face's heights (each a 5x5 mean over the face); the face's
    tilt is a plane fitted to its points within the suction radius, at least
    ``min_fit_radius_m``. All on every ``stride``-th pixel of each row and column.
    """

    stride: int = 2
    wall_slope_deg: float = 60.0
    slope_noise_m: float = 0.003
    face_outlier_m: float = 0.006
    ring_inner_px: int = 2
    ring_outer_px: int = 5
    underside_percentile: float = 10.0
    top_percentile: float = 95.0
    min_fit_radius_m: float = 0.012

    def __post_init__(self) -> None:
        _positive(self, "geometry", "slope_noise_m", "face_outlier_m", "min_fit_radius_m")
        _check(
            isinstance(self.stride, int) and 1 <= self.stride <= 4,
            "geometry.stride",
            self.stride,
            "must be an int in [1, 4]",
        )
        _check(
            0.0 < self.wall_slope_deg < 90.0,
            "geometry.wall_slope_deg",
            self.wall_slope_deg,
            "must lie in (0, 90)",
        )
        _check(
            isinstance(self.ring_inner_px, int)
            and isinstance(self.ring_outer_px, int)
            and 0 <= self.ring_inner_px < self.ring_outer_px,
            "geometry.ring_outer_px",
            self.ring_outer_px,
            "must be an int above ring_inner_px (an int >= 0)",
        )
        for key in ("underside_percentile", "top_percentile"):
            value = getattr(self, key)
            _check(0.0 <= value <= 100.0, f"geometry.{key}", value, "must lie in [0, 100]")


@dataclass(frozen=True, kw_only=True)
class DetectorConfig:
    """Everything the baseline detector needs besides its classifier.

    ``mode``: ``auto`` (depth when at least ``min_valid_depth`` of the frame's pixels have a
    depth, else colour), ``depth`` or ``colour``; ``work_stride``: segmentation runs on every
    ``work_stride``-th pixel of each row and column (world geometry on every
    ``geometry.stride``-th; the masks are full resolution), which keeps a
    640x480 frame within its time budget; ``unknown_class``: the class reported without a
    classifier.
    """

    mode: ModeChoice = "auto"
    work_stride: int = 2
    min_valid_depth: float = 0.5
    unknown_class: str = "unknown"
    depth: DepthConfig = field(default_factory=DepthConfig)
    colour: ColourConfig = field(default_factory=ColourConfig)
    geometry: GeometryConfig = field(default_factory=GeometryConfig)

    def __post_init__(self) -> None:
        _check(self.mode in ("auto", "depth", "colour"), "mode", self.mode, "auto|depth|colour")
        _check(
            isinstance(self.work_stride, int) and 1 <= self.work_stride <= 8,
            "work_stride",
            self.work_stride,
            "must be an int in [1, 8]",
        )
        _check(0.0 < self.min_valid_depth <= 1.0, "min_valid_depth", self.min_valid_depth, "(0,1]")
        _check(bool(self.unknown_class), "unknown_class", self.unknown_class, "must not be empty")


__all__ = [
    "ColourConfig",
    "DepthConfig",
    "DetectorConfig",
    "GeometryConfig",
    "Mode",
    "ModeChoice",
    "SplitConfig",
]
