"""Label images: the detector's compact form of a frame's instance masks, and conversions.

A label image ``(H, W) int32`` holds 0 where there is no instance and ``k`` on the pixels of the
k-th instance (1-based); it is what segmentation produces and what scoring consumes cheaply.
Masks ``(H, W) bool`` are the plug-in protocol's form (:mod:`detector.instances`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from detector.errors import FrameError
from detector.filters import max3


def upsample_labels(
    labels: np.ndarray, stride: int, shape: tuple[int, int], foreground: np.ndarray | None
) -> np.ndarray:
    """Working-resolution labels ``(h, w)`` back to full resolution ``shape`` (each working
    pixel covers ``stride`` x ``stride`` pixels); with a full-resolution ``foreground`` mask,
    labels are kept only on it and its pixels left unlabelled at the instances' edges take a
    neighbour's label. ``(H, W) int32``."""
    if stride == 1:
        full = labels
    else:
        full = np.repeat(np.repeat(labels, stride, axis=0), stride, axis=1)
        full = full[: shape[0], : shape[1]]
        if full.shape != shape:
            full = np.pad(full, ((0, shape[0] - full.shape[0]), (0, shape[1] - full.shape[1])))
    if foreground is None:
        return full.astype(np.int32, copy=False)
    grown = np.where(full > 0, full, max3(full))
    out: np.ndarray = np.where(foreground, grown, 0).astype(np.int32)
    return out


def relabel(labels: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """``labels`` with only the ids where ``keep[id]`` holds, renumbered 1..n in order.
    ``keep`` ``(max_id + 1,) bool`` (``keep[0]`` is ignored)."""
    keep = keep.copy()
    keep[0] = False
    lut = np.zeros(keep.size, dtype=np.int32)
    lut[keep] = np.arange(1, int(keep.sum()) + 1, dtype=np.int32)
    out: np.ndarray = lut[labels]
    return out


def drop_small(labels: np.ndarray, pixel_area: np.ndarray | float, min_area: float) -> np.ndarray:
    """``labels`` without the instances whose summed ``pixel_area`` (per pixel, or one value
    for all) is below ``min_area``, renumbered."""
    n = int(labels.max())
    if n == 0:
        return labels
    flat = labels.ravel()
    weights = np.broadcast_to(np.asarray(pixel_area, dtype=np.float64), labels.shape)
    area = np.bincount(flat, weights=weights.ravel(), minlength=n + 1)
    return relabel(labels, area >= min_area)


def masks_to_labels(
    masks: Sequence[np.ndarray], shape: tuple[int, int], scores: Sequence[float] | None = None
) -> np.ndarray:
    """A label image of ``masks`` (each ``(H, W) bool``; label ``k`` for ``masks[k - 1]``).
    Where masks overlap, the higher score wins (without scores, the later mask)."""
    out = np.zeros(shape, dtype=np.int32)
    order = range(len(masks)) if scores is None else np.argsort(np.asarray(scores), kind="stable")
    for i in order:
        mask = np.asarray(masks[int(i)])
        if mask.shape != shape:
            msg = f"masks[{int(i)}]: shape {mask.shape}, expected the image's {shape}"
            raise FrameError(msg)
        out[mask.astype(bool, copy=False)] = int(i) + 1
    return out


__all__ = ["drop_small", "masks_to_labels", "relabel", "upsample_labels"]
