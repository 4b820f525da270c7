"""A depth image made ready for segmentation and geometry: holes filled, speckle removed.

Real depth has dropouts (NaN) at edges and at random, and noise that grows with distance. Small
holes (up to about four pixels across) are filled from their valid neighbours, then a separable
3x3 median removes spikes; larger holes stay NaN (no depth: never foreground, never a point).
"""

from __future__ import annotations

import numpy as np

from detector.belt_view import BeltView
from detector.filters import fill_small_holes, median3


def filter_depth(depth_m: np.ndarray) -> np.ndarray:
    """``depth_m`` ``(H, W)`` with small holes filled and median-filtered, ``float32``."""
    filled = fill_small_holes(np.asarray(depth_m, dtype=np.float32))
    nan = np.isnan(filled)
    if not nan.any():
        return median3(filled)
    # keep large holes NaN: filter with them at the farthest depth, then put them back
    far = np.float32(np.nanmax(filled)) if (~nan).any() else np.float32(0.0)
    out = median3(np.where(nan, far, filled))
    out[nan] = np.nan
    return out


def prepare_depth(depth_m: np.ndarray, view: BeltView) -> tuple[np.ndarray, np.ndarray]:
    """The filtered depth and the height above the belt of every pixel, both ``(H, W)
    float32`` (NaN where there is no depth)."""
    depth = filter_depth(depth_m)
    return depth, view.heights_m(depth)


def pixel_area_m2(depth_m: np.ndarray, view: BeltView) -> np.ndarray:
    """The area each pixel covers on a surface facing the camera at its depth, ``(H, W)`` m^2
    (0 where there is no depth)."""
    k = view.intrinsics
    d = np.nan_to_num(depth_m, nan=0.0)
    out: np.ndarray = (d * d) / np.float32(k.fx_px * k.fy_px)
    return out


__all__ = ["filter_depth", "pixel_area_m2", "prepare_depth"]
