"""The mesh texts of a batch of footprints: prism OBJ bodies, convex pieces, scene.json points.

:func:`prism_texts` does for many footprints at once what meshing one footprint does:
earcut triangulation (:func:`meshgen.mesh.triangulate_ragged`), the check that it gave
``n - 2`` triangles, the prism's vertex and face lines, and for a concave footprint its
Hertel–Mehlhorn convex pieces. The numbers of all objects are formatted together
(:mod:`meshgen.objtext`); each object's text is a slice.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshgen.annotations import FloatArray
from meshgen.footprint import Footprint
from meshgen.mesh import hertel_mehlhorn, sides_text, triangulate_ragged
from meshgen.objtext import (
    caps_blocks,
    pieces_blocks,
    points_json_blocks,
    uv_blocks,
    vertex_rows,
    vertex_texts,
)
from meshgen.ragged import join_rows, split_rows

FOOTPRINT_DECIMALS = 9
"""scene.json ``footprint_m`` numbers are written with ``%.9f``."""
PIXEL_DECIMALS = 3
"""scene.json ``polygon_px`` numbers are written with ``%.3f``."""


@dataclass(frozen=True, slots=True, kw_only=True)
class PrismTexts:
    """Per footprint (in order): its texts, or ``error`` when it cannot be meshed.

    ``mesh`` is the OBJ body after the material lines (``o`` line, vertices, texture
    coordinates when textured, faces);
    ``pieces`` the convex pieces' OBJ body (empty for a convex footprint) and ``n_pieces``
    their number (1 when convex); ``footprint_json`` and ``polygon_json`` the point arrays of
    the scene.json entry. ``error`` is "" or the detail of a ``degenerate`` skip.
    """

    mesh: list[str]
    pieces: list[str]
    n_pieces: list[int]
    footprint_json: list[str]
    polygon_json: list[str]
    error: list[str]


def prism_texts(
    footprints: list[Footprint],
    heights_m: list[float],
    polygons_px: list[FloatArray],
    object_ids: list[str],
    up: str,
    uv: FloatArray | None = None,
) -> PrismTexts:
    """Mesh texts of prisms of ``heights_m`` over ``footprints`` (see :class:`PrismTexts`).

    The mesh frame is the footprint's ring relative to its centroid, half the height above
    the belt; ``polygons_px`` are the source polygons (for scene.json); ``object_ids`` name
    the ``o`` lines. ``uv`` is None (no texture coordinates) or the ``(P, 2)`` texture
    coordinates of all footprints' ring points, concatenated: each prism then has one ``vt``
    line per ``v`` line (the ring's for the bottom, again for the top, so a side or bottom
    vertex has the coordinate of the outline vertex it is extruded from) and its faces name
    them (``f a/a b/b c/c``). The vertices and the faces are the same either way.
    """
    count = len(footprints)
    if not count:
        return PrismTexts(
            mesh=[], pieces=[], n_pieces=[], footprint_json=[], polygon_json=[], error=[]
        )
    ring_points, sizes = join_rows([fp.ring_m for fp in footprints])
    centroids = np.array([fp.centroid_m for fp in footprints], dtype=np.float64)
    local = ring_points - np.repeat(centroids, sizes, axis=0)
    rings = split_rows(local, sizes)
    faces, counts = triangulate_ragged(rings, local, sizes)
    size_list: list[int] = sizes.tolist()
    count_list: list[int] = counts.tolist()
    error = [
        "" if m == n - 2 else f"earcut gave {m} triangles for {n} points"
        for m, n in zip(count_list, size_list, strict=True)
    ]
    half_m = 0.5 * np.array(heights_m, dtype=np.float64)
    vertices = vertex_rows(local, sizes, half_m, up)
    bottoms, tops = vertex_texts(vertices, sizes)
    textured = uv is not None
    caps = caps_blocks(faces, counts, sizes, textured)
    uvs = uv_blocks(uv, sizes) if uv is not None else [""] * count
    blocks = zip(object_ids, bottoms, tops, uvs, caps, size_list, strict=True)
    mesh = [
        f"o {name}\n{bottom}{top}{vts}{vts}{cap}{sides_text(n, textured)}"
        for name, bottom, top, vts, cap, n in blocks
    ]
    pieces = [""] * count
    n_pieces = [1] * count
    concave = [k for k, fp in enumerate(footprints) if not fp.convex and not error[k]]
    if concave:
        triangles = split_rows(faces, counts)
        found = hertel_mehlhorn([rings[k] for k in concave], [triangles[k] for k in concave])
        ring_starts = np.cumsum(sizes) - sizes
        texts = pieces_blocks(
            vertices, ring_starts[concave], found.vertices, found.sizes, found.per_ring
        )
        for k, text, number in zip(concave, texts, found.per_ring.tolist(), strict=True):
            pieces[k] = text
            n_pieces[k] = number
    pixel_points, pixel_sizes = join_rows(polygons_px)
    return PrismTexts(
        mesh=mesh,
        pieces=pieces,
        n_pieces=n_pieces,
        footprint_json=points_json_blocks(ring_points, sizes, FOOTPRINT_DECIMALS),
        polygon_json=points_json_blocks(pixel_points, pixel_sizes, PIXEL_DECIMALS),
        error=error,
    )
