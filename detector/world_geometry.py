"""What a depth frame says about every instance at once: world centroid, yaw, extents, height,
suction point and tilt (depth mode).

From the full-resolution label image, the filtered depth and the camera
(:class:`detector.belt_view.BeltView`), per instance:

- the **top face**: the largest 4-connected part of the instance's pixels that are not on a wall
  (the surface normal from the neighbours' world points is tilted less than ``wall_slope_deg``
  from up) and not specks (within ``face_outlier_m`` of the face's local 5x5 mean height);
- the **footprint**: the world x-y of the top face and of its rim (the instance's pixels just
  outside the face at the face's height: the top's last pixels before its edge, whose own depth
  mixes top and belt, placed where their rays meet the face's height). Walls are left out:
  perspective shows a piece's near side walls, which make an image box too long (the issue
  measured 14 mm), and their points, seen at grazing angles, are the noisiest. The
  minimum-area rectangle of the footprint's outline gives the yaw of the long axis (folded into
  (-pi/2, pi/2]), the length and the width;
- the **centroid**: the mean world x-y of the top face's points, each weighted by the area its
  pixel covers (depth squared), at z = the **underside**: the ``underside_percentile`` of the
  heights in a ring ``ring_inner_px`` to ``ring_outer_px`` around the instance (the belt, or the
  top of what the piece lies on);
- the **height**: the ``top_percentile`` of the face's 5x5 mean heights, minus the underside;
- the **suction point**: the face pixel farthest from the face's outline (Euclidean distance
  transform), as a world point, its distance in metres as the radius (:data:`RADIUS_OFFSET_PX`),
  and the **tilt**: the angle between world up and the normal of the plane fitted (least
  squares, smallest eigenvector of the covariance) to the face's points within
  :data:`FIT_SCALE` times that radius (at least ``min_fit_radius_m``) of it.

All on every ``stride``-th pixel (default 2: a quarter of the pixels; the rim, placed at the
face's height, keeps the extents unbiased on the synthetic frames of the tests), with
whole-image numpy and grouped statistics (:mod:`detector.grouped`): only each instance's
rectangle is a call of its own.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import ndimage as ndi

from detector import grouped
from detector.belt_view import BeltView
from detector.config import GeometryConfig
from detector.filters import max3, min3
from detector.rect import min_area_rectangles
from interfaces.detections import Detection

RADIUS_OFFSET_PX = 0.0
"""Added to the suction point's distance transform (geometry pixels) before it becomes the
radius. The transform runs on the footprint less its outermost pixels (those touching
another instance or the background), so the distance to the nearest removed pixel is already
about the distance to the outline (which lies half a pixel beyond the last footprint pixel)."""

FIT_SCALE = 1.5
"""The face's tilt is fitted to its points within this many suction radii (at least
``min_fit_radius_m``) of the suction point: more points, less of the depth noise's bias
(noise only ever adds tilt)."""

_TOP_SAMPLES = 20000
"""At most about this many face pixels (evenly spaced) go into the grouped top percentile."""


@dataclass(frozen=True, kw_only=True, eq=False)
class DepthImages:
    """One frame's images every instance's geometry reads: the camera's ``view``, the
    filtered ``depth_m`` and ``heights_m`` ``(H, W) float32`` (NaN: no depth) and the
    instances' ``labels`` ``(H, W) int32``."""

    view: BeltView
    depth_m: np.ndarray
    heights_m: np.ndarray
    labels: np.ndarray


def _steep(points: np.ndarray, cos_limit: float) -> np.ndarray:
    """Pixels whose surface normal (central differences of the world points ``(h, w, 3)``)
    is tilted more than ``acos(cos_limit)`` from up, or unknown, ``(h, w) bool``."""
    pad = np.pad(points, ((1, 1), (1, 1), (0, 0)), mode="edge")
    ax, ay, az = (pad[1:-1, 2:, i] - pad[1:-1, :-2, i] for i in range(3))
    bx, by, bz = (pad[2:, 1:-1, i] - pad[:-2, 1:-1, i] for i in range(3))
    nx = ay * bz - az * by
    ny = az * bx - ax * bz
    nz = ax * by - ay * bx
    with np.errstate(invalid="ignore"):
        level = nz * nz >= (cos_limit * cos_limit) * (nx * nx + ny * ny + nz * nz)
    out: np.ndarray = ~level
    return out


