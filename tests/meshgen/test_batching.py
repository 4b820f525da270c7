"""Batched forms give exactly what their one-at-a-time forms give."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from meshgen import footprint
from meshgen.footprint import _min_area_rectangles, _ragged_polygons, min_area_rectangle
from meshgen.loaders import _checked_points, points_one_by_one
from meshgen.mesh import diagonals_many, extrude, sides_text, triangulate
from meshgen.ragged import split_rows
from tests.meshgen.reference_text import caps_texts, prism_faces_text


def _star(points: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    angles = np.linspace(0.0, 2.0 * np.pi, points, endpoint=False)
    radii = rng.uniform(0.3, 1.0, points)
    return np.stack((radii * np.cos(angles), radii * np.sin(angles)), axis=1)


def test_diagonals_many_matches_one_ring_at_a_time() -> None:
    rings = [_star(n, seed) for seed, n in enumerate((3, 4, 7, 12, 30, 5, 64))]
    tris = [triangulate(r) for r in rings]
    batched = diagonals_many(tris, [len(r) for r in rings])
    assert len(batched) == len(rings)
    for ring, t, (first, second) in zip(rings, tris, batched, strict=True):
        # reference: a dictionary of directed edges, every interior edge once
        org = t.ravel().tolist()
        nxt = [e + 1 if e % 3 != 2 else e - 2 for e in range(len(org))]
        edge = {(org[e], org[nxt[e]]): e for e in range(len(org))}
        want = [
            (e, edge[org[nxt[e]], org[e]])
            for e in range(len(org))
            if org[e] < org[nxt[e]] and (org[nxt[e]], org[e]) in edge
        ]
        assert list(zip(first.tolist(), second.tolist(), strict=True)) == want
        assert len(want) == len(ring) - 3  # a triangulated n-gon has n - 3 diagonals
    assert diagonals_many([], []) == []


def test_prism_face_texts_match_extrude() -> None:
    rings = [_star(n, seed) for seed, n in enumerate((3, 4, 7, 12, 30, 5, 64))]
    tris = [triangulate(r) for r in rings]
    caps = caps_texts(tris, [len(r) for r in rings])
    assert len(caps) == len(rings)
    for ring, t, cap in zip(rings, tris, caps, strict=True):
        _, faces = extrude(ring, t, 1.0)
        want = "".join(f"f {a} {b} {c}\n" for a, b, c in (faces + 1).tolist())
        assert cap + sides_text(len(ring)) == want
        assert prism_faces_text(t, len(ring)) == want
    assert caps_texts([], []) == []


def test_min_area_rectangles_match_one_ring_at_a_time(monkeypatch: pytest.MonkeyPatch) -> None:
    # more rings than one caliper group, hulls of very different sizes
    rings = [
        (0.01 + seed % 7) * _star(n, seed)
        for seed, n in enumerate([3, 4, 5, 8, 13, 21, 34, 55, 80] * 20)
    ]
    polys = _ragged_polygons(rings)
    grouped = _min_area_rectangles(rings, polys)
    assert len(rings) > footprint.CALIPER_GROUP
    monkeypatch.setattr(footprint, "CALIPER_GROUP", len(rings))
    assert _min_area_rectangles(rings, polys) == grouped  # padding never changes a result
    for ring, (yaw, length, width) in zip(rings, grouped, strict=True):
        want_yaw, want_length, want_width = min_area_rectangle(ring)
        assert length * width == pytest.approx(want_length * want_width, rel=1e-9)
        if len(ring) > 3:  # a triangle's rectangles on its three sides all tie in area
            assert (yaw, length, width) == pytest.approx((want_yaw, want_length, want_width))


def test_split_rows_matches_numpy_split() -> None:
    rows = np.arange(40.0).reshape(20, 2)
    sizes = np.array([3, 0, 5, 12], dtype=np.int64)
    got = split_rows(rows, sizes)
    want = np.split(rows, np.cumsum(sizes)[:-1])
    assert len(got) == len(want)
    for a, b in zip(got, want, strict=True):
        np.testing.assert_array_equal(a, b)


GOOD = [[10, 10], [50, 10], [50, 40]]
CASES: list[list[Any]] = [
    [GOOD, [[1.5, 2.25], [30, 2], [30, 9.75], [4, 9]]],
    [GOOD, [], [[1, 2]], [[1, 2], [3, 4]]],
    [GOOD, [[10, 10], [5000, 10], [50, 40]], [[-4.9, 10], [50, 10], [50, 40]]],
    [GOOD, [[10, 10], [float("nan"), 10], [50, 40]], [[10, 10], [float("inf"), 1], [5, 4]]],
    [GOOD, [[1, 2, 3], [4, 5], [6, 7]]],
    [GOOD, [[1, 2], [3, "4"], [5, 6]]],
    [GOOD, [[1, 2], [3, None], [5, 6]]],
    [GOOD, {"x": 1}],
    [GOOD, [[10**20, 2], [3, 4], [5, 6]]],
    [[[-0.0, 5], [3, 5], [3, 9]]],
]


@pytest.mark.parametrize("raws", CASES)
@pytest.mark.parametrize("fast", [True, False])
def test_checked_points_matches_one_list_at_a_time(raws: list[Any], fast: bool) -> None:
    got = _checked_points(raws, fast, 100, 80)
    want = points_one_by_one(raws, fast, 100, 80)
    assert len(got) == len(want)
    for (pts, reason, detail), (want_pts, want_reason, want_detail) in zip(got, want, strict=True):
        assert (reason, detail) == (want_reason, want_detail)
        if want_pts is None:
            assert pts is None
        else:
            assert pts is not None
            assert pts.dtype == np.float64
            np.testing.assert_array_equal(pts, want_pts)
            assert np.signbit(pts).tolist() == np.signbit(want_pts).tolist()
