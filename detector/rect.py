"""The minimum-area rectangle around a set of points in the plane (rotating calipers).

The convex hull (scipy's Qhull) of the points, then, for every hull edge direction, the
bounding box in that direction; the smallest one is the minimum-area rectangle (one of its
sides is collinear with a hull edge).
"""

from __future__ import annotations

import math
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


def min_area_rectangle(points: np.ndarray) -> Rectangle:
    """The minimum-area rectangle of ``points`` ``(n, 2)`` (n >= 1; degenerate sets give a
    zero width or length)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] == 0 or not np.isfinite(pts).all():
        msg = "min_area_rectangle: needs at least one finite point"
        raise ValueError(msg)
    try:
        hull = pts[ConvexHull(pts).vertices]
    except (QhullError, ValueError):
        hull = _collinear_ends(pts)
    if hull.shape[0] == 1:
        return Rectangle(
            centre=(float(hull[0, 0]), float(hull[0, 1])), angle_rad=0.0, length=0.0, width=0.0
        )
    edges = np.concatenate((hull[1:], hull[:1])) - hull
    angles = np.mod(np.arctan2(edges[:, 1], edges[:, 0]), math.pi / 2)
    cos, sin = np.cos(angles), np.sin(angles)
    # hull coordinates along (cos, sin) and (-sin, cos) for every candidate direction
    along = np.outer(cos, hull[:, 0]) + np.outer(sin, hull[:, 1])
    across = np.outer(cos, hull[:, 1]) - np.outer(sin, hull[:, 0])
    a_max, a_min = along.max(axis=1), along.min(axis=1)
    b_max, b_min = across.max(axis=1), across.min(axis=1)
    span_a, span_b = a_max - a_min, b_max - b_min
    best = int(np.argmin(span_a * span_b))
    mid_a = 0.5 * float(a_max[best] + a_min[best])
    mid_b = 0.5 * float(b_max[best] + b_min[best])
    c, s = float(cos[best]), float(sin[best])
    centre = (mid_a * c - mid_b * s, mid_a * s + mid_b * c)
    if span_a[best] >= span_b[best]:
        angle, length, width = float(angles[best]), float(span_a[best]), float(span_b[best])
    else:
        angle = float(angles[best]) + math.pi / 2
        length, width = float(span_b[best]), float(span_a[best])
    return Rectangle(centre=centre, angle_rad=_fold(angle), length=length, width=width)


def _collinear_ends(pts: np.ndarray) -> np.ndarray:
    """The two extreme points of a (nearly) collinear set, or its single point."""
    centred = pts - pts.mean(axis=0)
    if not np.any(centred):
        return pts[:1]
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    t = centred @ vt[0]
    return pts[[int(np.argmin(t)), int(np.argmax(t))]]


__all__ = ["Rectangle", "min_area_rectangle"]
