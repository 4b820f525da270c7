"""The suction point a pick-point detector reports: the pole of the upturned face, world frame."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
import trimesh
from shapely.geometry import Point, Polygon, box

from twin.ground_truth import GroundTruth
from twin.suction_point import SuctionPoints
from twin.top_view import TopView

HEIGHT_M = 0.04
# A 10 cm square with a 2 cm wide bar 30 cm long to its right: the footprint's centroid lies on
# the bar (1 cm from its edges), the square's centre is where a cup fits (5 cm from every edge).
OUTLINE = box(-0.05, -0.05, 0.05, 0.05).union(box(0.05, -0.01, 0.35, 0.01))


def _triangles(outline: Polygon) -> np.ndarray:
    mesh = trimesh.creation.extrude_polygon(outline, HEIGHT_M)
    return np.asarray(mesh.triangles, dtype=float)


def _truth(position_m: tuple[float, float, float], quat_xyzw: tuple[float, ...]) -> GroundTruth:
    return GroundTruth(
        id=7,
        source_id="o7",
        class_name="brick",
        position_m=position_m,
        orientation_xyzw=quat_xyzw,  # type: ignore[arg-type]
        linear_velocity_mps=(0.4, 0.0, 0.0),
        angular_velocity_radps=(0.0, 0.0, 0.0),
        top_view=TopView(yaw_rad=0.0, length_m=0.4, width_m=0.1, height_m=HEIGHT_M, below_m=0.0),
        length_m=0.4,
        width_m=0.1,
        area_m2=OUTLINE.area,
        volume_m3=OUTLINE.area * HEIGHT_M,
        height_m=HEIGHT_M,
        mass_kg=1.0,
        on_belt=True,
        in_workspace=False,
        held=False,
        in_bin=False,
    )


def test_the_pole_of_a_concave_top_is_where_the_cup_fits_not_the_centroid() -> None:
    calls: list[int] = []

    def mesh_of(object_id: int) -> np.ndarray:
        calls.append(object_id)
        return _triangles(OUTLINE)

    points = SuctionPoints(mesh_of)
    yaw = 0.7
    quat = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    (x, y, z), radius_m, tilt_rad = points(_truth((1.0, 0.5, 0.2), quat))
    # the square's centre, turned by the yaw and moved to the position; z on the top
    assert (x, y) == pytest.approx((1.0, 0.5), abs=1.5e-3)  # the pole is 0.5 mm right of it
    assert z == pytest.approx(0.2 + HEIGHT_M, abs=1e-9)
    assert radius_m == pytest.approx(0.05, abs=2e-4)
    assert tilt_rad == pytest.approx(0.0, abs=1e-6)  # level: turned about z only
    centroid = OUTLINE.centroid
    assert OUTLINE.boundary.distance(Point(centroid.x, centroid.y)) < 0.011  # no room there
    # moved on, the same object's point moves with it; its mesh is read once
    (x2, _, _), _, _ = points(_truth((1.3, 0.5, 0.2), quat))
    assert x2 == pytest.approx(x + 0.3, abs=1e-9)
    assert calls == [7]


def test_a_tipped_object_is_judged_by_the_face_turned_up() -> None:
    points = SuctionPoints(lambda _: _triangles(box(-0.1, -0.03, 0.1, 0.03)))
    upright = _truth((0.0, 0.5, 0.0), (0.0, 0.0, 0.0, 1.0))
    assert points(upright)[1] == pytest.approx(0.03, abs=2e-4)  # the 6 cm wide top
    # on its long side (a quarter turn about x): the up face is 20 cm x 4 cm
    tipped = replace(
        upright, orientation_xyzw=(math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4))
    )
    (_, _, z), radius_m, tilt_rad = points(tipped)
    assert radius_m == pytest.approx(HEIGHT_M / 2, abs=2e-4)
    assert z == pytest.approx(0.03, abs=1e-9)  # the side that was at y = -0.03 is up
    assert tilt_rad == pytest.approx(0.0, abs=1e-6)  # that side lies level


@pytest.mark.parametrize("tilt_deg", [10.0, 25.0, 40.0])
def test_a_propped_object_reports_its_faces_tilt(tilt_deg: float) -> None:
    """Propped on another piece (turned about its long axis by less than 45 degrees) the top
    stays the face turned up, and the camera reports how far it is tilted from level."""
    points = SuctionPoints(lambda _: _triangles(box(-0.1, -0.03, 0.1, 0.03)))
    half = math.radians(tilt_deg) / 2
    propped = _truth((0.0, 0.5, 0.05), (math.sin(half), 0.0, 0.0, math.cos(half)))
    (_, _, z), radius_m, tilt_rad = points(propped)
    assert tilt_rad == pytest.approx(math.radians(tilt_deg), abs=1e-9)
    assert radius_m == pytest.approx(0.03, abs=2e-4)  # still the 6 cm wide top
    # the pole, the top's centre (the mesh frame's origin is under it, on the bottom)
    assert z == pytest.approx(0.05 + HEIGHT_M * math.cos(math.radians(tilt_deg)), abs=1e-6)


def test_a_second_instance_reuses_the_faces_of_a_mesh_and_gives_the_same_point(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The perception and the spawn judge each keep a SuctionPoints over the same objects: the
    faces of a mesh are computed once per process (named by its triangles) and both give the
    same point; another mesh (another height) gets its own faces."""
    from twin import suction_point
    from twin.tools import suction_cup

    computed: list[int] = []
    real = suction_cup.planar_faces

    def counted(triangles: np.ndarray) -> Any:
        computed.append(len(triangles))
        return real(triangles)

    monkeypatch.setattr(suction_point, "planar_faces", counted)
    outline = box(-0.05, -0.04, 0.07, 0.04)  # a mesh no other test made
    first = SuctionPoints(lambda _: _triangles(outline))
    second = SuctionPoints(lambda _: _triangles(outline))
    truth = _truth((1.0, 0.5, 0.2), (0.0, 0.0, 0.0, 1.0))
    assert first(truth) == second(truth)
    assert len(computed) == 1
    taller = SuctionPoints(lambda _: _triangles(outline) * np.array([1.0, 1.0, 1.5]))
    (_, _, z), _, _ = taller(truth)
    assert z == pytest.approx(0.2 + 1.5 * HEIGHT_M, abs=1e-9)
    assert len(computed) == 2
