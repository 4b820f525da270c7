"""Prism meshes from footprints: earcut triangulation, extrusion, convex decomposition, OBJ text.

The triangulation engine is pinned: ``mapbox_earcut.triangulate_float64`` (ear clipping), called
once per footprint; its triangles form both caps of the prism and seed the Hertel–Mehlhorn
convex decomposition. A prism over an open counter-clockwise ring of ``n`` points has ``2n``
vertices and ``4n - 4`` triangles, every edge shared by exactly two of them (watertight,
consistently wound, normals outward).

Mesh local frame: origin at the centre of mass (footprint centroid, half the height above the
belt), axes parallel to the belt frame. ``up="z"`` writes ``(x, y, z)`` (ROS REP 103),
``up="y"`` writes ``(x, z, -y)``.

OBJ text is written for a whole batch of prisms at once (:mod:`meshgen.prisms`,
:mod:`meshgen.objtext`). The one piece made here is the face text of the side walls of an
``n``-prism (:func:`sides_text`), which depends only on ``n`` and is cached for the run
(:func:`clear_text_caches` empties the cache; the pipeline calls it at the start of each run).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import compress

import mapbox_earcut
import numpy as np
import numpy.typing as npt

from meshgen.annotations import FloatArray
from meshgen.ragged import join_rows, split_rows

IntArray = npt.NDArray[np.int64]

CONVEX_REL_TOL = 1e-9


def triangulate(ring: FloatArray) -> IntArray:
    """Ear-clip an open counter-clockwise ``(n, 2)`` ring into ``(n - 2, 3) int`` CCW triangles."""
    tris = mapbox_earcut.triangulate_float64(ring, np.array([len(ring)], dtype=np.uint32))
    faces = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    corners = ring[faces]
    d1 = corners[:, 1] - corners[:, 0]
    d2 = corners[:, 2] - corners[:, 0]
    flip = d1[:, 0] * d2[:, 1] < d1[:, 1] * d2[:, 0]
    if flip.all():
        return faces[:, ::-1].copy()
    if flip.any():
        faces[flip] = faces[flip][:, ::-1]
    return faces


def triangulate_many(rings: list[FloatArray]) -> list[IntArray]:
    """:func:`triangulate` of many rings: one earcut call each, orientation fixed in one pass.

    Gives exactly what :func:`triangulate` gives for each ring (same triangles, same order, each
    triangle with a clockwise result reversed); only the orientation check, which costs more
    than earcut itself on small rings, is vectorised over all rings together
    (:func:`triangulate_ragged`).
    """
    if not rings:
        return []
    sizes = np.fromiter((len(r) for r in rings), dtype=np.int64, count=len(rings))
    faces, counts = triangulate_ragged(rings, np.concatenate(rings), sizes)
    return split_rows(faces, counts)


def triangulate_ragged(
    rings: list[FloatArray], points: FloatArray, sizes: IntArray
) -> tuple[IntArray, IntArray]:
    """:func:`triangulate_many` as one ``(M, 3)`` array of ring-local triangles and its counts.

    ``points`` is ``rings`` concatenated (``sizes`` their lengths). The orientation check runs
    on coordinate columns (same products as :func:`triangulate`; a reversed ``(a, b, c)`` is
    ``(c, b, a)``).
    """
    raw = [
        np.asarray(
            mapbox_earcut.triangulate_float64(ring, np.array([len(ring)], dtype=np.uint32)),
            dtype=np.int64,
        )
        for ring in rings
    ]
    counts = np.fromiter((len(t) // 3 for t in raw), dtype=np.int64, count=len(raw))
    shift = np.repeat(np.cumsum(sizes) - sizes, counts)[:, None]
    faces = np.concatenate(raw).reshape(-1, 3) + shift
    x, y = points[:, 0], points[:, 1]
    a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
    flip = (x[b] - x[a]) * (y[c] - y[a]) < (y[b] - y[a]) * (x[c] - x[a])
    faces[:, 0], faces[:, 2] = np.where(flip, c, a), np.where(flip, a, c)
    faces -= shift
    return faces, counts


def extrude(ring: FloatArray, tris: IntArray, height_m: float) -> tuple[FloatArray, IntArray]:
    """Prism between ``z = -height/2`` and ``+height/2`` over a CCW ``(n, 2)`` ring.

    ``tris`` is ``(m, 3) int`` CCW cap triangles. Returns ``(2n, 3) float`` vertices (bottom ring,
    then top ring) and ``(2m + 2n, 3) int`` outward-wound triangles.
    """
    n = len(ring)
    half = 0.5 * height_m
    verts = np.empty((2 * n, 3), dtype=np.float64)
    verts[:n, :2] = ring
    verts[n:, :2] = ring
    verts[:n, 2] = -half
    verts[n:, 2] = half
    i = np.arange(n, dtype=np.int64)
    j = np.concatenate((i[1:], i[:1]))
    sides = np.empty((2 * n, 3), dtype=np.int64)
    sides[0::2] = np.stack((i, j, j + n), axis=1)
    sides[1::2] = np.stack((i, j + n, i + n), axis=1)
    faces = np.concatenate((tris[:, ::-1], tris + n, sides))
    return verts, faces


def is_convex(ring: FloatArray) -> bool:
    """True when the open CCW ``(n, 2)`` ring turns left (or goes straight) at every vertex."""
    prev = np.concatenate((ring[-1:], ring[:-1]))
    a = ring - prev
    b = np.concatenate((ring[1:], ring[:1])) - ring
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    scale = float(np.ptp(ring, axis=0).max())
    return bool((cross >= -CONVEX_REL_TOL * scale * scale).all())


def interior_diagonals(tris_list: list[IntArray], sizes: list[int]) -> tuple[IntArray, IntArray]:
    """Interior half-edge pairs of many triangulations (of rings of ``sizes[i]`` points) at once.

    The half-edges of all triangulations are numbered one after another: half-edge ``e`` of
    the concatenated ``tris.ravel()`` arrays runs from its corner to the next corner of its
    triangle. Returns ``(e, f)``: every half-edge ``e`` whose start index is below its end
    index and that has a twin ``f`` (the same edge, reversed, in the neighbouring triangle of
    the same ring), ``e`` increasing. Vertex indices are shifted by the preceding rings' sizes,
    so edge keys never collide between rings and one stable sort and one search serve them all.
    """
    if not tris_list:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    counts = np.fromiter((t.size for t in tris_list), dtype=np.int64, count=len(tris_list))
    ring_sizes = np.array(sizes, dtype=np.int64)
    vertex_shift = np.repeat(np.cumsum(ring_sizes) - ring_sizes, counts)
    org = np.concatenate([t.ravel() for t in tris_list]) + vertex_shift
    total = len(org)
    stride = int(ring_sizes.sum())
    ring_next = np.arange(1, total + 1, dtype=np.int64)
    ring_next[2::3] -= 3
    dst = org[ring_next]
    keys = org * stride + dst
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    candidates = np.flatnonzero(org < dst)
    twin_keys = dst[candidates] * stride + org[candidates]
    at = np.minimum(np.searchsorted(sorted_keys, twin_keys), total - 1)
    found = sorted_keys[at] == twin_keys
    return candidates[found], order[at[found]]


_NEXT_IN_TRIANGLE: list[int] = []
_PREV_IN_TRIANGLE: list[int] = []


def _triangle_links(count: int) -> tuple[list[int], list[int]]:
    """Fresh ``next``/``previous`` half-edge lists of ``count // 3`` separate triangles.

    Half-edge ``e`` belongs to triangle ``e // 3``; its successor is the next corner of that
    triangle. The lists depend on ``count`` only, so they are sliced from module-level
    templates (grown on demand) instead of being rebuilt element by element for every batch.
    """
    if len(_NEXT_IN_TRIANGLE) < count:
        size = max(count, 2 * len(_NEXT_IN_TRIANGLE), 3 * 256)
        size += -size % 3
        _NEXT_IN_TRIANGLE[:] = [e + 1 if e % 3 != 2 else e - 2 for e in range(size)]
        _PREV_IN_TRIANGLE[:] = [e - 1 if e % 3 != 0 else e + 2 for e in range(size)]
    return _NEXT_IN_TRIANGLE[:count], _PREV_IN_TRIANGLE[:count]


@dataclass(frozen=True, slots=True)
class ConvexPieces:
    """Convex pieces of many rings: ``vertices`` holds every piece's CCW ring indices (local to
    its ring) one piece after another, cut by ``sizes``; ring ``k`` owns the next
    ``per_ring[k]`` pieces."""

    vertices: IntArray
    sizes: IntArray
    per_ring: IntArray


@dataclass(frozen=True, slots=True)
class _HalfEdges:
    """The half-edges of many triangulations in one numbering, ready for diagonal removal.

    Half-edge ``e`` starts at ring-local vertex ``org[e]`` of its ring, at ``(xs[e], ys[e])``;
    ``edge_ends`` are the cumulative half-edge counts of the rings. ``first``/``second`` are the
    interior diagonals as half-edge pairs (:func:`interior_diagonals`) and ``tols`` the
    convexity tolerance of each one's ring.
    """

    org: list[int]
    xs: list[float]
    ys: list[float]
    edge_ends: IntArray
    first: list[int]
    second: list[int]
    tols: list[float]


def _half_edges(rings: list[FloatArray], tris_list: list[IntArray]) -> _HalfEdges:
    """Everything :func:`hertel_mehlhorn` needs that does not depend on earlier removals."""
    first, second = interior_diagonals(tris_list, [len(r) for r in rings])
    edge_counts = np.fromiter((t.size for t in tris_list), dtype=np.int64, count=len(rings))
    edge_ends = np.cumsum(edge_counts)
    points, ring_sizes = join_rows(rings)
    starts = np.cumsum(ring_sizes) - ring_sizes
    span = np.maximum(
        np.maximum.reduceat(points[:, 0], starts) - np.minimum.reduceat(points[:, 0], starts),
        np.maximum.reduceat(points[:, 1], starts) - np.minimum.reduceat(points[:, 1], starts),
    )
    ring_tol = -CONVEX_REL_TOL * span * span
    local = np.concatenate([t.ravel() for t in tris_list])
    corners = np.take(points, local + np.repeat(starts, edge_counts), axis=0)
    diagonal_ring = np.searchsorted(edge_ends, first, side="right")
    return _HalfEdges(
        org=local.tolist(),
        xs=corners[:, 0].tolist(),
        ys=corners[:, 1].tolist(),
        edge_ends=edge_ends,
        first=first.tolist(),
        second=second.tolist(),
        tols=ring_tol[diagonal_ring].tolist(),
    )


def _remove_diagonals(edges: _HalfEdges) -> tuple[list[int], list[bool]]:
    """Remove every diagonal whose removal keeps both end points convex, in half-edge order.

    Returns the ``next`` links of the half-edges after the removals and which half-edges are
    still alive (the removed diagonals' two halves are not).
    """
    xs, ys = edges.xs, edges.ys
    count = len(xs)
    nxt, prv = _triangle_links(count)
    alive = [True] * count
    for e, f, tol in zip(edges.first, edges.second, edges.tols, strict=True):
        # a = org[e] joins x = org[prv[e]] and w = org[nxt[nxt[f]]]
        pe = prv[e]
        w = nxt[nxt[f]]
        xa = xs[e]
        ya = ys[e]
        if (xa - xs[pe]) * (ys[w] - ya) - (ya - ys[pe]) * (xs[w] - xa) < tol:
            continue
        # b = org[f] joins u = org[prv[f]] and y = org[nxt[nxt[e]]]
        pf = prv[f]
        ne = nxt[e]
        y = nxt[ne]
        xb = xs[f]
        yb = ys[f]
        if (xb - xs[pf]) * (ys[y] - yb) - (yb - ys[pf]) * (xs[y] - xb) < tol:
            continue
        nf = nxt[f]
        nxt[pe] = nf
        prv[nf] = pe
        nxt[pf] = ne
        prv[ne] = pf
        alive[e] = alive[f] = False
    return nxt, alive


def hertel_mehlhorn(rings: list[FloatArray], tris_list: list[IntArray]) -> ConvexPieces:
    """Exact convex decomposition (Hertel–Mehlhorn) of many CCW rings from their triangulations.

    Per ring: removes every diagonal whose removal keeps both of its end points convex (a left
    turn, or within ``CONVEX_REL_TOL`` of the ring's squared extent of one); the result has at
    most four times the minimum number of pieces. The triangles of all rings are held as
    half-edges in one numbering (``e`` runs from ``org[e]`` to ``org[nxt[e]]``), so removing a
    diagonal is four pointer updates and its test two cross products. Diagonals are visited in
    half-edge order (:func:`interior_diagonals`), pieces listed from their lowest half-edge.
    Everything that does not depend on earlier removals (diagonals and twins, each half-edge's
    corner coordinates, each ring's tolerance) is computed for all rings at once in numpy
    (:func:`_half_edges`); only the removals and the walk around the pieces run in Python, over
    all rings in one loop each.
    """
    if not rings:
        empty = np.zeros(0, dtype=np.int64)
        return ConvexPieces(empty, empty, empty)
    edges = _half_edges(rings, tris_list)
    nxt, alive = _remove_diagonals(edges)
    org = edges.org
    vertices: list[int] = []
    piece_sizes: list[int] = []
    piece_starts: list[int] = []
    # compress reads ``alive`` as it goes, so edges already walked are passed over
    for start in compress(range(len(org)), alive):
        before = len(vertices)
        e = start
        while alive[e]:
            alive[e] = False
            vertices.append(org[e])
            e = nxt[e]
        piece_sizes.append(len(vertices) - before)
        piece_starts.append(start)
    owner = np.searchsorted(edges.edge_ends, np.array(piece_starts, dtype=np.int64), side="right")
    return ConvexPieces(
        np.array(vertices, dtype=np.int64),
        np.array(piece_sizes, dtype=np.int64),
        np.bincount(owner, minlength=len(rings)).astype(np.int64),
    )


_SIDES_TEXT: dict[tuple[int, bool], str] = {}
_CACHE_LIMIT = 100_000


def clear_text_caches() -> None:
    """Empty the side-wall text cache (so every run starts cold and memory stays bounded)."""
    _SIDES_TEXT.clear()


def sides_text(n: int, textured: bool = False) -> str:
    """OBJ ``f`` lines of the side walls of an ``n``-prism (as :func:`extrude`, 1-based).

    Per ring edge ``i -> j``: ``(i, j, j + n)`` and ``(i, j + n, i + n)``; with ``textured``
    every corner also names the texture coordinate of its own index (``f i/i j/j ...``).
    Cached per ``n`` for the run; built from a plain list, which for rings this small beats
    building it in numpy.
    """
    sides = _SIDES_TEXT.get((n, textured))
    if sides is None:
        flat: list[int] = []
        for i in range(1, n + 1):
            j = i % n + 1
            flat += (i, j, j + n, i, j + n, i + n)
        if textured:
            line = "f %d/%d %d/%d %d/%d\n"
            flat = [k for k in flat for _ in range(2)]
        else:
            line = "f %d %d %d\n"
        sides = (line * (2 * n)) % tuple(flat)
        if len(_SIDES_TEXT) < _CACHE_LIMIT:
            _SIDES_TEXT[(n, textured)] = sides
    return sides
