"""Metric footprints: pixel polygon to repaired, simplified polygon in the belt frame.

Belt frame of an image: metres, origin at the image centre on the belt surface, +x = image down
(the direction of travel: rows increase downstream), +y = image right, +z up (right-handed,
x × y = z when the camera looks down on the belt). ``m_per_px = belt_width_m / image_width_px``
on both axes, so a pixel ``(u, v)`` (column, row) maps to
``x = (v - height_px / 2) * m_per_px`` and ``y = (u - width_px / 2) * m_per_px``.

Repairs, in order: drop consecutive duplicate points and collinear points (this also removes
out-and-back spikes A→B→A), make the ring counter-clockwise seen from +z, repair
self-intersections with GEOS ``make_valid`` keeping the largest polygonal part (holes dropped),
optionally simplify with a tolerance (Douglas–Peucker, falling back to the topology-preserving
variant where plain Douglas–Peucker does not give one valid polygon), and reject what is left
when it is below the minimum area. Each change is recorded in ``repairs``. A ring with fewer
than three distinct non-collinear points, or a self-intersecting one with no area left, is
rejected as ``degenerate``.

The self-intersection repair records ``kept_area_ratio``: the area of the part kept over the
area of the whole valid geometry GEOS makes of the outline (each region the outline encloses
counted once), so it lies in (0, 1]: 1 when nothing was cut off, 0.5 for a bow-tie of two equal
loops. The signed shoelace area of the input is not used as the reference: the loops of a
self-intersecting ring cancel in it, down to zero for a symmetric bow-tie.

:func:`build_footprints` treats all polygons of an image together: GEOS is called once per step
(validity, simplification, convex hull) on an array of geometries and the measurements (area,
centroid, minimum-area rectangle, convexity) are vectorised in numpy; only the rare invalid
rings are repaired one at a time. Points of many rings live in one ``(N, 2)`` array; rows are
gathered with ``np.take``/``np.compress`` along axis 0 and tests run on the two coordinate
columns, which gives the same values as ``a[idx]``, ``a[mask]`` and ``.any(axis=1)`` at a
fraction of their cost on such narrow arrays (numpy's general fancy indexing handles each short
row on its own).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import shapely

from meshgen.annotations import FloatArray
from meshgen.ragged import split_rows

IntArray = npt.NDArray[np.int64]

COLLINEAR_REL_TOL = 1e-9
CONVEX_REL_TOL = 1e-9


@dataclass(frozen=True, slots=True, kw_only=True)
class Footprint:
    """A repaired metric footprint in the belt frame.

    ``ring_m`` is ``(n, 2) float``, counter-clockwise seen from +z, not closed, n >= 3.
    ``area_change_ratio`` is the simplified area divided by the repaired area before simplifying.
    ``convex`` is True when the ring turns left or goes straight at every vertex.
    """

    ring_m: FloatArray
    area_m2: float
    centroid_m: tuple[float, float]
    yaw_rad: float
    length_m: float
    width_m: float
    area_change_ratio: float
    repairs: tuple[str, ...]
    convex: bool = True


class FootprintRejected(Exception):  # noqa: N818 - control flow, not an error for the user
    """The polygon cannot give a footprint; ``reason`` is a key of ``SKIP_REASONS``."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason
        self.detail = detail


def pixels_to_belt(
    points_px: FloatArray, width_px: int, height_px: int, m_per_px: float
) -> FloatArray:
    """Map ``(n, 2)`` pixel points ``(u, v)`` to ``(n, 2)`` belt-frame points ``(x, y)`` in m."""
    out = np.empty_like(points_px)
    out[:, 0] = (points_px[:, 1] - 0.5 * height_px) * m_per_px
    out[:, 1] = (points_px[:, 0] - 0.5 * width_px) * m_per_px
    return out


def touches_border(points_px: FloatArray, width_px: int, height_px: int, margin_px: float) -> bool:
    """True when any ``(n, 2)`` pixel point lies within ``margin_px`` of the image border."""
    u, v = points_px[:, 0], points_px[:, 1]
    return bool(
        u.min() <= margin_px
        or v.min() <= margin_px
        or u.max() >= width_px - 1 - margin_px
        or v.max() >= height_px - 1 - margin_px
    )


