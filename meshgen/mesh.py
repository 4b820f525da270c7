"""Prism meshes from footprints: earcut triangulation, extrusion, convex decomposition, OBJ text.

The triangulation engine is pinned: ``mapbox_earcut.triangulate_float64`` (ear clipping), called
once per footprint; its triangles form both caps of the prism and seed the Hertel–Mehlhorn
convex decomposition. A prism over an open counter-clockwise ring of ``n`` points has ``2n``
vertices and ``4n - 4`` triangles, every edge shared by exactly two of them (watertight,
consistently wound, normals outward).

Mesh local frame: origin at the centre of mass (footprint centroid, half the height above the
belt), axes parallel to the belt frame. ``up="z"`` writes ``(x, y, z)`` (ROS REP 103),
``up="y"`` writes ``(x, z, -y)``.

OBJ text is built from strings, not per line: the ring's vertex lines are formatted once with
one ``%``-format and shared by the mesh and the convex pieces (a piece's vertices are ring
vertices); face index text for the side quads of an ``n``-prism and for a convex ``k``-piece
at a given vertex offset depends only on those integers and is cached for the run
(:func:`clear_text_caches` empties the caches; the pipeline calls it at the start of each run);
the caps of a batch of prisms are numbered in one array operation (:func:`caps_texts`).
"""

from __future__ import annotations

from operator import itemgetter

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


def to_up_axis(verts: FloatArray, up: str) -> FloatArray:
    """Return ``(n, 3)`` vertices in the output axis convention (``"z"`` or ``"y"`` up)."""
    if up == "z":
        return verts
    out = np.empty_like(verts)
    out[:, 0] = verts[:, 0]
    out[:, 1] = verts[:, 2]
    out[:, 2] = -verts[:, 1]
    return out


_SIDES_TEXT: dict[int, str] = {}
_PIECE_TEXT: dict[tuple[int, int], str] = {}
_PIECE_PATTERN: dict[int, IntArray] = {}
_CACHE_LIMIT = 100_000


def clear_text_caches() -> None:
    """Empty the face-text caches (so every run starts cold and memory stays bounded)."""
    _SIDES_TEXT.clear()
    _PIECE_TEXT.clear()
    _PIECE_PATTERN.clear()


def _faces_text(faces_1based: IntArray) -> str:
    flat = faces_1based.ravel().tolist()
    return ("f %d %d %d\n" * (len(flat) // 3)) % tuple(flat)


def vertex_blocks(ring: FloatArray, half_m: float, up: str) -> tuple[str, str]:
    """OBJ ``v`` lines of the bottom (``z = -half_m``) and top ring of a prism, in order.

    ``ring`` is ``(n, 2) float`` in the mesh frame; ``up`` as in :func:`to_up_axis`. Each block
    is ``n`` lines ``v x y z`` with 6 decimals.
    """
    n = len(ring)
    if up == "z":
        text = ("v %.6f %.6f|\n" * n) % tuple(ring.ravel().tolist())
        return text.replace("|", f" {-half_m:.6f}"), text.replace("|", f" {half_m:.6f}")
    flipped = np.empty_like(ring)
    flipped[:, 0] = ring[:, 0]
    flipped[:, 1] = -ring[:, 1]
    text = ("v %.6f|%.6f\n" * n) % tuple(flipped.ravel().tolist())
    return text.replace("|", f" {-half_m:.6f} "), text.replace("|", f" {half_m:.6f} ")


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


def prism_faces_text(tris: IntArray, n: int) -> str:
    """OBJ ``f`` lines of the prism :func:`extrude` builds (same faces, same order, 1-based)."""
    caps = np.empty((2 * len(tris), 3), dtype=np.int64)
    caps[: len(tris)] = tris[:, ::-1]
    caps[len(tris) :] = tris + n
    caps += 1
    return _faces_text(caps) + sides_text(n)


def caps_texts(tris_list: list[IntArray], sizes: list[int]) -> list[str]:
    """OBJ ``f`` lines of both caps of many prisms: what :func:`prism_faces_text` writes first.

    Per prism over ``sizes[k]`` points: the bottom cap (``tris`` reversed, facing down), then
    the top cap (``tris + n``), 1-based. The index arithmetic is done once for all prisms and
    converted to Python ints in one go; each prism's text is then one ``%`` of its slices.
    """
    if not tris_list:
        return []
    counts = [len(t) for t in tris_list]
    faces = np.concatenate(tris_list)
    bottom: list[int] = (faces[:, ::-1] + 1).ravel().tolist()
    shift = np.repeat(np.array(sizes, dtype=np.int64) + 1, counts)
    top: list[int] = (faces + shift[:, None]).ravel().tolist()
    texts: list[str] = []
    start = 0
    for m in counts:
        stop = start + 3 * m
        texts.append(("f %d %d %d\n" * (2 * m)) % (*bottom[start:stop], *top[start:stop]))
        start = stop
    return texts


def _piece_pattern(k: int) -> IntArray:
    """``(4k - 4, 3) int`` local faces of a prism over a convex ``k``-gon (fans, then sides)."""
    pattern = _PIECE_PATTERN.get(k)
    if pattern is None:
        i = np.arange(1, k - 1, dtype=np.int64)
        fan_bottom = np.stack((np.zeros_like(i), i + 1, i), axis=1)
        fan_top = np.stack((np.full_like(i, k), i + k, i + k + 1), axis=1)
        local = np.arange(k, dtype=np.int64)
        nxt = np.concatenate((local[1:], local[:1]))
        sides = np.empty((2 * k, 3), dtype=np.int64)
        sides[0::2] = np.stack((local, nxt, nxt + k), axis=1)
        sides[1::2] = np.stack((local, nxt + k, local + k), axis=1)
        pattern = np.concatenate((fan_bottom, fan_top, sides))
        _PIECE_PATTERN[k] = pattern
    return pattern


def pieces_text(bottom: str, top: str, pieces: list[list[int]]) -> str:
    """OBJ text with one ``o piece_k`` block per convex piece, each a closed prism.

    ``bottom`` and ``top`` are the ring's vertex blocks from :func:`vertex_blocks`; ``pieces``
    are CCW lists of ring indices (:func:`hertel_mehlhorn`). A piece of ``k`` vertices gets
    ``2k`` vertices (bottom ring, top ring) and ``4k - 4`` triangles (bottom fan, top fan,
    sides), indices global and 1-based.
    """
    rows_b = bottom.splitlines(keepends=True)
    rows_t = top.splitlines(keepends=True)
    parts: list[str] = []
    offset = 0
    for number, piece in enumerate(pieces):
        size = len(piece)
        pick = itemgetter(*piece)
        parts.append(f"o piece_{number}\n")
        parts.append("".join(pick(rows_b)))
        parts.append("".join(pick(rows_t)))
        key = (size, offset)
        faces = _PIECE_TEXT.get(key)
        if faces is None:
            faces = _faces_text(_piece_pattern(size) + (offset + 1))
            if len(_PIECE_TEXT) < _CACHE_LIMIT:
                _PIECE_TEXT[key] = faces
        parts.append(faces)
        offset += 2 * size
    return "".join(parts)
