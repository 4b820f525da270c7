"""The reference one-object texts against hand-written OBJ text and mesh invariants.

``reference_text`` is the oracle for the batched production text (test_numtext.py,
test_records.py); these tests check the oracle itself without using production text code.
"""

from __future__ import annotations

import numpy as np
import pytest

from meshgen.mesh import triangulate
from tests.meshgen.reference_text import (
    hertel_mehlhorn_one,
    obj_meshes,
    pieces_text,
    points_json,
    prism_faces_text,
    vertex_blocks,
)

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
SQUARE_TRIS = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)


def test_vertex_blocks_of_a_square() -> None:
    bottom, top = vertex_blocks(SQUARE, 0.5, "z")
    assert bottom == (
        "v 0.000000 0.000000 -0.500000\n"
        "v 1.000000 0.000000 -0.500000\n"
        "v 1.000000 1.000000 -0.500000\n"
        "v 0.000000 1.000000 -0.500000\n"
    )
    assert top == bottom.replace("-0.500000", "0.500000")
    bottom, top = vertex_blocks(SQUARE, 0.5, "y")  # (x, z, -y)
    assert bottom == (
        "v 0.000000 -0.500000 -0.000000\n"
        "v 1.000000 -0.500000 -0.000000\n"
        "v 1.000000 -0.500000 -1.000000\n"
        "v 0.000000 -0.500000 -1.000000\n"
    )
    assert top == bottom.replace(" -0.500000 ", " 0.500000 ")


def test_prism_faces_text_of_a_square() -> None:
    assert prism_faces_text(SQUARE_TRIS, 4) == (
        "f 3 2 1\nf 4 3 1\n"  # bottom cap, reversed
        "f 5 6 7\nf 5 7 8\n"  # top cap
        "f 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n"  # sides
    )


def test_pieces_text_of_a_square_cut_in_two() -> None:
    bottom, top = vertex_blocks(SQUARE, 0.5, "z")
    b, t = bottom.splitlines(keepends=True), top.splitlines(keepends=True)
    faces = "f 1 3 2\nf 4 5 6\nf 1 2 5\nf 1 5 4\nf 2 3 6\nf 2 6 5\nf 3 1 4\nf 3 4 6\n"
    assert pieces_text(bottom, top, [[0, 1, 2], [0, 2, 3]]) == (
        f"o piece_0\n{b[0]}{b[1]}{b[2]}{t[0]}{t[1]}{t[2]}{faces}"
        f"o piece_1\n{b[0]}{b[2]}{b[3]}{t[0]}{t[2]}{t[3]}"
        "f 7 9 8\nf 10 11 12\nf 7 8 11\nf 7 11 10\nf 8 9 12\nf 8 12 11\nf 9 7 10\nf 9 10 12\n"
    )


def test_points_json_literal() -> None:
    points = np.array([[1.5, -0.0], [2.0, 3.0]])
    assert points_json(points, "%.3f") == "[[1.500,-0.000],[2.000,3.000]]"
    assert points_json(np.zeros((0, 2)), "%.3f") == "[]"


def _star(points: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    angles = np.linspace(0.0, 2.0 * np.pi, points, endpoint=False)
    radii = rng.uniform(0.3, 1.0, points)
    return np.stack((radii * np.cos(angles), radii * np.sin(angles)), axis=1)


@pytest.mark.parametrize(("points", "seed"), [(3, 0), (4, 1), (7, 2), (12, 3), (30, 4)])
@pytest.mark.parametrize("up", ["z", "y"])
def test_prism_and_pieces_are_closed_and_fill_the_prism(points: int, seed: int, up: str) -> None:
    ring = _star(points, seed)
    x, y = ring[:, 0], ring[:, 1]
    volume = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)) * 0.4
    tris = triangulate(ring)
    bottom, top = vertex_blocks(ring, 0.2, up)
    (prism,) = obj_meshes(bottom + top + prism_faces_text(tris, len(ring)))
    assert prism.is_watertight
    assert prism.is_winding_consistent
    assert prism.volume == pytest.approx(volume, rel=1e-4)
    pieces = obj_meshes(pieces_text(bottom, top, hertel_mehlhorn_one(ring, tris)))
    assert all(p.is_watertight and p.is_winding_consistent and p.is_convex for p in pieces)
    assert all(p.volume > 0 for p in pieces)  # outward normals
    assert sum(p.volume for p in pieces) == pytest.approx(volume, rel=1e-4)