def _next(a: FloatArray) -> FloatArray:
    return np.concatenate((a[1:], a[:1]))


def _prev(a: FloatArray) -> FloatArray:
    return np.concatenate((a[-1:], a[:-1]))


def signed_area(ring: FloatArray) -> float:
    """Shoelace signed area of an open ``(n, 2)`` ring; positive when counter-clockwise."""
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(x[:-1] @ y[1:] - x[1:] @ y[:-1] + x[-1] * y[0] - x[0] * y[-1])


def clean_ring(ring: FloatArray) -> tuple[FloatArray, int, int]:
    """Drop consecutive duplicates and collinear points (spikes included) until stable.

    Returns the ``(m, 2)`` ring and the numbers of duplicate and collinear points removed.
    """
    duplicates = collinear = 0
    scale = float(np.ptp(ring, axis=0).max()) if len(ring) else 0.0
    tol = COLLINEAR_REL_TOL * scale * scale
    while len(ring) >= 3:
        keep = np.any(ring != _prev(ring), axis=1)
        if not keep.all():
            duplicates += int((~keep).sum())
            ring = ring[keep]
            if not keep.any():
                break
            continue
        a = ring - _prev(ring)
        b = _next(ring) - ring
        cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
        flat = np.abs(cross) <= tol
        if not flat.any():
            break
        # Drop every other point of a run of flagged neighbours; the rest is re-checked next pass.
        idx = np.flatnonzero(flat)
        starts = np.concatenate(([True], np.diff(idx) > 1))
        run_start = np.maximum.accumulate(np.where(starts, np.arange(len(idx)), 0))
        drop = idx[(np.arange(len(idx)) - run_start) % 2 == 0]
        if len(drop) > 1 and drop[0] == 0 and drop[-1] == len(ring) - 1:
            drop = drop[:-1]
        mask = np.ones(len(ring), dtype=bool)
        mask[drop] = False
        collinear += len(drop)
        ring = ring[mask]
    return ring, duplicates, collinear


def _largest_part(geom: shapely.Geometry) -> shapely.Polygon | None:
    parts = [
        g
        for g in shapely.get_parts(geom)
        if isinstance(g, shapely.Polygon | shapely.MultiPolygon) and not g.is_empty
    ]
    polys: list[shapely.Polygon] = []
    for part in parts:
        polys.extend(shapely.get_parts(part) if isinstance(part, shapely.MultiPolygon) else [part])
    if not polys:
        return None
    return max(polys, key=lambda p: p.area)


def _exterior(poly: shapely.Polygon) -> FloatArray:
    return np.asarray(poly.exterior.coords, dtype=np.float64)[:-1]


def min_area_rectangle(
    ring: FloatArray, polygon: shapely.Polygon | None = None
) -> tuple[float, float, float]:
    """Yaw of the long axis in (-pi/2, pi/2] and length >= width of the min-area rectangle.

    ``ring`` is ``(n, 2) float`` (``polygon``, when given, is the same ring as a shapely polygon);
    the rectangle is found by rotating calipers over the convex hull.
    """
    source = polygon if polygon is not None else shapely.multipoints(ring)
    hull = shapely.convex_hull(source)
    pts = np.asarray(shapely.get_coordinates(hull), dtype=np.float64)
    if len(pts) < 4:
        pts = ring
        edges = _next(pts) - pts
    else:
        edges = pts[1:] - pts[:-1]
        pts = pts[:-1]
    lengths = np.hypot(edges[:, 0], edges[:, 1])
    ok = lengths > 0
    units = edges[ok] / lengths[ok, None]
    along = pts @ units.T
    across = pts @ np.stack((-units[:, 1], units[:, 0]), axis=1).T
    ext_a = along.max(axis=0) - along.min(axis=0)
    ext_c = across.max(axis=0) - across.min(axis=0)
    best = int(np.argmin(ext_a * ext_c))
    ux, uy = units[best]
    length, width = float(ext_a[best]), float(ext_c[best])
    if width > length:
        ux, uy = -uy, ux
        length, width = width, length
    yaw = math.atan2(uy, ux)
    if yaw <= -math.pi / 2:
        yaw += math.pi
    elif yaw > math.pi / 2:
        yaw -= math.pi
    return yaw, length, width


