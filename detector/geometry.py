"""What an instance's mask says about the piece in the image, or on the belt plane.

Image geometry (:func:`image_geometry`, any mode): centroid, long-axis angle (from the pixels'
second moments) and extents of a mask, in pixels. With a camera over the belt but no depth
(:func:`belt_plane_geometry`, colour mode), the mask's pixels projected along their rays onto the
belt plane give the centroid, yaw and extents in metres; the height is unknown (NaN), and so are
the suction point, its radius and tilt. Depth-mode world geometry is
:mod:`detector.world_geometry`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from detector import grouped
from detector.belt_view import BeltView
from detector.rect import min_area_rectangle
from interfaces.detections import Detection


@dataclass(frozen=True, kw_only=True)
class ImageGeometry:
    """An instance in the image: centroid ``(u, v)`` px (column, row), the long axis's angle
    from the column axis towards the row axis (rad, (-pi/2, pi/2]), extents and area in
    pixels."""

    centroid_uv_px: tuple[float, float]
    axis_rad: float
    length_px: float
    width_px: float
    area_px: int


def image_geometry(rows: np.ndarray, cols: np.ndarray) -> ImageGeometry:
    """Geometry of the pixels ``(rows[i], cols[i])`` of one mask (at least one): the long
    axis from the pixels' second moments, the extents along and across it (plus one pixel)."""
    u = cols.astype(np.float64)
    v = rows.astype(np.float64)
    cu, cv = float(u.mean()), float(v.mean())
    du, dv = u - cu, v - cv
    suu, svv, suv = float((du * du).mean()), float((dv * dv).mean()), float((du * dv).mean())
    axis = 0.5 * math.atan2(2.0 * suv, suu - svv)
    c, s = math.cos(axis), math.sin(axis)
    along = du * c + dv * s
    across = -du * s + dv * c
    length = float(along.max() - along.min()) + 1.0
    width = float(across.max() - across.min()) + 1.0
    if width > length:
        length, width = width, length
        axis += math.pi / 2
    return ImageGeometry(
        centroid_uv_px=(cu, cv),
        axis_rad=_fold(axis),
        length_px=length,
        width_px=width,
        area_px=int(rows.size),
    )


def image_geometries(labels: np.ndarray, n: int, stride: int = 1) -> list[ImageGeometry]:
    """:func:`image_geometry` of every instance ``1..n`` of ``labels`` ``(H, W)`` at once, from
    every ``stride``-th pixel (an instance too small to be sampled from all of its pixels; one
    without any pixel has a NaN centroid and zero extents)."""
    sampled = labels[::stride, ::stride]
    rows, cols = np.nonzero(sampled)
    owner = sampled[rows, cols]
    v = rows.astype(np.float64) * stride
    u = cols.astype(np.float64) * stride
    count = grouped.counts(owner, n).astype(np.float64)
    safe = np.maximum(count, 1.0)
    cu, cv = grouped.sums(owner, u, n) / safe, grouped.sums(owner, v, n) / safe
    du, dv = u - cu[owner], v - cv[owner]
    suu = grouped.sums(owner, du * du, n)
    svv = grouped.sums(owner, dv * dv, n)
    suv = grouped.sums(owner, du * dv, n)
    axis = 0.5 * np.arctan2(2.0 * suv, suu - svv)
    c, s = np.cos(axis)[owner], np.sin(axis)[owner]
    along, across = du * c + dv * s, -du * s + dv * c
    span_a = grouped.maxima(owner, along, n) + grouped.maxima(owner, -along, n) + stride
    span_b = grouped.maxima(owner, across, n) + grouped.maxima(owner, -across, n) + stride
    area = grouped.counts(labels.ravel(), n)
    out: list[ImageGeometry] = []
    for k in range(1, n + 1):
        if count[k] == 0:
            rows_k, cols_k = np.nonzero(labels == k)
            out.append(
                image_geometry(rows_k, cols_k)
                if rows_k.size
                else ImageGeometry(
                    centroid_uv_px=(math.nan, math.nan),
                    axis_rad=0.0,
                    length_px=0.0,
                    width_px=0.0,
                    area_px=0,
                )
            )
            continue
        length, width, angle = float(span_a[k]), float(span_b[k]), float(axis[k])
        if width > length:
            length, width, angle = width, length, angle + math.pi / 2
        out.append(
            ImageGeometry(
                centroid_uv_px=(float(cu[k]), float(cv[k])),
                axis_rad=_fold(angle),
                length_px=length,
                width_px=width,
                area_px=int(area[k]),
            )
        )
    return out


def _fold(angle_rad: float) -> float:
    """An axis direction folded into (-pi/2, pi/2]."""
    a = math.fmod(angle_rad, math.pi)
    if a <= -math.pi / 2:
        a += math.pi
    elif a > math.pi / 2:
        a -= math.pi
    return a


def belt_plane_geometry(
    *,
    view: BeltView,
    rows: np.ndarray,
    cols: np.ndarray,
    class_name: str,
    score: float,
) -> Detection:
    """A colour-mode detection: the mask's pixels projected onto the belt plane (height,
    suction point, radius and tilt NaN: a colour image does not show them)."""
    belt_depth = view.belt_depth_m()[rows, cols].astype(np.float64)
    pts = view.points_m(rows, cols, belt_depth)
    weight = belt_depth * belt_depth
    rect = min_area_rectangle(pts[:, :2])
    pixel_m = view.metres_per_px(float(np.median(belt_depth)))
    return Detection(
        class_name=class_name,
        confidence=float(score),
        x_m=float((pts[:, 0] * weight).sum() / weight.sum()),
        y_m=float((pts[:, 1] * weight).sum() / weight.sum()),
        z_m=view.belt_z_m,
        yaw_rad=rect.angle_rad,
        length_m=rect.length + pixel_m,
        width_m=rect.width + pixel_m,
        height_m=math.nan,
    )


__all__ = [
    "ImageGeometry",
    "belt_plane_geometry",
    "image_geometries",
    "image_geometry",
]
