"""The minimum-area rectangle around a set of points in the plane (rotating calipers).

The convex hull (scipy's Qhull) of the points, then, for every hull edge direction, the
bounding box in that direction; the smallest one is the minimum-area rectangle (one of its
sides is collinear with a hull edge).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError


@dataclass(frozen=True, kw_only=True)
class Rectangle:
    """A rectangle in the plane: its centre, the direction of its long side (rad from the
    first axis towards the second, folded into (-pi/2, pi/2]) and its side lengths
    (``length >= width``), in the points' units."""

    centre: tuple[float, float]
    angle_rad: float
    length: float
    width: float


def _fold(angle_rad: float) -> float:
    a = math.fmod(angle_rad, math.pi)
    if a <= -math.pi / 2:
        a += math.pi
    elif a > math.pi / 2:
        a -= math.pi
    return a


def _hull(points: np.ndarray) -> np.ndarray:
    """The convex hull's vertices of ``points`` ``(n, 2)`` in order (a degenerate set: its two
    extreme points, or its single point)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] == 0 or not np.isfinite(pts).all():
        msg = "min_area_rectangle: needs at least one finite point"
        raise ValueError(msg)
    try:
        out: np.ndarray = pts[ConvexHull(pts).vertices]
    except (QhullError, ValueError):
        out = _collinear_ends(pts)
    return out


def min_area_rectangle(points: np.ndarray) -> Rectangle:
    """The minimum-area rectangle of ``points`` ``(n, 2)`` (n >= 1; degenerate sets give a
    zero width or length)."""
    return min_area_rectangles([points])[0]


def min_area_rectangles(point_sets: Sequence[np.ndarray]) -> list[Rectangle]:
    """:func:`min_area_rectangle` of each of ``point_sets`` (each ``(n_i, 2)``, n_i >= 1), the
    candidate directions of all sets evaluated at once (hulls padded to the longest by
    repeating their first vertex, padded edges never chosen): the same rectangles, without a
    dozen small array operations per set."""
    hulls = [_hull(p) for p in point_sets]
    out: list[Rectangle | None] = [None] * len(hulls)
    multi = []
    for k, hull in enumerate(hulls):
        if hull.shape[0] == 1:
            out[k] = Rectangle(
                centre=(float(hull[0, 0]), float(hull[0, 1])), angle_rad=0.0, length=0.0, width=0.0
            )
        else:
            multi.append(k)
    if multi:
        size = max(hulls[k].shape[0] for k in multi)
        hx = np.empty((len(multi), size))
        hy = np.empty((len(multi), size))
        valid = np.zeros((len(multi), size), dtype=bool)
        angles = np.zeros((len(multi), size))
        for row, k in enumerate(multi):
            hull = hulls[k]
            m = hull.shape[0]
            hx[row, :m], hy[row, :m] = hull[:, 0], hull[:, 1]
            hx[row, m:], hy[row, m:] = hull[0, 0], hull[0, 1]
            valid[row, :m] = True
            edges = np.concatenate((hull[1:], hull[:1])) - hull
            angles[row, :m] = np.mod(np.arctan2(edges[:, 1], edges[:, 0]), math.pi / 2)
        cos, sin = np.cos(angles), np.sin(angles)
        # hull coordinates along (cos, sin) and (-sin, cos) for every candidate direction
        along = cos[:, :, None] * hx[:, None, :] + sin[:, :, None] * hy[:, None, :]
        across = cos[:, :, None] * hy[:, None, :] - sin[:, :, None] * hx[:, None, :]
        a_max, a_min = along.max(axis=2), along.min(axis=2)
        b_max, b_min = across.max(axis=2), across.min(axis=2)
        span_a, span_b = a_max - a_min, b_max - b_min
        best = np.argmin(np.where(valid, span_a * span_b, np.inf), axis=1)
        for row, k in enumerate(multi):
            j = int(best[row])
            out[k] = _rectangle(
                float(angles[row, j]),
                (float(cos[row, j]), float(sin[row, j])),
                (float(a_min[row, j]), float(a_max[row, j])),
                (float(b_min[row, j]), float(b_max[row, j])),
            )
    return [r for r in out if r is not None]


def _rectangle(
    angle_rad: float,
    cos_sin: tuple[float, float],
    along: tuple[float, float],
    across: tuple[float, float],
) -> Rectangle:
    """The rectangle spanning ``along`` (min, max) in direction ``angle_rad`` (its cosine and
    sine ``cos_sin``) and ``across`` at right angles to it."""
    mid_a = 0.5 * (along[1] + along[0])
    mid_b = 0.5 * (across[1] + across[0])
    span_a, span_b = along[1] - along[0], across[1] - across[0]
    c, s = cos_sin
    centre = (mid_a * c - mid_b * s, mid_a * s + mid_b * c)
    if span_a >= span_b:
        angle, length, width = angle_rad, span_a, span_b
    else:
        angle, length, width = angle_rad + math.pi / 2, span_b, span_a
    return Rectangle(centre=centre, angle_rad=_fold(angle), length=length, width=width)


def _collinear_ends(pts: np.ndarray) -> np.ndarray:
    """The two extreme points of a (nearly) collinear set, or its single point."""
    centred = pts - pts.mean(axis=0)
    if not np.any(centred):
        return pts[:1]
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    t = centred @ vt[0]
    return pts[[int(np.argmin(t)), int(np.argmax(t))]]


__all__ = ["Rectangle", "min_area_rectangle", "min_area_rectangles"]
