"""Reference one-object OBJ and scene.json texts: the oracle for the batched production code.

meshgen formats the text of a whole batch of objects at once (:mod:`meshgen.objtext`,
:mod:`meshgen.prisms`, :func:`meshgen.records.object_json_text`). These functions write the
same text for one object in the plainest way: Python ``%``/f-string formatting, one line at a
time, no caches, no numpy tricks. ``tests/meshgen/test_numtext.py`` and
``tests/meshgen/test_records.py`` check the batched forms against them;
``tests/meshgen/test_reference_text.py`` and ``tests/meshgen/test_batching.py`` check these
against independent expectations (hand-written text, :func:`meshgen.mesh.extrude`, closed
convex pieces, ``json.dumps``).

Import as ``from tests.meshgen.reference_text import ...`` (pytest's importlib mode names
this folder's modules ``tests.meshgen.*``).
"""

from __future__ import annotations

import json

import numpy as np
import numpy.typing as npt
import trimesh

from meshgen.export import SCENE_COLUMNS
from meshgen.mesh import ConvexPieces
from meshgen.objfile import parse_obj
from meshgen.records import ObjectRecord

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def _faces_text(faces_0based: list[tuple[int, int, int]], textured: bool = False) -> str:
    if textured:
        return "".join(
            f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}\n" for a, b, c in faces_0based
        )
    return "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces_0based)


def uv_block(uv: FloatArray) -> str:
    """OBJ ``vt`` lines of ``(n, 2)`` texture coordinates, every number with 6 decimals."""
    return "".join(f"vt {u:.6f} {v:.6f}\n" for u, v in uv.tolist())


def vertex_blocks(ring: FloatArray, half_m: float, up: str) -> tuple[str, str]:
    """OBJ ``v`` lines of the bottom (``z = -half_m``) and the top ring of a prism.

    ``ring`` is the ``(n, 2)`` mesh-frame footprint; ``up="z"`` writes ``(x, y, z)``,
    ``up="y"`` writes ``(x, z, -y)``. Every number with 6 decimals.
    """

    def block(z: float) -> str:
        lines = []
        for x, y in ring.tolist():
            a, b, c = (x, y, z) if up == "z" else (x, z, -y)
            lines.append(f"v {a:.6f} {b:.6f} {c:.6f}\n")
        return "".join(lines)

    return block(-half_m), block(half_m)


def caps_faces(tris: IntArray, n: int) -> list[tuple[int, int, int]]:
    """0-based cap faces of a prism over ``n`` points: bottom (reversed, facing down), top."""
    bottom = [(c, b, a) for a, b, c in tris.tolist()]
    top = [(a + n, b + n, c + n) for a, b, c in tris.tolist()]
    return bottom + top


def caps_texts(tris_list: list[IntArray], sizes: list[int], textured: bool = False) -> list[str]:
    """Per prism the ``f`` lines of both caps (what :func:`prism_faces_text` writes first)."""
    return [_faces_text(caps_faces(t, n), textured) for t, n in zip(tris_list, sizes, strict=True)]


def prism_faces_text(tris: IntArray, n: int, textured: bool = False) -> str:
    """OBJ ``f`` lines of a prism over ``n`` points with CCW cap triangles ``tris``, 1-based.

    Both caps (:func:`caps_faces`), then per ring edge ``i -> j`` the side triangles
    ``(i, j, j + n)`` and ``(i, j + n, i + n)``: the faces of :func:`meshgen.mesh.extrude`.
    ``textured`` writes every corner as ``i/i`` (the texture coordinate of the same index).
    """
    sides = []
    for i in range(n):
        j = (i + 1) % n
        sides += [(i, j, j + n), (i, j + n, i + n)]
    return _faces_text(caps_faces(tris, n) + sides, textured)


def pieces_text(bottom: str, top: str, pieces: list[list[int]]) -> str:
    """OBJ text with one ``o piece_j`` block per convex piece, each a closed prism.

    ``bottom`` and ``top`` are the ring's vertex blocks (:func:`vertex_blocks`); ``pieces``
    are CCW lists of ring indices (:func:`hertel_mehlhorn_one`). A piece of ``k``
    vertices writes its ``k`` bottom and ``k`` top vertex lines and ``4k - 4`` triangles:
    the bottom fan ``(0, i + 1, i)``, the top fan ``(k, i + k, i + k + 1)`` for
    ``i = 1 .. k - 2``, then per edge ``l -> l'`` the sides ``(l, l', l' + k)`` and
    ``(l, l' + k, l + k)``; indices count on from the earlier pieces' vertices.
    """
    bottom_lines = bottom.splitlines(keepends=True)
    top_lines = top.splitlines(keepends=True)
    out = []
    offset = 0
    for number, piece in enumerate(pieces):
        k = len(piece)
        out.append(f"o piece_{number}\n")
        out += [bottom_lines[i] for i in piece]
        out += [top_lines[i] for i in piece]
        faces = [(0, i + 1, i) for i in range(1, k - 1)]
        faces += [(k, i + k, i + k + 1) for i in range(1, k - 1)]
        for m in range(k):
            m_next = (m + 1) % k
            faces += [(m, m_next, m_next + k), (m, m_next + k, m + k)]
        out.append(_faces_text([(a + offset, b + offset, c + offset) for a, b, c in faces]))
        offset += 2 * k
    return "".join(out)


def points_json(points: FloatArray, fmt: str) -> str:
    """``[[a,b],...]`` JSON text of ``(n, 2)`` points, each number with the %-format ``fmt``."""
    return "[" + ",".join(f"[{fmt % a},{fmt % b}]" for a, b in points.tolist()) + "]"


