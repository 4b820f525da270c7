"""The suction point a pick-point detector reports for an object it sees from above.

Vision systems of suction pickers report where a cup fits best: the point of the object's upturned
face farthest from the face's outline (its pole of inaccessibility), and that distance, the
largest lip radius that fits there, with the surface's normal (here its tilt from level, which
decides whether a lip can seal on it at all). Here the face is the one of the object's mesh
whose outward normal points most nearly up (:func:`twin.tools.suction_cup.planar_faces`: the
top cap of an upright extruded prism, a side of a tipped one), the same face the twin's suction
cup seals on, and the pole is shapely's ``polylabel`` (to 0.1 mm). On a concave or bent piece
the pole lies well away from the footprint's centroid, which may have no room for a lip at all.

The faces of each object and the pole of each of its faces are computed once per episode (a
few per object; a 60 s episode has a few hundred objects).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from shapely.ops import polylabel

from twin.tools.suction_cup import Face, planar_faces
from twin.top_view import FloatArray, rotation_matrix

if TYPE_CHECKING:
    from twin.ground_truth import GroundTruth

POLE_TOLERANCE_M = 1e-4
"""How close ``polylabel`` gets to the pole."""

Vec3 = tuple[float, float, float]


class SuctionPoints:
    """``points(gt)``: the suction point (world frame, m) of the object ``gt``, its radius (m)
    and the tilt of its face (rad from level). ``mesh_of(object_id)`` gives an object's
    triangles ``(t, 3, 3)`` in its own frame."""

    def __init__(self, mesh_of: Callable[[int], FloatArray]) -> None:
        self._mesh_of = mesh_of
        self._faces: dict[int, tuple[Face, ...]] = {}
        self._normals: dict[int, FloatArray] = {}
        self._poles: dict[tuple[int, int], tuple[FloatArray, float]] = {}

    def __call__(self, gt: GroundTruth) -> tuple[Vec3, float, float]:
        """The upturned face's pole in the world frame, its distance to the face's outline and
        the angle between the face's outward normal and up."""
        faces = self._faces.get(gt.id)
        if faces is None:
            faces = planar_faces(self._mesh_of(gt.id))
            self._faces[gt.id] = faces
            self._normals[gt.id] = np.array([f.normal for f in faces])
        rotation = rotation_matrix(gt.orientation_xyzw)
        ups = self._normals[gt.id] @ rotation[2]  # world z of every face normal
        up = int(np.argmax(ups))
        pole = self._poles.get((gt.id, up))
        if pole is None:
            face = faces[up]
            point = polylabel(face.polygon, POLE_TOLERANCE_M)
            local = face.origin + point.x * face.u + point.y * face.v
            pole = (local, float(face.polygon.boundary.distance(point)))
            self._poles[(gt.id, up)] = pole
        local, radius_m = pole
        world = np.asarray(gt.position_m) + rotation @ local
        tilt_rad = math.acos(min(1.0, max(-1.0, float(ups[up]))))
        return (float(world[0]), float(world[1]), float(world[2])), radius_m, tilt_rad


__all__ = ["POLE_TOLERANCE_M", "SuctionPoints"]