def _ragged_polygons(rings: list[FloatArray]) -> npt.NDArray[np.object_]:
    """Shapely polygons of open ``(n_i, 2)`` rings, built in one call."""
    sizes = np.fromiter((len(r) for r in rings), dtype=np.int64, count=len(rings))
    counts = sizes + 1
    ring_offsets = np.concatenate(([0], np.cumsum(counts)))
    starts = np.cumsum(sizes) - sizes
    # each ring's points in order, then its first point again to close it
    source = np.arange(ring_offsets[-1]) - np.repeat(ring_offsets[:-1] - starts, counts)
    source[ring_offsets[1:] - 1] = starts
    closed = np.take(np.concatenate(rings), source, axis=0)
    poly_offsets = np.arange(len(rings) + 1, dtype=np.int64)
    polys: npt.NDArray[np.object_] = shapely.from_ragged_array(
        shapely.GeometryType.POLYGON, closed, (ring_offsets, poly_offsets)
    )
    return polys


def _make_valid(ring: FloatArray, repairs: list[str]) -> FloatArray:
    """Largest valid part of a self-intersecting CCW ring (holes dropped), as a CCW ring.

    Records ``self_intersection_repaired:kept_area_ratio=r`` with ``r`` the kept part's area
    over the area of everything ``make_valid`` returns (see the module docstring).
    """
    valid = shapely.make_valid(shapely.Polygon(ring))
    fixed = _largest_part(valid)
    if fixed is None or fixed.area <= 0.0:
        raise FootprintRejected("degenerate", "self-intersecting polygon with no area left")
    kept = fixed.area / valid.area  # lines and points have no area: valid.area >= fixed.area
    repairs.append(f"self_intersection_repaired:kept_area_ratio={kept:.4f}")
    if len(fixed.interiors):
        repairs.append(f"holes_dropped:{len(fixed.interiors)}")
    ring, _, _ = clean_ring(_exterior(fixed))
    if len(ring) < 3:
        raise FootprintRejected("degenerate", "repaired polygon has fewer than 3 points")
    if signed_area(ring) < 0.0:
        ring = ring[::-1].copy()
    return ring


def _segments(sizes: IntArray) -> tuple[IntArray, IntArray, IntArray, IntArray]:
    """Start/end offsets and next/previous point indices of rings concatenated by ``sizes``."""
    ends = np.cumsum(sizes)
    starts = ends - sizes
    idx = np.arange(int(ends[-1]) if len(ends) else 0, dtype=np.int64)
    nxt = idx + 1
    nxt[ends - 1] = starts
    prv = idx - 1
    prv[starts] = ends - 1
    return starts, ends, nxt, prv


def _signed_areas(pts: FloatArray, sizes: IntArray) -> FloatArray:
    """Shoelace signed areas of rings concatenated in ``pts`` (sizes >= 1)."""
    starts, _, nxt, _ = _segments(sizes)
    p = pts - np.repeat(np.take(pts, starts, axis=0), sizes, axis=0)
    x, y = p[:, 0], p[:, 1]
    result: FloatArray = 0.5 * np.add.reduceat(x * y[nxt] - x[nxt] * y, starts)
    return result


def _without_duplicates(
    rings: list[FloatArray], exact: bool
) -> tuple[FloatArray, IntArray, IntArray, IntArray]:
    """Rings without consecutive duplicate points, concatenated: ``(pts, sizes, dups, cols)``.

    ``exact`` cleans each ring with :func:`clean_ring` (collinear points too); otherwise the
    duplicates of all rings are dropped in one vectorised pass and no collinear point is
    counted. ``dups`` and ``cols`` are the numbers of points removed per ring.
    """
    count = len(rings)
    if exact:
        cleaned = [clean_ring(r) for r in rings]
        rings = [c[0] for c in cleaned]
        duplicates = np.array([c[1] for c in cleaned], dtype=np.int64)
        collinear = np.array([c[2] for c in cleaned], dtype=np.int64)
        sizes = np.fromiter((len(r) for r in rings), dtype=np.int64, count=count)
        pts = np.concatenate(rings) if (sizes > 0).any() else np.empty((0, 2))
        return pts, sizes, duplicates, collinear
    raw_sizes = np.fromiter((len(r) for r in rings), dtype=np.int64, count=count)
    raw = np.concatenate(rings)
    _, _, _, prv = _segments(raw_sizes)
    x, y = raw[:, 0], raw[:, 1]
    keep = (x != x[prv]) | (y != y[prv])
    pts = np.compress(keep, raw, axis=0)
    sizes = np.add.reduceat(keep.astype(np.int64), raw_sizes.cumsum() - raw_sizes)
    return pts, sizes, raw_sizes - sizes, np.zeros(count, dtype=np.int64)