def _face_mean(level: np.ndarray, face: np.ndarray) -> np.ndarray:
    """The mean of ``level`` over the face pixels of each 5x5 neighbourhood, ``(h, w)``."""
    weight = face.astype(np.float32)
    total = ndi.uniform_filter(level * weight, 5)
    count = ndi.uniform_filter(weight, 5)
    out: np.ndarray = total / np.maximum(count, np.float32(1e-6))
    return out


def _largest_faces(face: np.ndarray, labels: np.ndarray, n: int) -> np.ndarray:
    """For every instance, only the largest 4-connected part of its face pixels."""
    parts, n_parts = ndi.label(face)
    if n_parts == 0:
        return face
    inside = face.nonzero()
    key = parts[inside].astype(np.int64) * (n + 1) + labels[inside]
    keys, sizes = np.unique(key, return_counts=True)
    owner = keys % (n + 1)
    part = keys // (n + 1)
    order = np.lexsort((-sizes, owner))
    first = np.ones(order.size, dtype=bool)
    first[1:] = owner[order][1:] != owner[order][:-1]
    chosen = np.full(n + 1, -1, dtype=np.int64)
    chosen[owner[order][first]] = part[order][first]
    out: np.ndarray = face & (parts == chosen[labels])
    return out


@dataclass(frozen=True, kw_only=True, eq=False)
class _Crop:
    """The images cut to the instances' bounding box and sampled every ``stride`` pixels:
    labels, depth, heights (NaN as 0 in ``level``), validity, world points ``(h, w, 3)`` and
    rays ``(h, w, 3)``."""

    labels: np.ndarray
    depth: np.ndarray
    level: np.ndarray
    finite: np.ndarray
    points: np.ndarray
    rays: np.ndarray
    stride: int


def _cut(images: DepthImages, pad: int, stride: int) -> _Crop | None:
    """The images cut to the bounding box of all instances plus ``pad``, every ``stride``-th
    pixel (None without any instance)."""
    labels = images.labels
    rows_any = np.flatnonzero(labels.any(axis=1))
    cols_any = np.flatnonzero(labels.any(axis=0))
    if rows_any.size == 0:
        return None
    h, w = labels.shape
    r = slice(max(int(rows_any[0]) - pad, 0), min(int(rows_any[-1]) + pad + 1, h), stride)
    c = slice(max(int(cols_any[0]) - pad, 0), min(int(cols_any[-1]) + pad + 1, w), stride)
    depth = images.depth_m[r, c]
    rays = images.view.rays[r, c]
    finite = np.isfinite(depth)
    return _Crop(
        labels=labels[r, c],
        depth=depth,
        level=np.where(finite, images.heights_m[r, c], np.float32(0.0)),
        finite=finite,
        points=depth[..., None] * rays + images.view.worldMoptical[:3, 3].astype(np.float32),
        rays=rays,
        stride=stride,
    )


def _faces(crop: _Crop, n: int, config: GeometryConfig) -> tuple[np.ndarray, np.ndarray]:
    """Every instance's top face ``(h, w) bool`` and the 5x5 face-mean heights."""
    inst = crop.labels > 0
    cos_limit = math.cos(math.radians(config.wall_slope_deg))
    face = inst & crop.finite & min3(crop.finite) & ~_steep(crop.points, cos_limit)
    smooth = _face_mean(crop.level, face)
    face &= np.abs(crop.level - smooth) <= config.face_outlier_m
    face = _largest_faces(face, crop.labels, n)
    thin = grouped.counts(crop.labels[face], n) < 3
    if thin[1:].any():
        face |= inst & crop.finite & thin[crop.labels]
    return face, smooth