def object_json(
    record: ObjectRecord,
    *,
    source_where: str,
    density_kg_m3: float,
    seed: int,
    rng_key: tuple[int, int, int],
    footprint_m: FloatArray,
    polygon_px: FloatArray,
) -> str:
    """The scene.json entry of one object, built with ``json.dumps``.

    The record's scene.csv fields (``repairs`` as a list) plus ``source_where``,
    ``density_kg_m3``, ``seed`` and ``rng_key``, as sorted compact JSON, then ``footprint_m``
    (``%.9f``) and ``polygon_px`` (``%.3f``).
    """
    fields: dict[str, object] = {name: getattr(record, name) for name in SCENE_COLUMNS}
    fields["repairs"] = list(record.repairs)
    fields["source_where"] = source_where
    fields["density_kg_m3"] = density_kg_m3
    fields["seed"] = seed
    fields["rng_key"] = list(rng_key)
    head = json.dumps(fields, sort_keys=True, separators=(",", ":"))
    return (
        f'{head[:-1]},"footprint_m":{points_json(footprint_m, "%.9f")}'
        f',"polygon_px":{points_json(polygon_px, "%.3f")}}}'
    )


def obj_meshes(text: str) -> list[trimesh.Trimesh]:
    """One mesh per ``o`` block of OBJ text (a single mesh when there is no ``o`` line).

    Read with :func:`meshgen.objfile.parse_obj`; each block's mesh holds the vertices its faces
    use.
    """
    mesh = parse_obj(text)
    out = []
    for group in mesh.groups:
        faces = mesh.faces[group.faces]
        if not len(faces):
            continue
        used = np.unique(faces)
        remap = np.full(len(mesh.vertices), -1)
        remap[used] = np.arange(len(used))
        out.append(trimesh.Trimesh(mesh.vertices[used], remap[faces], process=False))
    return out


CONVEX_REL_TOL = 1e-9
"""The convexity tolerance of :mod:`meshgen.mesh` (relative to the ring's squared extent)."""


def interior_diagonals_one(tris: IntArray) -> list[tuple[int, int]]:
    """``(e, f)`` interior half-edge pairs of one triangulation, from a dictionary of edges.

    Half-edge ``e`` of ``tris.ravel()`` runs from its corner to the next corner of its
    triangle; pairs are every ``e`` whose start index is below its end index with its twin
    ``f`` (the reversed edge), ``e`` increasing.
    """
    org = tris.ravel().tolist()
    nxt = [e + 1 if e % 3 != 2 else e - 2 for e in range(len(org))]
    edge = {(org[e], org[nxt[e]]): e for e in range(len(org))}
    return [
        (e, edge[org[nxt[e]], org[e]])
        for e in range(len(org))
        if org[e] < org[nxt[e]] and (org[nxt[e]], org[e]) in edge
    ]


def hertel_mehlhorn_one(ring: FloatArray, tris: IntArray) -> list[list[int]]:
    """Hertel–Mehlhorn convex pieces of one CCW ring, the plainest way.

    Visits the interior diagonals in half-edge order (:func:`interior_diagonals_one`) and
    removes each one whose removal leaves both end points turning left (cross product at least
    ``-CONVEX_REL_TOL * extent**2``, ``extent`` the larger side of the ring's bounding box);
    then lists the pieces from their lowest half-edge, as CCW lists of ring indices.
    """
    xs: list[float] = ring[:, 0].tolist()
    ys: list[float] = ring[:, 1].tolist()
    scale = max(max(xs) - min(xs), max(ys) - min(ys))
    tol = -CONVEX_REL_TOL * scale * scale
    org: list[int] = tris.ravel().tolist()
    count = len(org)
    nxt = [e + 1 if e % 3 != 2 else e - 2 for e in range(count)]
    prv = [e - 1 if e % 3 != 0 else e + 2 for e in range(count)]
    alive = [True] * count

    def turns_left(p: int, q: int, r: int) -> bool:
        cross = (xs[q] - xs[p]) * (ys[r] - ys[q]) - (ys[q] - ys[p]) * (xs[r] - xs[q])
        return cross >= tol

    for e, f in interior_diagonals_one(tris):
        a, b = org[e], org[f]
        pe, ne, pf, nf = prv[e], nxt[e], prv[f], nxt[f]
        if not turns_left(org[pe], a, org[nxt[nf]]):
            continue
        if not turns_left(org[pf], b, org[nxt[ne]]):
            continue
        nxt[pe], prv[nf] = nf, pe
        nxt[pf], prv[ne] = ne, pf
        alive[e] = alive[f] = False
    pieces: list[list[int]] = []
    for start in range(count):
        piece: list[int] = []
        e = start
        while alive[e]:
            alive[e] = False
            piece.append(org[e])
            e = nxt[e]
        if piece:
            pieces.append(piece)
    return pieces


def nested_pieces(found: ConvexPieces) -> list[list[list[int]]]:
    """The ragged convex pieces of :func:`meshgen.mesh.hertel_mehlhorn` as per-ring lists."""
    flat: list[int] = found.vertices.tolist()
    pieces: list[list[int]] = []
    at = 0
    for size in found.sizes.tolist():
        pieces.append(flat[at : at + size])
        at += size
    out: list[list[list[int]]] = []
    at = 0
    for count in found.per_ring.tolist():
        out.append(pieces[at : at + count])
        at += count
    return out
