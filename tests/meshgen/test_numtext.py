"""Array formatting gives exactly Python's ``%`` text; batched mesh texts equal one-object ones."""

from __future__ import annotations

from decimal import ROUND_HALF_EVEN, Decimal
from itertools import pairwise

import numpy as np
import pytest

from meshgen.loaders import _numeric_pairs
from meshgen.mesh import triangulate
from meshgen.numtext import Fixed, Part, Whole, render, round_scaled
from meshgen.objtext import (
    caps_blocks,
    pieces_blocks,
    points_json_blocks,
    uv_blocks,
    vertex_rows,
    vertex_texts,
)
from tests.meshgen.reference_text import (
    caps_texts,
    hertel_mehlhorn_one,
    pieces_text,
    points_json,
    uv_block,
    vertex_blocks,
)


def _floats() -> np.ndarray:
    """Values that test rounding: exact binary ties at many decimals, their neighbours, noise."""
    rng = np.random.default_rng(4)
    ties = [(rng.integers(-(10**6), 10**6, 400) + 0.5) / 10.0**d for d in range(1, 16)]
    near = [np.nextafter(t, s) for t in ties for s in (np.inf, -np.inf)]
    return np.concatenate(
        [
            np.arange(-3000, 3000) * (0.6 / 1024),  # belt metres of whole pixels: many ties
            rng.integers(-(2**30), 2**30, 3000) / 2.0 ** rng.integers(1, 40, 3000),
            rng.normal(0.0, 1.0, 3000) * 10.0 ** rng.integers(-12, 6, 3000),
            *ties,
            *near,
            [0.0, -0.0, 5e-324, -1e-300, 0.5, 1.5, 2.5, 9.9999995, 0.0078125, 999999.5],
        ]
    )


def _rows(parts: list[Part], count: int) -> list[str]:
    text, offsets = render(parts, count).text(range(count + 1))
    return [text[a:b] for a, b in pairwise(offsets)]


def test_round_scaled_rounds_the_exact_value_half_to_even() -> None:
    values = np.abs(_floats())
    for decimals in (1, 3, 6, 9, 12):
        ok = values[values < 2.0**51 / 10**decimals]
        want = [
            int((Decimal(v) * 10**decimals).to_integral_value(ROUND_HALF_EVEN)) for v in ok.tolist()
        ]
        assert round_scaled(ok, decimals).tolist() == want


@pytest.mark.parametrize("decimals", range(1, 16))
def test_fixed_columns_match_percent_format(decimals: int) -> None:
    values = _floats()
    other = np.random.default_rng(decimals).permutation(values)
    got = _rows(["[", Fixed(values, decimals), ",", Fixed(other, decimals), "],"], len(values))
    pattern = f"[%.{decimals}f,%.{decimals}f],"
    assert got == [pattern % pair for pair in zip(values.tolist(), other.tolist(), strict=True)]


def test_columns_at_the_row_start_and_side_by_side() -> None:
    rng = np.random.default_rng(8)
    small = rng.integers(0, 12, 500)
    ints = rng.integers(-(10**9), 10**9, 500)
    floats = rng.normal(0.0, 50.0, 500)
    parts: list[Part] = [Whole(small), Whole(ints), Fixed(floats, 2), Whole(small), "|"]
    pattern = "%d%d%.2f%d|"
    rows = zip(small.tolist(), ints.tolist(), floats.tolist(), small.tolist(), strict=True)
    want = [pattern % row for row in rows]
    assert _rows(parts, 500) == want


def test_values_python_must_format_fall_back() -> None:
    floats = np.array([1.0, np.nan, -np.inf, 1e300, -2.5])
    pattern = "x%.3f\n"
    assert _rows(["x", Fixed(floats, 3), "\n"], 5) == [pattern % v for v in floats.tolist()]
    ints = np.array([0, -1, 10**18, np.iinfo(np.int64).min, 7], dtype=np.int64)
    pattern = "f %d\n"
    assert _rows(["f ", Whole(ints), "\n"], 5) == [pattern % v for v in ints.tolist()]


def test_whole_columns_match_percent_d() -> None:
    rng = np.random.default_rng(2)
    values = np.concatenate(
        [rng.integers(-(10**17), 10**17, 2000), rng.integers(0, 10**4, 2000), [0, 9, 10, 9999]]
    )
    got = _rows(["f ", Whole(values), " ", Whole(values[::-1].copy()), "\n"], len(values))
    pairs = zip(values.tolist(), values[::-1].tolist(), strict=True)
    pattern = "f %d %d\n"
    assert got == [pattern % pair for pair in pairs]


