"""Instances from colour alone: pieces against a dark belt, without depth.

Most real photos of waste come without depth. The belt is dark, nearly grey and smooth; a piece
is brighter or darker than the belt around it (concrete, brick, wood; rubber is darker), more
colourful, or more textured (rubber is as dark as the belt but rougher). Each cue is a robust
z-score against the belt's own statistics (median and MAD over the image, where the belt
dominates), the belt's brightness taken from a coarse grid so lighting gradients and bright
bands along the belt are the belt's; the pixel's saliency is its largest cue, averaged over a
small box; foreground is saliency above ``threshold_z``, holes filled, specks removed; touching
pieces are split by :func:`detector.split.split_touching` on the foreground's distance
transform. All on every ``stride``-th pixel.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage as ndi

from detector.config import ColourConfig
from detector.filters import box_mean
from detector.labels import drop_small, upsample_labels
from detector.split import split_touching

_EPS = 1e-4
"""Smallest spread a cue's z-score divides by (a perfectly flat synthetic belt has none)."""


def working_rgb(rgb: np.ndarray, stride: int) -> np.ndarray:
    """Every ``stride``-th pixel of ``rgb`` ``(H, W, 3) uint8`` as ``(h, w, 3) float32`` in
    [0, 1] (the mean of each ``stride`` x ``stride`` block, which also averages sensor
    noise)."""
    h, w = rgb.shape[0] // stride, rgb.shape[1] // stride
    block = rgb[: h * stride, : w * stride].astype(np.float32)
    if stride > 1:
        block = block.reshape(h, stride, w, stride, 3).mean(axis=(1, 3))
    out: np.ndarray = block / np.float32(255.0)
    return out


def belt_level(values: np.ndarray, cell_px: int, window_cells: int) -> np.ndarray:
    """The belt's value of a cue under every pixel of ``values`` ``(h, w) float32``: the
    median of each ``cell_px`` cell, then the median over ``window_cells`` cells (pieces cover
    a minority of any such window), back to full size and smoothed."""
    h, w = values.shape
    gh, gw = max(1, h // cell_px), max(1, w // cell_px)
    cells = values[: gh * cell_px, : gw * cell_px].reshape(gh, cell_px, gw, cell_px)
    grid = np.median(cells.transpose(0, 2, 1, 3).reshape(gh, gw, -1), axis=2)
    grid = ndi.median_filter(grid, size=min(window_cells, max(gh, gw)), mode="nearest")
    rows = np.minimum(np.arange(h) // cell_px, gh - 1)
    cols = np.minimum(np.arange(w) // cell_px, gw - 1)
    up = grid[rows][:, cols].astype(np.float32)
    smooth: np.ndarray = box_mean(up, cell_px | 1)
    return smooth


def _local_z(values: np.ndarray, config: ColourConfig, min_spread: float) -> np.ndarray:
    """``values`` as z-scores against the belt around each pixel: its local level and local
    spread (1.4826 times the local median absolute deviation; at least half the image's and
    at least ``min_spread``, so a smooth belt's JPEG blocks do not stand out)."""
    cell, window = config.background_cell_px, config.background_window_cells
    off = values - belt_level(values, cell, window)
    deviation = np.abs(off)
    spread = 1.4826 * belt_level(deviation, cell, window)
    floor = max(0.5 * 1.4826 * float(np.median(deviation[::3, ::3])), min_spread, _EPS)
    out: np.ndarray = off / np.maximum(spread, floor)
    return out


def colour_saliency(rgb_work: np.ndarray, config: ColourConfig) -> np.ndarray:
    """How unlike the belt around it every working pixel looks, ``(h, w) float32`` in robust
    z units, from ``rgb_work`` ``(h, w, 3) float32`` in [0, 1]: the largest of brightness
    off the belt's (either way), colourfulness and texture above the belt's."""
    luma = rgb_work @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    chroma = rgb_work.max(axis=2) - rgb_work.min(axis=2)
    mean = box_mean(luma, 3)
    texture = np.sqrt(np.maximum(box_mean(luma * luma, 3) - mean * mean, 0.0))
    spread = config.min_spread
    z = np.maximum(np.abs(_local_z(luma, config, spread)), _local_z(chroma, config, spread))
    z = np.maximum(z, _local_z(texture, config, 0.5 * spread))
    out: np.ndarray = box_mean(z.astype(np.float32), config.smooth_px)
    return out


def segment_colour(rgb: np.ndarray, *, config: ColourConfig, stride: int) -> np.ndarray:
    """Instance labels ``(H, W) int32`` of the pieces in ``rgb`` ``(H, W, 3) uint8``."""
    work = working_rgb(rgb, stride)
    foreground = colour_saliency(work, config) > config.threshold_z
    foreground = ndi.binary_opening(foreground, iterations=1)
    foreground = ndi.binary_fill_holes(foreground)
    if config.shrink_px:
        foreground = ndi.binary_erosion(foreground, iterations=config.shrink_px)
    labels = split_touching(
        foreground=foreground,
        core=foreground,
        min_peak_px=config.min_peak_radius_px,
        merge_ratio=config.split.merge_ratio,
        colour=work,
        colour_tolerance=config.colour_tolerance,
    )
    labels = drop_small(labels, float(stride * stride), config.min_area_px)
    return upsample_labels(labels, stride, rgb.shape[:2], None)


__all__ = ["belt_level", "colour_saliency", "segment_colour", "working_rgb"]