def _outlines(
    crop: _Crop, face: np.ndarray, n: int, view: BeltView, config: GeometryConfig
) -> tuple[list[np.ndarray], np.ndarray]:
    """Every instance's footprint outline (face and rim, see the module), world x-y
    ``(m, 2)`` per instance, and the footprint ``(h, w) bool``."""
    labels, level = crop.labels, crop.level
    near_level = max3(np.where(face, level, -np.inf))
    rim = max3(face) & (labels > 0) & ~face
    rim &= np.abs(near_level - level) <= config.slope_noise_m
    rim &= max3(np.where(face, labels, 0)) == labels
    footprint = face | rim
    edge = footprint & ~min3(footprint)
    er, ec = np.nonzero(edge)
    on_rim = rim[er, ec]
    ray = crop.rays[er, ec].astype(np.float64)
    rim_z = near_level[er, ec].astype(np.float64) + view.belt_z_m
    with np.errstate(invalid="ignore", divide="ignore"):
        rim_depth = (rim_z - view.worldMoptical[2, 3]) / ray[:, 2]
    depth = np.where(on_rim, rim_depth, crop.depth[er, ec].astype(np.float64))
    xy = depth[:, None] * ray[:, :2] + view.worldMoptical[:2, 3]
    owner = labels[er, ec]
    order = np.argsort(owner, kind="stable")
    sizes = grouped.counts(owner, n)
    return np.split(xy[order], np.cumsum(sizes[1:])[:-1]), footprint


def _undersides(crop: _Crop, n: int, config: GeometryConfig) -> np.ndarray:
    """Every instance's underside: the ``underside_percentile`` of the heights in the ring
    ``ring_inner_px`` to ``ring_outer_px`` around it (0 without one), ``(n + 1,)``.

    With two label dilations (largest and smallest label in reach), so a ring pixel near two
    instances counts for both."""
    labels, level, finite = crop.labels, crop.level, crop.finite
    outer = 2 * math.ceil(config.ring_outer_px / crop.stride) + 1
    inner = 2 * math.ceil(config.ring_inner_px / crop.stride) + 1
    big = np.int32(n + 1)
    low = np.where(labels > 0, labels, big)
    in_max, in_min = ndi.maximum_filter(labels, inner), ndi.minimum_filter(low, inner)
    owners, values = [], []
    for candidate in (ndi.maximum_filter(labels, outer), ndi.minimum_filter(low, outer)):
        ring = (candidate > 0) & (candidate < big) & finite
        ring &= (in_max != candidate) & (in_min != candidate)
        owners.append(candidate[ring])
        values.append(level[ring])
    owner = np.concatenate(owners)
    value = np.concatenate(values).astype(np.float64)
    out: np.ndarray = np.nan_to_num(
        grouped.percentiles(owner, value, n, config.underside_percentile), nan=0.0
    )
    return out