def _star(points: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    angles = np.linspace(0.0, 2.0 * np.pi, points, endpoint=False)
    radii = rng.uniform(0.3, 1.0, points) * 0.05
    return np.stack((radii * np.cos(angles), radii * np.sin(angles)), axis=1)


RINGS = [_star(n, seed) for seed, n in enumerate((3, 4, 7, 12, 30, 5, 64, 9))]
SIZES = np.array([len(r) for r in RINGS], dtype=np.int64)


@pytest.mark.parametrize("up", ["z", "y"])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_vertex_texts_match_vertex_blocks(up: str, sign: float) -> None:
    # sign -1: negative half heights, so the top rows cannot be the bottom rows minus a "-"
    halves = sign * np.array([0.0, 0.01, 0.0125, 0.03, 0.5, 0.0078125, 0.02, 1.5])
    bottoms, tops = vertex_texts(vertex_rows(np.concatenate(RINGS), SIZES, halves, up), SIZES)
    for ring, half, bottom, top in zip(RINGS, halves.tolist(), bottoms, tops, strict=True):
        assert (bottom, top) == vertex_blocks(ring, half, up)


def test_caps_and_pieces_blocks_match_one_object_texts() -> None:
    tris = [triangulate(r) for r in RINGS]
    counts = np.array([len(t) for t in tris], dtype=np.int64)
    caps = caps_blocks(np.concatenate(tris), counts, SIZES)
    assert caps == caps_texts(tris, SIZES.tolist())
    textured = caps_blocks(np.concatenate(tris), counts, SIZES, textured=True)
    assert textured == caps_texts(tris, SIZES.tolist(), textured=True)
    halves = np.linspace(0.01, 0.04, len(RINGS))
    rows = vertex_rows(np.concatenate(RINGS), SIZES, halves, "z")
    pieces = [hertel_mehlhorn_one(r, t) for r, t in zip(RINGS, tris, strict=True)]
    flat = [i for parts in pieces for piece in parts for i in piece]
    texts = pieces_blocks(
        rows,
        np.cumsum(SIZES) - SIZES,
        np.array(flat, dtype=np.int64),
        np.array([len(p) for parts in pieces for p in parts], dtype=np.int64),
        np.array([len(parts) for parts in pieces], dtype=np.int64),
    )
    for ring, half, parts, text in zip(RINGS, halves.tolist(), pieces, texts, strict=True):
        assert text == pieces_text(*vertex_blocks(ring, half, "z"), parts)


def test_uv_blocks_match_uv_block() -> None:
    # texture coordinates of pixels of a 1024 x 960 photo, including the edges and exact ties
    rng = np.random.default_rng(9)
    pixels = np.concatenate(
        (rng.uniform(0.0, 1024.0, (int(SIZES.sum()) - 4, 2)), [[0, 0], [1024, 960], [512, 480]])
    )
    pixels = np.concatenate((pixels, [[0.5, 959.5]]))
    uv = np.stack((pixels[:, 0] / 1024.0, 1.0 - pixels[:, 1] / 960.0), axis=1)
    blocks = uv_blocks(uv, SIZES)
    starts = np.cumsum(SIZES) - SIZES
    for start, size, block in zip(starts.tolist(), SIZES.tolist(), blocks, strict=True):
        assert block == uv_block(uv[start : start + size])


def test_points_json_blocks_match_points_json() -> None:
    points = np.concatenate(RINGS) * 1000.0
    for decimals in (3, 9):
        blocks = points_json_blocks(points, SIZES, decimals)
        assert blocks == [points_json(r * 1000.0, f"%.{decimals}f") for r in RINGS]


def test_points_json_blocks_of_pixel_polygons() -> None:
    # whole pixels (the usual case), fractions, negatives, -0.0, huge and almost-whole values
    rng = np.random.default_rng(3)
    polygons = [
        rng.integers(0, 5000, size=(50, 2)).astype(np.float64),
        rng.uniform(-10, 5000, size=(50, 2)),
        np.array([[-0.0, 0.0], [1.0, 2.0], [3.0, 4.5]]),
        np.array([[-2.0, 5.0], [3.0, 5.0], [3.0, 9.0]]),
        np.array([[2.0**53, 1.0], [2.0**60, 2.0], [3.0, 4.0]]),
        np.array([[0.9999999999999999, 1.0], [1.0, 2.0], [3.0, 4.0]]),
        np.zeros((0, 2)),
    ]
    sizes = np.array([len(p) for p in polygons], dtype=np.int64)
    blocks = points_json_blocks(np.concatenate(polygons), sizes, 3)
    assert blocks == [points_json(p, "%.3f") for p in polygons]
    assert blocks[2] == "[[-0.000,0.000],[1.000,2.000],[3.000,4.500]]"


@pytest.mark.parametrize(
    "raws",
    [
        [[[1, 2], [3, 4], [5, 6]], [[7.5, 8], [9, 10], [11, 12]]],
        [[[1, 2], [3, 4]], []],
        [[], []],
        [[[1, 2], [3, 4, 5], [6]]],
        [[[1, 2], "ab"]],
        [[[1, 2], {"a": 1, "b": 2}]],
        [[[1, 2], [[1, 2], [3, 4]]]],
        [[[1, 2], 5]],
        [[[1, None], [2, 3]]],
        [[[2**70, 1], [2, 3]]],
        [[["1", "2"], [3, 4]]],
        [[[1, 2]], "points"],
    ],
)
def test_numeric_pairs_equals_the_nested_array(raws: list[object]) -> None:
    got = _numeric_pairs(raws)
    flat: list[object] = []
    try:
        for raw in raws:
            flat += raw  # type: ignore[arg-type]
        want = np.array(flat)
        if want.ndim != 2 or want.shape[1] != 2 or want.dtype.kind not in "if":
            want = None
    except (TypeError, ValueError, OverflowError):
        want = None
    if want is None:
        assert got is None
    else:
        assert got is not None
        assert got.dtype == want.dtype
        assert np.array_equal(got, want)
