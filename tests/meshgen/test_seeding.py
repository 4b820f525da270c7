"""The batched seeding and triangulation match numpy / the one-at-a-time forms exactly."""

from __future__ import annotations

import zlib

import numpy as np

from meshgen.mesh import hertel_mehlhorn, triangulate, triangulate_many
from meshgen.seeding import first_doubles
from tests.meshgen.reference_text import nested_pieces


def test_first_doubles_match_numpy() -> None:
    rng = np.random.default_rng(5)
    seeds = [0, 1, 7, 2**31, 2**32 - 1, 2**32, 2**40 + 5, 2**64 + 3, 2**100]
    keys = [
        [seed, zlib.crc32(f"img{k}".encode()), int(rng.integers(0, 1000))]
        for seed in seeds
        for k in range(20)
    ]
    keys += [[0, 0, 0], [0], [5, 6], [1, 2, 3, 4, 5, 6], [2**33, 1, 2, 3, 4]]
    expected = [np.random.default_rng(key).random() for key in keys]
    assert first_doubles(keys) == expected


def _star_rings(count: int) -> list[np.ndarray]:
    rng = np.random.default_rng(11)
    rings = []
    for _ in range(count):
        m = int(rng.integers(4, 40))
        angles = np.sort(rng.uniform(0.0, 2.0 * np.pi, m))
        radii = rng.uniform(0.2, 1.0, m)
        rings.append(np.stack((radii * np.cos(angles), radii * np.sin(angles)), axis=1))
    return rings


def test_triangulate_many_equals_triangulate() -> None:
    rings = _star_rings(200)
    for ring, tris in zip(rings, triangulate_many(rings), strict=True):
        single = triangulate(ring)
        assert tris.dtype == single.dtype
        np.testing.assert_array_equal(tris, single)


def test_hertel_mehlhorn_pieces_cover_every_triangle_once() -> None:
    rings = _star_rings(100)
    tris_list = [triangulate(ring) for ring in rings]
    for tris, pieces in zip(
        tris_list, nested_pieces(hertel_mehlhorn(rings, tris_list)), strict=True
    ):
        assert sum(len(p) - 2 for p in pieces) == len(tris)
        assert sorted(i for p in pieces for i in p)[0] == 0
