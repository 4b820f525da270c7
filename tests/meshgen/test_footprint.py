"""Repair, orientation and measurement of single footprints."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import shapely

from meshgen.footprint import (
    FootprintRejected,
    build_footprint,
    pixels_to_belt,
    touches_border,
)
from meshgen.mesh import extrude, hertel_mehlhorn, is_convex, triangulate
from tests.meshgen.reference_text import nested_pieces


def _rect(length: float, width: float, yaw: float) -> np.ndarray:
    pts = np.array(
        [
            [-length / 2, -width / 2],
            [length / 2, -width / 2],
            [length / 2, width / 2],
            [-length / 2, width / 2],
        ]
    )
    c, s = math.cos(yaw), math.sin(yaw)
    return pts @ np.array([[c, s], [-s, c]]) + [0.05, -0.02]


@pytest.mark.parametrize("yaw", [0.0, 0.3, -1.2, math.pi / 2, 2.5])
def test_rectangle_measures(yaw: float) -> None:
    fp = build_footprint(_rect(0.2, 0.08, yaw)[::-1], simplify_m=0.0, min_area_m2=0.0)
    assert fp.area_m2 == pytest.approx(0.016)
    assert fp.centroid_m == pytest.approx((0.05, -0.02))
    assert (fp.length_m, fp.width_m) == pytest.approx((0.2, 0.08))
    expected = math.atan2(math.sin(yaw), math.cos(yaw))
    expected = expected - math.pi if expected > math.pi / 2 else expected
    expected = expected + math.pi if expected <= -math.pi / 2 else expected
    assert -math.pi / 2 < fp.yaw_rad <= math.pi / 2
    assert fp.yaw_rad == pytest.approx(expected)
    assert "reoriented" in fp.repairs


def test_duplicates_spikes_and_collinear_points_are_removed() -> None:
    ring = np.array([[0, 0], [0, 0], [1, 0], [2, 0], [2, 1], [2.5, 1], [2, 1], [0, 1]], dtype=float)
    fp = build_footprint(ring * 0.1, simplify_m=0.0, min_area_m2=0.0)
    assert len(fp.ring_m) == 4
    assert fp.area_m2 == pytest.approx(0.02)
    assert any(r.startswith("removed_duplicates") for r in fp.repairs)
    assert any(r.startswith("removed_collinear") for r in fp.repairs)


def test_bow_tie_keeps_the_larger_valid_part() -> None:
    ring = np.array([[0, 0], [0.2, 0.1], [0.2, 0], [0, 0.05]])
    fp = build_footprint(ring, simplify_m=0.0, min_area_m2=0.0)
    assert shapely.Polygon(fp.ring_m).is_valid
    assert any(r.startswith("self_intersection_repaired") for r in fp.repairs)
    assert fp.area_m2 > 0


def test_degenerate_and_small_are_rejected() -> None:
    with pytest.raises(FootprintRejected, match="distinct non-collinear") as info:
        build_footprint(np.array([[0, 0], [1, 1], [2, 2.0]]), simplify_m=0.0, min_area_m2=0.0)
    assert info.value.reason == "degenerate"
    with pytest.raises(FootprintRejected, match="minimum") as info:
        build_footprint(_rect(0.004, 0.004, 0), simplify_m=0.0, min_area_m2=25e-6)
    assert info.value.reason == "below_min_area"


def test_simplification_records_area_change() -> None:
    t = np.linspace(0, 2 * math.pi, 400, endpoint=False)
    ring = np.stack((0.1 * np.cos(t), 0.06 * np.sin(t)), axis=1)
    ring = np.round(ring / 0.0006) * 0.0006
    fp = build_footprint(ring, simplify_m=1e-3, min_area_m2=0.0)
    assert len(fp.ring_m) < 100
    assert 0.97 < fp.area_change_ratio < 1.03
    assert shapely.Polygon(fp.ring_m).is_valid


def test_belt_frame_mapping() -> None:
    px = np.array([[512.0, 480.0], [612.0, 480.0], [512.0, 580.0]])
    m = pixels_to_belt(px, 1024, 960, 0.6 / 1024)
    assert m[0] == pytest.approx((0.0, 0.0))
    assert m[1] == pytest.approx((0.0, 100 * 0.6 / 1024))  # image right is +y
    assert m[2] == pytest.approx((100 * 0.6 / 1024, 0.0))  # image down is +x
    assert touches_border(np.array([[0.5, 10.0], [20, 20], [30, 10]]), 100, 100, 1.0)
    assert not touches_border(np.array([[2.5, 10.0], [20, 20], [30, 10]]), 100, 100, 1.0)


def test_hertel_mehlhorn_on_comb() -> None:
    ring = np.array(
        [
            [0, 0],
            [5, 0],
            [5, 3],
            [4, 3],
            [4, 1],
            [3, 1],
            [3, 3],
            [2, 3],
            [2, 1],
            [1, 1],
            [1, 3],
            [0, 3],
        ],
        float,
    )
    tris = triangulate(ring)
    assert len(tris) == len(ring) - 2
    (pieces,) = nested_pieces(hertel_mehlhorn([ring], [tris]))
    assert 3 <= len(pieces) <= 6
    assert sum(shapely.Polygon(ring[p]).area for p in pieces) == pytest.approx(
        shapely.Polygon(ring).area
    )
    assert all(is_convex(ring[p]) for p in pieces)
    verts, faces = extrude(ring, tris, 1.0)
    assert len(verts) == 2 * len(ring)
    assert len(faces) == 4 * len(ring) - 4


def _kept_area_ratio(repairs: tuple[str, ...]) -> float:
    (entry,) = [r for r in repairs if r.startswith("self_intersection_repaired:")]
    return float(entry.split("kept_area_ratio=")[1])


@pytest.mark.parametrize("nudge", [0.0, 1e-12, 1e-9, 1e-6, -1e-6])
def test_symmetric_bow_tie_keeps_half_of_the_enclosed_area(nudge: float) -> None:
    """The two loops of a bow-tie cancel in its signed area (0 or ~1e-13 here): the ratio must
    not be taken against that."""
    ring = np.array([[0, 0], [0.1, 0.1], [0.1, 0], [0, 0.1 + nudge]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fp = build_footprint(ring, simplify_m=0.0, min_area_m2=0.0)
    assert _kept_area_ratio(fp.repairs) == pytest.approx(0.5, abs=1e-4)
    assert fp.area_m2 == pytest.approx(0.0025, rel=1e-4)


def test_bow_tie_ratio_is_the_kept_loop_over_both_loops() -> None:
    # the edges (0,0)-(0.2,0.1) and (0.2,0)-(0,0.05) cross at (0.2/3, 0.1/3): loops of area
    # 0.05 * (0.2/3) / 2 and 0.1 * (0.2 - 0.2/3) / 2, i.e. 1/600 and 4/600
    ring = np.array([[0, 0], [0.2, 0.1], [0.2, 0], [0, 0.05]])
    fp = build_footprint(ring, simplify_m=0.0, min_area_m2=0.0)
    assert fp.area_m2 == pytest.approx(4 / 600)
    assert _kept_area_ratio(fp.repairs) == pytest.approx(0.8, abs=1e-4)


@pytest.mark.parametrize(
    "ring",
    [
        [[0, 0], [1, 1], [2, 2]],
        [[0, 0], [1, 1], [2, 2], [3, 3], [1, 1]],
        [[0, 0], [1, 0], [0, 0], [1, 0]],
        [[0, 0], [0, 0], [0, 0]],
        [[0, 0], [1, 1e-12], [2, 0]],
        [[0, 0], [1, 1e-13], [1, 0], [0, 1e-13]],
    ],
)
@pytest.mark.parametrize("simplify_m", [0.0, 1e-3])
def test_collinear_outlines_are_rejected_as_degenerate(
    ring: list[list[float]], simplify_m: float
) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(FootprintRejected) as info:
            build_footprint(np.array(ring) * 0.05, simplify_m=simplify_m, min_area_m2=0.0)
    assert info.value.reason == "degenerate"
