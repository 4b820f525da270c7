"""The suction point a pick-point detector reports for an object it sees from above.

Vision systems of suction pickers report where a cup fits best: the point of the object's upturned
face farthest from the face's outline (its pole of inaccessibility), and that distance, the
largest lip radius that fits there, with the surface's normal (here its tilt from level, which
decides whether a lip can seal on it at all). Here the face is the one of the object's mesh
whose outward normal points most nearly up (:func:`twin.tools.suction_cup.planar_faces`: the
top cap of an upright extruded prism, a side of a tipped one), the same face the twin's suction
cup seals on, and the pole is shapely's ``polylabel`` (to 0.1 mm). On a concave or bent piece
the pole lies well away from the footprint's centroid, which may have no room for a lip at all.

The faces of each mesh and the pole of each of its faces are computed once per process, named
by a digest of the mesh's triangles: the perception's and the spawn judge's instances see the
same objects, and each object's faces were computed twice (3 ms each, 5 % of the reference
cell's episode).
"""

from __future__ import annotations

import hashlib
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

_CACHE_MESHES = 4096
"""Meshes whose faces and poles are kept (a few episodes' worth; then the cache starts over)."""

_FACES: dict[bytes, tuple[tuple[Face, ...], FloatArray]] = {}
_POLES: dict[tuple[bytes, int], tuple[FloatArray, float]] = {}


class SuctionPoints:
    """``points(gt)``: the suction point (world frame, m) of the object ``gt``, its radius (m)
    and the tilt of its face (rad from level). ``mesh_of(object_id)`` gives an object's
    triangles ``(t, 3, 3)`` in its own frame."""

    def __init__(self, mesh_of: Callable[[int], FloatArray]) -> None:
        self._mesh_of = mesh_of
        self._mesh_key: dict[int, bytes] = {}  # object id: the digest of its triangles

    def _mesh(self, object_id: int) -> tuple[bytes, tuple[Face, ...], FloatArray]:
        """The object's mesh, named by its triangles, and its faces and their normals
        (computed by the first instance that sees the mesh, for every later one)."""
        key = self._mesh_key.get(object_id)
        triangles = None
        if key is None:
            triangles = self._mesh_of(object_id)
            data = np.ascontiguousarray(triangles)
            key = hashlib.blake2b(data.tobytes(), digest_size=16).digest()
            key += f"{data.dtype}{data.shape}".encode()
            self._mesh_key[object_id] = key
        cached = _FACES.get(key)
        if cached is None:
            if len(_FACES) >= _CACHE_MESHES:
                _FACES.clear()
                _POLES.clear()
            faces = planar_faces(self._mesh_of(object_id) if triangles is None else triangles)
            cached = _FACES[key] = (faces, np.array([f.normal for f in faces]))
        return key, *cached

    def faces(self, object_id: int) -> tuple[tuple[Face, ...], FloatArray]:
        """The object's planar faces in its own frame and their outward normals ``(f, 3)``."""
        _, faces, normals = self._mesh(object_id)
        return faces, normals

    def __call__(self, gt: GroundTruth) -> tuple[Vec3, float, float]:
        """The upturned face's pole in the world frame, its distance to the face's outline and
        the angle between the face's outward normal and up."""
        key, faces, normals = self._mesh(gt.id)
        rotation = rotation_matrix(gt.orientation_xyzw)
        ups = normals @ rotation[2]  # world z of every face normal
        up = int(np.argmax(ups))
        pole = _POLES.get((key, up))
        if pole is None:
            face = faces[up]
            point = polylabel(face.polygon, POLE_TOLERANCE_M)
            local = face.origin + point.x * face.u + point.y * face.v
            pole = (local, float(face.polygon.boundary.distance(point)))
            _POLES[(key, up)] = pole
        local, radius_m = pole
        world = np.asarray(gt.position_m) + rotation @ local
        tilt_rad = math.acos(min(1.0, max(-1.0, float(ups[up]))))
        return (float(world[0]), float(world[1]), float(world[2])), radius_m, tilt_rad


__all__ = ["POLE_TOLERANCE_M", "SuctionPoints"]