def _counter_clockwise(
    pts: FloatArray, sizes: IntArray
) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Concatenated rings each turned counter-clockwise, and which of them were reversed."""
    count = len(sizes)
    live = sizes > 0
    live_sizes = sizes[live]
    signed = np.zeros(count)
    if len(live_sizes):
        signed[live] = _signed_areas(pts, live_sizes)
    flip = signed < 0.0
    if flip.any():
        owner = np.repeat(np.arange(count), sizes)
        starts = np.cumsum(sizes) - sizes
        idx = np.arange(len(pts))
        mirrored = 2 * starts[owner] + sizes[owner] - 1 - idx
        pts = np.take(pts, np.where(flip[owner], mirrored, idx), axis=0)
    return pts, flip


def _finish_ring(
    ring: FloatArray, counts: tuple[int, int], *, valid: bool, flipped: bool, exact: bool
) -> tuple[FloatArray, list[str]] | FootprintRejected:
    """One ring's last repairs (see :func:`_repair_all`) and the list of every repair made.

    ``counts`` are the duplicate and collinear points already removed; ``valid`` is GEOS's
    verdict on ``ring``, ``flipped`` whether it was reversed.
    """
    dup, col = counts
    if len(ring) >= 3 and not exact and not valid:
        ring, more_dup, col = clean_ring(ring)
        dup += more_dup
        valid = len(ring) >= 3 and bool(shapely.is_valid(shapely.Polygon(ring)))
    repairs: list[str] = []
    if dup:
        repairs.append(f"removed_duplicates:{dup}")
    if col:
        repairs.append(f"removed_collinear:{col}")
    if len(ring) < 3:
        return FootprintRejected("degenerate", f"{len(ring)} distinct non-collinear point(s) left")
    if flipped:
        repairs.append("reoriented")
    if not valid:
        try:
            ring = _make_valid(ring, repairs)
        except FootprintRejected as exc:
            return exc
    return ring, repairs


def _repair_all(
    rings: list[FloatArray], exact: bool
) -> list[tuple[FloatArray, list[str]] | FootprintRejected]:
    """Valid CCW rings and their repairs (or the rejection), validity tested in one GEOS call.

    ``exact`` also drops collinear points of valid rings; otherwise only invalid rings (spikes,
    out-and-back traces) are cleaned of collinear points before ``make_valid`` is considered.
    Duplicate removal and orientation are vectorised over all rings.
    """
    pts, sizes, duplicates, collinear = _without_duplicates(rings, exact)
    pts, flip = _counter_clockwise(pts, sizes)
    split = split_rows(pts, sizes)
    usable = np.flatnonzero(sizes >= 3)
    valid = np.zeros(len(rings), dtype=bool)
    if len(usable):
        valid[usable] = shapely.is_valid(_ragged_polygons([split[i] for i in usable]))
    return [
        _finish_ring(ring, (dup, col), valid=ok, flipped=flipped, exact=exact)
        for ring, dup, col, ok, flipped in zip(
            split,
            duplicates.tolist(),
            collinear.tolist(),
            valid.tolist(),
            flip.tolist(),
            strict=True,
        )
    ]


def _simplify_all(
    rings: list[FloatArray], polys: npt.NDArray[np.object_], tol_m: float
) -> tuple[list[FloatArray | None], FloatArray]:
    """Douglas–Peucker simplified CCW rings (``None`` where simplifying gives nothing better).

    All rings go through GEOS in one call; results that are not a single valid polygon are
    simplified again with the topology-preserving variant. Also returns the ``(m,)`` areas of
    the simplified rings (0 where ``None``).
    """
    simple = shapely.simplify(polys, tol_m, preserve_topology=False)
    good = (shapely.get_type_id(simple) == 3) & ~shapely.is_empty(simple) & shapely.is_valid(simple)
    if not good.all():
        bad = ~good
        simple[bad] = shapely.simplify(polys[bad], tol_m, preserve_topology=True)
    ok = (shapely.get_type_id(simple) == 3) & ~shapely.is_empty(simple)
    exteriors = shapely.get_exterior_ring(np.where(ok, simple, None))
    counts = shapely.get_num_coordinates(exteriors)
    coords = shapely.get_coordinates(exteriors)
    sizes = np.maximum(counts - 1, 0)
    old = np.fromiter((len(r) for r in rings), dtype=np.int64, count=len(rings))
    accept = ok & (sizes >= 3) & (sizes < old)
    open_mask = np.ones(len(coords), dtype=bool)
    open_mask[np.cumsum(counts)[counts > 0] - 1] = False
    pts = np.compress(open_mask, coords, axis=0)
    areas = np.zeros(len(rings))
    live = sizes > 0
    if live.any():
        areas[live] = _signed_areas(pts, sizes[live])
    split = split_rows(pts, sizes)
    out: list[FloatArray | None] = []
    for i in range(len(rings)):
        if not accept[i]:
            out.append(None)
        elif areas[i] < 0.0:
            out.append(split[i][::-1].copy())
        else:
            out.append(split[i])
    return out, np.abs(areas)


def _projections(pts: FloatArray, units: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Coordinates of ``(m, p, 2)`` points along ``(m, e, 2)`` unit edges and their normals.

    Returns ``(m, p, e)`` arrays ``x * ux + y * uy`` and ``x * -uy + y * ux`` (normal
    ``(-uy, ux)``), the products summed in that order: the same numbers as
    ``np.einsum("mpd,med->mpe", ...)`` with ``units`` and the normals (up to the sign of a zero),
    without einsum's slow generic loop for a contraction of length two.
    """
    x, y = pts[:, :, None, 0], pts[:, :, None, 1]
    ux, uy = units[:, None, :, 0], units[:, None, :, 1]
    along: FloatArray = x * ux + y * uy
    across: FloatArray = x * -uy + y * ux
    return along, across


