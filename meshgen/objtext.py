"""OBJ and scene.json text of many objects at once, formatted by :func:`meshgen.numtext.render`.

Every function here gives, per object, exactly the text that formatting that one object
line by line with Python's ``%`` gives (``tests/meshgen/reference_text.py`` is that reference;
``tests/meshgen/test_numtext.py`` checks against it); the numbers of all objects are formatted
together and each object's text is a slice of one string.

Objects are given as ragged arrays: the rows of all objects concatenated, cut by ``sizes``.
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import numpy.typing as npt

from meshgen.numtext import Fixed, Part, Rendered, Whole, render

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

VERTEX_DECIMALS = 6
"""OBJ vertex coordinates are written with ``%.6f``."""
UV_DECIMALS = 6
"""OBJ texture coordinates are written with ``%.6f`` (a thousandth of a pixel of a 1024 px
photo)."""


def _offsets(sizes: IntArray) -> list[int]:
    """``[0, s0, s0 + s1, ...]``: where each block of ``sizes`` starts, then the end."""
    return [0, *np.cumsum(sizes).tolist()]


def _blocks(rows: Rendered, bounds: list[int]) -> list[str]:
    """The text of each block of rows between consecutive ``bounds`` (row numbers)."""
    text, offsets = rows.text(bounds)
    return [text[a:b] for a, b in pairwise(offsets)]


def vertex_rows(points: FloatArray, sizes: IntArray, half_m: FloatArray, up: str) -> Rendered:
    """OBJ ``v`` rows of prisms: all bottom rings (``z = -half_m``), then all top rings.

    ``points`` is the ``(P, 2)`` mesh-frame rings of all prisms, cut by ``sizes``; ``half_m``
    their half heights. Rows ``i`` (bottom) and ``P + i`` (top) are the lines ``v x y z`` of
    point ``i`` (``%.6f``; ``up`` as in :mod:`meshgen.mesh`). When every ``-half_m`` has its
    sign bit set, ``"%.6f" % half`` is ``"%.6f" % -half`` without the ``-``, so the top rows
    are the bottom rows with that one character dropped.
    """
    bottom_z = np.repeat(-half_m, sizes)
    if np.signbit(bottom_z).all():
        bottom = _vertex_render(points, bottom_z, up)
        sign = bottom.signs[2 if up == "z" else 1] if bottom.signs else -1
        if sign >= 0:
            chars = np.concatenate((bottom.chars, bottom.chars))
            chars[len(points) :, sign] = 0
            return Rendered(chars, np.concatenate((bottom.lengths, bottom.lengths - 1)))
    z = np.concatenate((bottom_z, np.repeat(half_m, sizes)))
    return _vertex_render(np.concatenate((points, points)), z, up)


def _vertex_render(points: FloatArray, z: FloatArray, up: str) -> Rendered:
    """``v`` rows of ``(n, 2)`` mesh-frame points at heights ``z``, in the ``up`` convention."""
    x = Fixed(points[:, 0], VERTEX_DECIMALS)
    height = Fixed(z, VERTEX_DECIMALS)
    if up == "z":
        parts: list[Part] = ["v ", x, " ", Fixed(points[:, 1], VERTEX_DECIMALS), " ", height]
    else:
        parts = ["v ", x, " ", height, " ", Fixed(-points[:, 1], VERTEX_DECIMALS)]
    return render([*parts, "\n"], len(z))


def vertex_texts(rows: Rendered, sizes: IntArray) -> tuple[list[str], list[str]]:
    """Per prism its bottom and top ``v`` blocks from :func:`vertex_rows`."""
    offsets = _offsets(sizes)
    blocks = _blocks(rows, offsets + [offsets[-1] + o for o in offsets[1:]])
    return blocks[: len(sizes)], blocks[len(sizes) :]


def uv_blocks(uv: FloatArray, sizes: IntArray) -> list[str]:
    """Per ring its ``vt u v`` lines (``%.6f``), from the ``(P, 2)`` uv of all rings."""
    u, v = Fixed(uv[:, 0], UV_DECIMALS), Fixed(uv[:, 1], UV_DECIMALS)
    return _blocks(render(["vt ", u, " ", v, "\n"], len(uv)), _offsets(sizes))


def face_rows(faces: IntArray, textured: bool = False) -> Rendered:
    """``f a b c`` lines of ``(m, 3)`` 1-based faces; ``f a/a b/b c/c`` when ``textured``.

    A textured face names, for each corner, the texture coordinate of the same index as its
    vertex (one ``vt`` line per ``v`` line).
    """
    a, b, c = (Whole(faces[:, k]) for k in range(3))
    if textured:
        parts: list[Part] = ["f ", a, "/", a, " ", b, "/", b, " ", c, "/", c, "\n"]
    else:
        parts = ["f ", a, " ", b, " ", c, "\n"]
    return render(parts, len(faces))


def caps_blocks(
    faces: IntArray, counts: IntArray, sizes: IntArray, textured: bool = False
) -> list[str]:
    """Face lines of both caps of prisms: bottom (reversed), then top (``+ n``), 1-based.

    ``faces`` is the ``(M, 3)`` CCW cap triangles of all prisms (indices local to each ring),
    ``counts`` how many each prism has and ``sizes`` its ring size; ``textured`` as in
    :func:`face_rows`.
    """
    total = len(faces)
    starts = np.cumsum(counts) - counts
    position = np.arange(total) + np.repeat(starts, counts)  # prism k's rows from 2 * starts[k]
    rows = np.empty((2 * total, 3), dtype=np.int64)
    rows[position] = faces[:, ::-1] + 1
    rows[position + np.repeat(counts, counts)] = faces + np.repeat(sizes + 1, counts)[:, None]
    return _blocks(face_rows(rows, textured), [2 * s for s in _offsets(counts)])


def points_json_blocks(points: FloatArray, sizes: IntArray, decimals: int) -> list[str]:
    """``[[a,b],...]`` JSON of each block of ``(N, 2)`` points, numbers as ``%.{decimals}f``."""
    first, second = Fixed(points[:, 0], decimals), Fixed(points[:, 1], decimals)
    text, offsets = render(["[", first, ",", second, "],"], len(points)).text(_offsets(sizes))
    return ["[" + text[a : b - 1] + "]" for a, b in pairwise(offsets)]


def pieces_blocks(
    vertices: Rendered,
    ring_starts: IntArray,
    piece_vertices: IntArray,
    piece_sizes: IntArray,
    pieces_per_object: IntArray,
) -> list[str]:
    """OBJ text of the convex pieces of many prisms, one ``o`` block per piece, each a prism.

    ``vertices`` is :func:`vertex_rows` of all prisms (``P`` bottom rows, then ``P`` top rows);
    ``ring_starts`` the first row of each object's ring among them. The pieces of all objects
    are concatenated: ``piece_vertices`` holds their ring indices (local to their ring), cut by
    ``piece_sizes``, and object ``k`` owns the next ``pieces_per_object[k]`` pieces. Per piece:
    ``o piece_j``, its bottom rows, its top rows, then its ``4k - 4`` faces (bottom fan, top
    fan, sides), numbered after the vertices of the object's earlier pieces.
    """
    half = len(vertices.chars) // 2
    total = len(piece_vertices)
    piece_starts = np.cumsum(piece_sizes) - piece_sizes
    owner = np.repeat(np.arange(len(pieces_per_object)), pieces_per_object)
    # piece j's k bottom rows, then its k top rows, from row 2 * piece_starts[j]
    ring_rows = piece_vertices + np.repeat(ring_starts[owner], piece_sizes)
    at_bottom = np.arange(total) + np.repeat(piece_starts, piece_sizes)
    order = np.empty(2 * total, dtype=np.int64)
    order[at_bottom] = ring_rows
    order[at_bottom + np.repeat(piece_sizes, piece_sizes)] = ring_rows + half
    vtext, vbounds = vertices.take(order).text([2 * s for s in _offsets(piece_sizes)])
    object_first = np.cumsum(pieces_per_object) - pieces_per_object
    before = piece_starts - piece_starts[object_first][owner]
    face_counts = 4 * piece_sizes - 4
    faces = piece_faces(piece_sizes) + np.repeat(2 * before + 1, face_counts)[:, None]
    ftext, fbounds = face_rows(faces).text(_offsets(face_counts))
    local = (np.arange(len(piece_sizes)) - object_first[owner]).tolist()
    parts = [
        f"o piece_{j}\n{vtext[vbounds[p] : vbounds[p + 1]]}{ftext[fbounds[p] : fbounds[p + 1]]}"
        for p, j in enumerate(local)
    ]
    return ["".join(parts[a:b]) for a, b in pairwise(_offsets(pieces_per_object))]


def piece_faces(sizes: IntArray) -> IntArray:
    """``(sum(4k - 4), 3)`` local faces of prisms over convex ``k``-gons, one after another.

    Per piece: the bottom fan ``(0, i + 1, i)`` and the top fan ``(k, i + k, i + k + 1)`` for
    ``i = 1 .. k - 2``, then per ring edge ``l -> l'`` the sides ``(l, l', l' + k)`` and
    ``(l, l' + k, l + k)``; 0-based in the piece.
    """
    fans = sizes - 2
    fan_starts = np.cumsum(fans) - fans
    fan_i = np.arange(int(fans.sum())) - np.repeat(fan_starts, fans) + 1
    fan_k = np.repeat(sizes, fans)
    edge_starts = np.cumsum(sizes) - sizes
    edge_l = np.arange(int(sizes.sum())) - np.repeat(edge_starts, sizes)
    edge_k = np.repeat(sizes, sizes)
    edge_n = np.where(edge_l + 1 == edge_k, 0, edge_l + 1)
    sides = np.empty((2 * len(edge_l), 3), dtype=np.int64)
    sides[0::2] = np.stack((edge_l, edge_n, edge_n + edge_k), axis=1)
    sides[1::2] = np.stack((edge_l, edge_n + edge_k, edge_l + edge_k), axis=1)
    per_piece = 4 * sizes - 4
    starts = np.cumsum(per_piece) - per_piece
    out = np.empty((int(per_piece.sum()), 3), dtype=np.int64)
    fan_rows = np.arange(len(fan_i)) + np.repeat(starts - fan_starts, fans)
    out[fan_rows] = np.stack((np.zeros_like(fan_i), fan_i + 1, fan_i), axis=1)
    out[fan_rows + np.repeat(fans, fans)] = np.stack(
        (fan_k, fan_i + fan_k, fan_i + fan_k + 1), axis=1
    )
    side_rows = np.arange(len(sides)) + np.repeat(starts + 2 * fans - 2 * edge_starts, 2 * sizes)
    out[side_rows] = sides
    return out