def _suction_points(
    crop: _Crop,
    face: np.ndarray,
    footprint: np.ndarray,
    n: int,
    view: BeltView,
    config: GeometryConfig,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every instance's suction point ``(n + 1, 3)`` (world, m), radius ``(n + 1,)`` (m) and
    tilt ``(n + 1,)`` (rad); NaN where an instance has no face.

    The distance transform runs once over all footprints (face and rim: the whole seen top,
    each cut away from its neighbours); the plane fit is one grouped covariance of the face
    points near each instance's suction point."""
    labels = crop.labels
    own = np.where(footprint, labels, 0)
    alone = (max3(own) == own) & (min3(np.where(footprint, labels, n + 1)) == own)
    apart = footprint & alone
    distance = ndi.distance_transform_edt(apart)
    wr, wc = np.nonzero(apart)
    best = grouped.argmaxima(labels[wr, wc], distance[wr, wc], n)
    point = np.full((n + 1, 3), np.nan)
    radius = np.full(n + 1, np.nan)
    tilt = np.full(n + 1, np.nan)
    has = best >= 0
    if not has.any():
        return point, radius, tilt
    sr, sc = wr[best[has]], wc[best[has]]
    depth = crop.depth[sr, sc].astype(np.float64)
    pixel_m = crop.stride * depth / math.sqrt(view.intrinsics.fx_px * view.intrinsics.fy_px)
    point[has] = crop.points[sr, sc].astype(np.float64)
    radius[has] = np.maximum(distance[sr, sc] + RADIUS_OFFSET_PX, 0.0) * pixel_m
    centre_r = np.zeros(n + 1)
    centre_c = np.zeros(n + 1)
    centre_r[has], centre_c[has] = sr, sc
    fit_px = np.zeros(n + 1)
    fit_px[has] = FIT_SCALE * np.maximum(radius[has], config.min_fit_radius_m) / pixel_m
    fr, fc = np.nonzero(face)
    owner = labels[fr, fc]
    near = (fr - centre_r[owner]) ** 2 + (fc - centre_c[owner]) ** 2 <= fit_px[owner] ** 2
    tilt[1:] = _plane_tilts(crop.points[fr[near], fc[near]].astype(np.float64), owner[near], n)[1:]
    return point, radius, tilt


def _plane_tilts(points: np.ndarray, owner: np.ndarray, n: int) -> np.ndarray:
    """Angle between up and the normal of each group's least-squares plane (NaN with fewer
    than 6 points), ``(n + 1,)``."""
    count = grouped.counts(owner, n).astype(np.float64)
    safe = np.maximum(count, 1.0)
    mean = np.stack([grouped.sums(owner, points[:, i], n) / safe for i in range(3)], axis=1)
    cov = np.empty((n + 1, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            second = grouped.sums(owner, points[:, i] * points[:, j], n) / safe
            cov[:, i, j] = cov[:, j, i] = second - mean[:, i] * mean[:, j]
    _, vectors = np.linalg.eigh(cov)
    up = np.clip(np.abs(vectors[:, 2, 0]), 0.0, 1.0)
    out: np.ndarray = np.where(count >= 6, np.arccos(up), np.nan).astype(np.float64)
    return out


def frame_detections(
    images: DepthImages,
    *,
    class_names: Sequence[str],
    scores: Sequence[float],
    config: GeometryConfig,
) -> list[Detection | None]:
    """The detection of every instance ``1..n`` of ``images.labels`` (``n`` =
    ``len(class_names)``), ``None`` for one without a pixel with depth (see the module)."""
    n = len(class_names)
    view = images.view
    crop = _cut(images, config.ring_outer_px + 2, config.stride)
    if n == 0 or crop is None:
        return [None] * n
    face, smooth = _faces(crop, n, config)
    fr, fc = np.nonzero(face)
    owner = crop.labels[fr, fc]
    face_count = grouped.counts(owner, n)
    every = max(1, fr.size // _TOP_SAMPLES)
    top = grouped.percentiles(
        owner[::every],
        smooth[fr[::every], fc[::every]].astype(np.float64),
        n,
        config.top_percentile,
    )
    weight = crop.depth[fr, fc].astype(np.float64) ** 2
    face_xy = crop.points[fr, fc, :2].astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        total = grouped.sums(owner, weight, n)
        cx = grouped.sums(owner, face_xy[:, 0] * weight, n) / total
        cy = grouped.sums(owner, face_xy[:, 1] * weight, n) / total
    outlines, footprint = _outlines(crop, face, n, view, config)
    undersides = _undersides(crop, n, config)
    suction, radius, tilt = _suction_points(crop, face, footprint, n, view, config)
    seen = [k for k in range(1, n + 1) if face_count[k] > 0]
    rects = dict(
        zip(
            seen,
            min_area_rectangles(
                [outlines[k - 1] if len(outlines[k - 1]) else face_xy[owner == k] for k in seen]
            ),
            strict=True,
        )
    )
    out: list[Detection | None] = []
    for k in range(1, n + 1):
        if face_count[k] == 0:
            out.append(None)
            continue
        top_k = float(top[k]) if np.isfinite(top[k]) else float(smooth[fr, fc][owner == k].max())
        underside = min(max(float(undersides[k]), 0.0), top_k)
        rect = rects[k]
        out.append(
            Detection(
                class_name=class_names[k - 1],
                confidence=float(scores[k - 1]),
                x_m=float(cx[k]),
                y_m=float(cy[k]),
                z_m=view.belt_z_m + underside,
                yaw_rad=rect.angle_rad,
                length_m=rect.length,
                width_m=rect.width,
                height_m=top_k - underside,
                suction_point_m=(float(suction[k, 0]), float(suction[k, 1]), float(suction[k, 2])),
                suction_radius_m=float(radius[k]),
                suction_tilt_rad=float(tilt[k]),
            )
        )
    return out


__all__ = ["DepthImages", "frame_detections"]
