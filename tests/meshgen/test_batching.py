"""Batched forms give exactly what their one-at-a-time forms give."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from meshgen import footprint
from meshgen.config import MeshgenConfig
from meshgen.footprint import (
    Footprint,
    _min_area_rectangles,
    _ragged_polygons,
    build_footprints,
    min_area_rectangle,
)
from meshgen.loaders import _checked_points, discover, load_source, points_one_by_one
from meshgen.mesh import extrude, hertel_mehlhorn, interior_diagonals, sides_text, triangulate
from meshgen.ragged import split_rows
from tests.meshgen.reference_text import (
    caps_texts,
    hertel_mehlhorn_one,
    interior_diagonals_one,
    nested_pieces,
    prism_faces_text,
)


def _star(points: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    angles = np.linspace(0.0, 2.0 * np.pi, points, endpoint=False)
    radii = rng.uniform(0.3, 1.0, points)
    return np.stack((radii * np.cos(angles), radii * np.sin(angles)), axis=1)


def test_interior_diagonals_match_one_ring_at_a_time() -> None:
    rings = [_star(n, seed) for seed, n in enumerate((3, 4, 7, 12, 30, 5, 64))]
    tris = [triangulate(r) for r in rings]
    first, second = interior_diagonals(tris, [len(r) for r in rings])
    pairs = list(zip(first.tolist(), second.tolist(), strict=True))
    want = []
    offset = 0  # half-edges of the earlier rings
    for ring, t in zip(rings, tris, strict=True):
        one = interior_diagonals_one(t)
        assert len(one) == len(ring) - 3  # a triangulated n-gon has n - 3 diagonals
        want += [(e + offset, f + offset) for e, f in one]
        offset += t.size
    assert pairs == want
    empty = interior_diagonals([], [])
    assert len(empty[0]) == len(empty[1]) == 0


def test_prism_face_texts_match_extrude() -> None:
    rings = [_star(n, seed) for seed, n in enumerate((3, 4, 7, 12, 30, 5, 64))]
    tris = [triangulate(r) for r in rings]
    caps = caps_texts(tris, [len(r) for r in rings])
    textured_caps = caps_texts(tris, [len(r) for r in rings], textured=True)
    assert len(caps) == len(rings)
    for ring, t, cap, textured_cap in zip(rings, tris, caps, textured_caps, strict=True):
        _, faces = extrude(ring, t, 1.0)
        want = "".join(f"f {a} {b} {c}\n" for a, b, c in (faces + 1).tolist())
        assert cap + sides_text(len(ring)) == want
        assert prism_faces_text(t, len(ring)) == want
        # textured: every corner also names the texture coordinate of its own index
        textured = "".join(f"f {a}/{a} {b}/{b} {c}/{c}\n" for a, b, c in (faces + 1).tolist())
        assert textured_cap + sides_text(len(ring), textured=True) == textured
        assert prism_faces_text(t, len(ring), textured=True) == textured
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


def _staircase(steps: int, seed: int) -> np.ndarray:
    """A CCW orthogonal staircase on the integer grid: reflex corners and collinear runs."""
    rng = np.random.default_rng(seed)
    widths = rng.integers(1, 4, steps)
    heights = rng.integers(1, 4, steps)
    x = np.concatenate(([0], np.cumsum(widths)))
    y = np.concatenate(([0], np.cumsum(heights)))
    points = [(0, 0), (int(x[-1]), 0)]
    for k in range(steps, 0, -1):
        points += [(int(x[k]), int(y[k])), (int(x[k - 1]), int(y[k]))]
    points.append((0, int(y[1])))  # straight on to the start: a collinear vertex
    return np.array(points, dtype=np.float64)


def _dented(points: int, scale: float, dent: float) -> np.ndarray:
    """A regular polygon with every edge's midpoint pushed in by ``dent`` of the radius: each
    midpoint turns right by a hair, within the convexity tolerance when ``dent`` is tiny."""
    angles = np.linspace(0.0, 2.0 * np.pi, points, endpoint=False)
    corners = np.stack((np.cos(angles), np.sin(angles)), axis=1)
    middles = 0.5 * (corners + np.roll(corners, -1, axis=0)) * (1.0 - dent)
    return scale * np.stack((corners, middles), axis=1).reshape(-1, 2)


def test_hertel_mehlhorn_matches_one_ring_at_a_time() -> None:
    # stars, staircases and barely dented polygons of very different sizes: each ring needs its
    # own tolerance, and the dents are reflex or not depending on it
    rings = [_star(n, seed) * 10.0 ** (seed % 7 - 3) for seed, n in enumerate(range(4, 80, 3))]
    rings += [_staircase(steps, seed) * 0.01 * (seed + 1) for seed, steps in enumerate((2, 3, 9))]
    rings += [_dented(n, 10.0**k, d) for n in (5, 8) for k in (-3, 2) for d in (1e-12, 1e-6)]
    tris = [triangulate(r) for r in rings]
    found = hertel_mehlhorn(rings, tris)
    want = [hertel_mehlhorn_one(r, t) for r, t in zip(rings, tris, strict=True)]
    assert nested_pieces(found) == want
    assert found.vertices.dtype == found.sizes.dtype == found.per_ring.dtype == np.int64
    assert any(len(pieces) > 1 for pieces in want)
    empty = hertel_mehlhorn([], [])
    assert len(empty.vertices) == len(empty.sizes) == len(empty.per_ring) == 0


def test_hertel_mehlhorn_matches_one_ring_at_a_time_on_the_real_sample(real_sample: Path) -> None:
    config = MeshgenConfig()
    listing = discover(real_sample, config.fmt, config.image_size_px)
    anns = [load_source(source, real_sample)[0] for source in listing.sources[:20]]
    rings = [
        fp.ring_m - np.array(fp.centroid_m)
        for fp in build_footprints(
            [poly.points_px * 1e-3 for ann in anns if ann for poly in ann.polygons],
            simplify_m=1e-3,
            min_area_m2=0.0,
        )
        if isinstance(fp, Footprint) and not fp.convex
    ]
    tris = [triangulate(r) for r in rings]
    assert len(rings) > 20
    want = [hertel_mehlhorn_one(r, t) for r, t in zip(rings, tris, strict=True)]
    assert nested_pieces(hertel_mehlhorn(rings, tris)) == want