CALIPER_GROUP = 64
"""Hulls measured together by :func:`_min_area_rectangles`: sorted by size and taken in groups,
so each group is padded only to its own largest hull (the work per group grows with the
square of that size)."""


def _calipers(
    coords: FloatArray, starts: IntArray, sizes: IntArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Yaw, length and width of the minimum-area rectangles of many convex hulls.

    Hull ``i`` is the closed ring ``coords[starts[i] : starts[i] + sizes[i] + 1]``. Every hull
    edge direction is tried at once, hulls padded with their closing point to the largest size
    (padding changes no extent; padded edges are never chosen).
    """
    width = int(sizes.max())
    col = np.arange(width)
    take = starts[:, None] + np.minimum(col[None, :], sizes[:, None])
    pts = np.take(coords, take, axis=0)  # (m, w, 2): hull points, padded with the first
    after = starts[:, None] + np.minimum(col[None, :] + 1, sizes[:, None])
    pts_next = np.take(coords, after, axis=0)
    edges = pts_next - pts
    lengths = np.hypot(edges[..., 0], edges[..., 1])
    used = (col[None, :] < sizes[:, None]) & (lengths > 0)
    units = edges / np.where(used, lengths, 1.0)[..., None]
    along, across = _projections(pts, units)
    ext_a = along.max(axis=1) - along.min(axis=1)
    ext_c = across.max(axis=1) - across.min(axis=1)
    best = np.argmin(np.where(used, ext_a * ext_c, np.inf), axis=1)
    rows = np.arange(len(sizes))
    ux, uy = units[rows, best, 0], units[rows, best, 1]
    length, wide = ext_a[rows, best], ext_c[rows, best]
    swap = wide > length
    ux, uy = np.where(swap, -uy, ux), np.where(swap, ux, uy)
    length, wide = np.where(swap, wide, length), np.where(swap, length, wide)
    yaw = np.arctan2(uy, ux)
    yaw = np.where(yaw <= -math.pi / 2, yaw + math.pi, yaw)
    yaw = np.where(yaw > math.pi / 2, yaw - math.pi, yaw)
    return yaw, length, wide


def _min_area_rectangles(
    rings: list[FloatArray], polys: npt.NDArray[np.object_]
) -> list[tuple[float, float, float]]:
    """:func:`min_area_rectangle` of many rings: one GEOS hull call, calipers padded in numpy."""
    hulls = shapely.convex_hull(polys)
    counts = shapely.get_num_coordinates(hulls)
    out: list[tuple[float, float, float] | None] = [None] * len(rings)
    todo = np.flatnonzero(counts >= 4)
    if len(todo):
        coords = shapely.get_coordinates(hulls[todo])
        sizes = counts[todo] - 1
        starts = np.concatenate(([0], np.cumsum(sizes + 1)[:-1]))
        by_size = np.argsort(sizes, kind="stable")
        for first in range(0, len(by_size), CALIPER_GROUP):
            group = by_size[first : first + CALIPER_GROUP]
            yaw, length, wide = _calipers(coords, starts[group], sizes[group])
            measured = zip(yaw.tolist(), length.tolist(), wide.tolist(), strict=True)
            for i, rect in zip(todo[group].tolist(), measured, strict=True):
                out[i] = rect
    return [r if r is not None else min_area_rectangle(rings[i]) for i, r in enumerate(out)]


def _extents(rings: list[FloatArray]) -> FloatArray:
    """The longer bounding-box side of each of many ``(n_i, 2)`` rings, ``(m,) float``."""
    sizes = np.fromiter((len(r) for r in rings), dtype=np.int64, count=len(rings))
    pts = np.concatenate(rings)
    starts = np.cumsum(sizes) - sizes
    span: FloatArray = np.maximum(
        np.maximum.reduceat(pts[:, 0], starts) - np.minimum.reduceat(pts[:, 0], starts),
        np.maximum.reduceat(pts[:, 1], starts) - np.minimum.reduceat(pts[:, 1], starts),
    )
    return span


def _convexity(rings: list[FloatArray], span: FloatArray) -> list[bool]:
    """:func:`is_convex` semantics (left turn or straight everywhere) for many rings at once.

    ``span`` is :func:`_extents` of ``rings``.
    """
    sizes = np.fromiter((len(r) for r in rings), dtype=np.int64, count=len(rings))
    pts = np.concatenate(rings)
    ends = np.cumsum(sizes)
    starts = ends - sizes
    idx = np.arange(len(pts))
    nxt = idx + 1
    nxt[ends - 1] = starts
    prv = idx - 1
    prv[starts] = ends - 1
    x, y = pts[:, 0], pts[:, 1]
    cross = (x - x[prv]) * (y[nxt] - y) - (y - y[prv]) * (x[nxt] - x)
    tol = -CONVEX_REL_TOL * span * span
    ok = np.minimum.reduceat(cross - np.repeat(tol, sizes), starts) >= 0.0
    return [bool(v) for v in ok]


def _centroid_areas(rings: list[FloatArray]) -> FloatArray:
    """Signed areas of many open rings (one vectorised shoelace)."""
    sizes = np.fromiter((len(r) for r in rings), dtype=np.int64, count=len(rings))
    return _signed_areas(np.concatenate(rings), sizes)


def _centroids(rings: list[FloatArray]) -> list[tuple[float, float, float]]:
    """Area and centroid ``(area_m2, cx, cy)`` of each open counter-clockwise ``(n, 2)`` ring.

    A ring of zero shoelace area (collinear in floating point, though GEOS found it valid) gets
    a centroid of nan without a warning; :func:`build_footprints` rejects such rings.
    """
    sizes = np.fromiter((len(r) for r in rings), dtype=np.int64, count=len(rings))
    pts = np.concatenate(rings)
    ends = np.cumsum(sizes)
    starts = ends - sizes
    origin = np.take(pts, starts, axis=0)
    p = pts - np.repeat(origin, sizes, axis=0)
    nxt = np.arange(1, len(pts) + 1)
    nxt[ends - 1] = starts
    x, y = p[:, 0], p[:, 1]
    qx, qy = x[nxt], y[nxt]
    cross = x * qy - qx * y
    area = 0.5 * np.add.reduceat(cross, starts)
    six_area = np.where(area != 0.0, 6.0 * area, np.nan)
    cx = np.add.reduceat((x + qx) * cross, starts) / six_area
    cy = np.add.reduceat((y + qy) * cross, starts) / six_area
    cx += origin[:, 0]
    cy += origin[:, 1]
    return list(zip(area.tolist(), cx.tolist(), cy.tolist(), strict=True))


def build_footprints(
    rings_m: list[FloatArray], *, simplify_m: float, min_area_m2: float
) -> list[Footprint | FootprintRejected]:
    """Validate, repair, simplify and measure many ``(n_i, 2)`` metric rings (one image's worth).

    The result has one entry per ring, in order: its :class:`Footprint`, or the
    :class:`FootprintRejected` that says why nothing valid of at least ``min_area_m2`` remains.
    GEOS is called once per step for all rings (validity, simplification, convex hull); the rare
    invalid rings are repaired one by one. With simplification on, collinear points are left to
    the simplifier unless the ring is invalid (spikes); without it they are removed exactly.
    """
    rings = [np.asarray(r, dtype=np.float64) for r in rings_m]
    repaired = _repair_all(rings, exact=simplify_m <= 0.0)
    ok = [i for i, r in enumerate(repaired) if not isinstance(r, FootprintRejected)]
    final: list[FloatArray] = []
    repairs: list[list[str]] = []
    ratios: list[float] = []
    for i in ok:
        item = repaired[i]
        assert not isinstance(item, FootprintRejected)
        final.append(item[0])
        repairs.append(item[1])
        ratios.append(1.0)
    if not ok:
        return [r for r in repaired if isinstance(r, FootprintRejected)]
    polys = _ragged_polygons(final)
    if simplify_m > 0.0:
        big = [k for k, ring in enumerate(final) if len(ring) > 4]
        if big:
            before = np.abs(_centroid_areas([final[k] for k in big]))
            simple, after = _simplify_all([final[k] for k in big], polys[big], simplify_m)
            for j, (k, candidate) in enumerate(zip(big, simple, strict=True)):
                if candidate is None:
                    continue
                repairs[k].append(f"simplified:{len(final[k])}->{len(candidate)}")
                final[k] = candidate
                ratios[k] = float(after[j] / before[j]) if before[j] > 0 else 1.0
            polys = _ragged_polygons(final)
    measures = _centroids(final)
    rects = _min_area_rectangles(final, polys)
    spans = _extents(final)
    convex = _convexity(final, spans)
    flat = (0.5 * COLLINEAR_REL_TOL * spans * spans).tolist()
    results: list[Footprint | FootprintRejected] = []
    k = 0
    for item in repaired:
        if isinstance(item, FootprintRejected):
            results.append(item)
            continue
        area, cx, cy = measures[k]
        if not area > flat[k]:
            msg = f"the outline encloses no area: its points are collinear (area {area:.3g} m^2)"
            results.append(FootprintRejected("degenerate", msg))
        elif area < min_area_m2:
            msg = f"area {area * 1e6:.2f} mm^2 < minimum {min_area_m2 * 1e6:.2f} mm^2"
            results.append(FootprintRejected("below_min_area", msg))
        else:
            yaw, length, width = rects[k]
            results.append(
                Footprint(
                    ring_m=final[k],
                    area_m2=area,
                    centroid_m=(cx, cy),
                    yaw_rad=yaw,
                    length_m=length,
                    width_m=width,
                    area_change_ratio=ratios[k],
                    repairs=tuple(repairs[k]),
                    convex=convex[k],
                )
            )
        k += 1
    return results


def build_footprint(ring_m: FloatArray, *, simplify_m: float, min_area_m2: float) -> Footprint:
    """Validate, repair and optionally simplify a ``(n, 2)`` metric ring; measure the result.

    One-ring form of :func:`build_footprints`; raises :class:`FootprintRejected` when nothing
    valid of at least ``min_area_m2`` remains.
    """
    (result,) = build_footprints([ring_m], simplify_m=simplify_m, min_area_m2=min_area_m2)
    if isinstance(result, FootprintRejected):
        raise result
    return result
