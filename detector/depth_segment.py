"""Instances from a height image: foreground above the belt, walls between levels, split.

The height image is the belt-relative height of every pixel (metres from a depth camera through
:class:`detector.belt_view.BeltView`, or a dataset's height image in its own units), holes filled
and median-filtered. Foreground is what stands more than ``min_height`` above the belt; a pixel
whose 3x3 neighbourhood spans more than ``jump`` is a wall between two levels (the edge of a piece
lying on another, or a piece's side), so the faces on either side are separate "cores" for
:func:`detector.split.split_touching`. Segmentation runs on every ``stride``-th pixel; the labels
come back to full resolution on the full-resolution foreground; instances smaller than
``min_area`` (in the units of ``pixel_area``, measured on the working pixels) are dropped as
fragments first.
"""

from __future__ import annotations

import numpy as np

from detector.filters import local_range3
from detector.labels import drop_small, upsample_labels
from detector.split import split_touching


def segment_heights(
    height: np.ndarray,
    *,
    min_height: float,
    jump: float,
    min_peak_px: float,
    merge_ratio: float,
    stride: int,
    min_area: float,
    pixel_area: np.ndarray | float,
) -> np.ndarray:
    """Instance labels ``(H, W) int32`` of the height image ``height`` ``(H, W) float32``
    (finite everywhere: fill holes first). ``min_peak_px`` is in working pixels (full pixels
    divided by ``stride``); ``pixel_area`` ``(H, W)`` or one value: each full pixel's area."""
    work = height[::stride, ::stride]
    foreground = work > min_height
    core = foreground & (local_range3(work) <= jump)
    labels = split_touching(
        foreground=foreground, core=core, min_peak_px=min_peak_px, merge_ratio=merge_ratio
    )
    if np.ndim(pixel_area) == 0:
        work_area: np.ndarray | float = float(pixel_area) * stride * stride
    else:
        work_area = np.asarray(pixel_area)[::stride, ::stride] * (stride * stride)
    labels = drop_small(labels, work_area, min_area)
    return upsample_labels(labels, stride, height.shape, height > min_height)


__all__ = ["segment_heights"]
