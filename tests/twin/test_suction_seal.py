"""The suction cup's seal rule on mesh geometry alone (no simulator): the upturned face, the lip
within the contact tolerance, the whole lip disc on the face, the tilt limit."""

from __future__ import annotations

import math

import numpy as np
import pybullet as pb
import pytest
import trimesh
from shapely.geometry import Polygon

from interfaces.catalog import entry
from interfaces.tools import SuctionCupSpec, tool_from_data
from twin.tools import Pose
from twin.tools.suction_cup import planar_faces, seals_on

CUP = tool_from_data(entry("suction_cup", "tools", "tool"), "tool")
assert isinstance(CUP, SuctionCupSpec)
DOWN = pb.getQuaternionFromEuler([math.pi, 0.0, 0.0])  # the TCP's z axis points down


def _prism(outline: list[tuple[float, float]], height_m: float) -> np.ndarray:
    """Triangles of an extruded outline, centred on z = 0 (as meshgen's meshes)."""
    mesh = trimesh.creation.extrude_polygon(Polygon(outline), height_m)
    mesh.apply_translation((0.0, 0.0, -0.5 * height_m))
    return np.asarray(mesh.triangles)


BOX = _prism([(-0.04, -0.03), (0.04, -0.03), (0.04, 0.03), (-0.04, 0.03)], 0.05)  # 80 x 60 mm
NARROW = _prism([(-0.04, -0.015), (0.04, -0.015), (0.04, 0.015), (-0.04, 0.015)], 0.05)
# an L: 100 x 100 mm with a 60 x 60 mm notch out of one corner
ELL = _prism([(-0.05, -0.05), (0.05, -0.05), (0.05, -0.01), (-0.01, -0.01), (-0.01, 0.05),
              (-0.05, 0.05)], 0.04)  # fmt: skip

UPRIGHT: Pose = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


def _tcp(x: float, y: float, z: float, tilt_rad: float = 0.0) -> Pose:
    return (x, y, z), pb.getQuaternionFromEuler([math.pi + tilt_rad, 0.0, 0.0])


def test_a_box_has_six_planar_faces() -> None:
    faces = planar_faces(BOX)
    assert len(faces) == 6
    top = max(faces, key=lambda f: f.normal[2])
    assert top.normal == pytest.approx((0.0, 0.0, 1.0))
    assert top.offset == pytest.approx(0.025)
    assert top.polygon.area == pytest.approx(0.08 * 0.06)


@pytest.mark.parametrize(
    ("triangles", "tcp", "seals"),
    [
        (BOX, _tcp(0.0, 0.0, 0.026), True),  # on the top face, 1 mm above it
        (BOX, _tcp(0.0, 0.0, 0.023), True),  # the lip pressed 2 mm in
        (BOX, _tcp(0.0, 0.0, 0.031), False),  # 6 mm above: beyond the contact tolerance
        (BOX, _tcp(0.02, 0.0, 0.026), True),  # the disc reaches the edge: 20 mm from it
        (BOX, _tcp(0.025, 0.0, 0.026), False),  # the disc sticks out over the edge
        (NARROW, _tcp(0.0, 0.0, 0.026), False),  # 30 mm wide: a 40 mm lip does not fit
        (ELL, _tcp(-0.03, -0.03, 0.021), True),  # in the L's corner square, 40 x 40 mm
        (ELL, _tcp(-0.02, -0.02, 0.021), False),  # centre on the face, disc over the notch
        (BOX, _tcp(0.0, 0.0, 0.026, tilt_rad=0.3), True),  # tilted within 0.35 rad
        (BOX, _tcp(0.0, 0.0, 0.026, tilt_rad=0.4), False),  # tilted beyond it
    ],
    ids=[
        "on-top",
        "pressed-in",
        "too-high",
        "disc-to-the-edge",
        "disc-over-the-edge",
        "narrower-than-the-lip",
        "l-corner",
        "l-over-the-notch",
        "tilt-within",
        "tilt-beyond",
    ],
)
def test_the_seal_rule(triangles: np.ndarray, tcp: Pose, seals: bool) -> None:
    assert seals_on(CUP, planar_faces(triangles), UPRIGHT, tcp) is seals


def test_a_tipped_object_is_judged_by_its_upturned_face() -> None:
    """The 80 x 60 x 50 mm box rolled onto its side about x: the face now up is 80 x 50 mm,
    its plane 30 mm above the centre; the top cap is now a side."""
    rolled = pb.getQuaternionFromEuler([math.pi / 2, 0.0, 0.0])
    pose: Pose = ((0.3, 0.5, 0.1), rolled)
    faces = planar_faces(BOX)
    assert seals_on(CUP, faces, pose, _tcp(0.3, 0.5, 0.131))
    assert not seals_on(CUP, faces, pose, _tcp(0.3, 0.5, 0.126))  # where the top cap was
    assert not seals_on(CUP, faces, pose, _tcp(0.3 + 0.025, 0.5, 0.131))  # over its edge
