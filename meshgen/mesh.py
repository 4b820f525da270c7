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

import mapbox_earcut
import numpy as np
import numpy.typing as npt

from meshgen.annotations import FloatArray
from meshgen.ragged import split_rows

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


def diagonals_many(tris_list: list[IntArray], sizes: list[int]) -> list[tuple[IntArray, IntArray]]:
    """Interior half-edge pairs of many triangulations (of rings of ``sizes[i]`` points) at once.

    Half-edge ``e`` runs from ``tris.ravel()[e]`` to the next corner of its triangle. For each
    triangulation: ``(e, f)``, every half-edge ``e`` whose start index is below its end index
    and that has a twin ``f`` (the same edge, reversed, in the neighbouring triangle), ``e``
    increasing. The half-edges of all triangulations are shifted to one numbering (vertex
    indices by the preceding rings' sizes, half-edges by the preceding half-edge counts), so
    edge keys never collide between rings and one stable sort and one search serve them all.
    Gives exactly the per-ring results (same pairs, same order, indices local to each ring).
    """
    if not tris_list:
        return []
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
    first, second = candidates[found], order[at[found]]
    edge_ends = np.cumsum(counts)
    ring_ends = np.searchsorted(first, edge_ends)
    found_per_ring = np.diff(ring_ends, prepend=0)
    local = np.repeat(edge_ends - counts, found_per_ring)
    first, second = first - local, second - local
    per_ring = ring_ends.tolist()
    starts = [0, *per_ring[:-1]]
    return [(first[a:b], second[a:b]) for a, b in zip(starts, per_ring, strict=True)]


_NEXT_IN_TRIANGLE: list[int] = []
_PREV_IN_TRIANGLE: list[int] = []


def _triangle_links(count: int) -> tuple[list[int], list[int]]:
    """Fresh ``next``/``previous`` half-edge lists of ``count // 3`` separate triangles.

    Half-edge ``e`` belongs to triangle ``e // 3``; its successor is the next corner of that
    triangle. The lists depend on ``count`` only, so they are sliced from module-level
    templates (grown on demand) instead of being rebuilt element by element for every ring.
    """
    if len(_NEXT_IN_TRIANGLE) < count:
        size = max(count, 2 * len(_NEXT_IN_TRIANGLE), 3 * 256)
        size += -size % 3
        _NEXT_IN_TRIANGLE[:] = [e + 1 if e % 3 != 2 else e - 2 for e in range(size)]
        _PREV_IN_TRIANGLE[:] = [e - 1 if e % 3 != 0 else e + 2 for e in range(size)]
    return _NEXT_IN_TRIANGLE[:count], _PREV_IN_TRIANGLE[:count]


def hertel_mehlhorn(
    ring: FloatArray, tris: IntArray, diagonals: tuple[IntArray, IntArray] | None = None
) -> list[list[int]]:
    """Exact convex decomposition of a CCW ring from its triangulation (Hertel–Mehlhorn).

    Removes every diagonal whose removal keeps both of its end points convex; the result has at
    most four times the minimum number of pieces. Returns pieces as CCW lists of ring indices.
    The triangles are held as half-edges (``e`` runs from ``org[e]`` to ``org[nxt[e]]``), so
    removing a diagonal is four pointer updates and its test two cross products. Diagonals are
    visited in half-edge order; finding them and their twins is vectorised
    (:func:`diagonals_many`; pass ``diagonals`` when it found them for many
    rings at once), only the removals, which depend on earlier ones, run in Python.
    """
    xs: list[float] = ring[:, 0].tolist()
    ys: list[float] = ring[:, 1].tolist()
    scale = max(max(xs) - min(xs), max(ys) - min(ys))
    tol = -CONVEX_REL_TOL * scale * scale
    org: list[int] = tris.ravel().tolist()
    count = len(org)
    nxt, prv = _triangle_links(count)
    alive = [True] * count
    if diagonals is None:
        diagonals = diagonals_many([tris], [len(ring)])[0]
    first, second = diagonals
    for e, f in zip(first.tolist(), second.tolist(), strict=True):
        a = org[e]
        b = org[f]
        pe, ne, pf, nf = prv[e], nxt[e], prv[f], nxt[f]
        x, w = org[pe], org[nxt[nf]]
        u, y = org[pf], org[nxt[ne]]
        if (xs[a] - xs[x]) * (ys[w] - ys[a]) - (ys[a] - ys[x]) * (xs[w] - xs[a]) < tol:
            continue
        if (xs[b] - xs[u]) * (ys[y] - ys[b]) - (ys[b] - ys[u]) * (xs[y] - xs[b]) < tol:
            continue
        nxt[pe], prv[nf] = nf, pe
        nxt[pf], prv[ne] = ne, pf
        alive[e] = alive[f] = False
    pieces: list[list[int]] = []
    for start in range(count):
        if not alive[start]:
            continue
        piece: list[int] = []
        e = start
        while alive[e]:
            alive[e] = False
            piece.append(org[e])
            e = nxt[e]
        pieces.append(piece)
    return pieces


_SIDES_TEXT: dict[int, str] = {}
_CACHE_LIMIT = 100_000


def clear_text_caches() -> None:
    """Empty the side-wall text cache (so every run starts cold and memory stays bounded)."""
    _SIDES_TEXT.clear()


def sides_text(n: int) -> str:
    """OBJ ``f`` lines of the side walls of an ``n``-prism (as :func:`extrude`, 1-based).

    Per ring edge ``i -> j``: ``(i, j, j + n)`` and ``(i, j + n, i + n)``. Cached per ``n`` for
    the run; built from a plain list, which for rings this small beats building it in numpy.
    """
    sides = _SIDES_TEXT.get(n)
    if sides is None:
        flat: list[int] = []
        for i in range(1, n + 1):
            j = i % n + 1
            flat += (i, j, j + n, i, j + n, i + n)
        sides = ("f %d %d %d\n" * (2 * n)) % tuple(flat)
        if len(_SIDES_TEXT) < _CACHE_LIMIT:
            _SIDES_TEXT[n] = sides
    return sides
