"""The suction cup, twin side: a vacuum cup on a stem on the robot's flange.

Command: the vacuum, 1 on, 0 off (``>= 0.5`` is on). Measured: the vacuum reached as a fraction
of ``vacuum_kPa`` (0 to 1), reported on ``joint_states`` as the joint ``<name>_vacuum``
(velocity 0), as a vacuum switch would report it.

Seal (with the vacuum on, checked every physics step for an object the TCP box overlaps): the
object's upturned face is the face of its mesh whose outward normal points most nearly up (the
top cap of an upright extruded prism, a side face of a tipped one; coplanar triangles of the
mesh make one face); the cup seals when

- the face is tilted from the cup's axis by at most ``max_tilt_rad`` (the angle between the
  face's normal and the TCP's z axis reversed: the lip lies flat on the face);
- the lip's centre (the TCP) lies within ``contact_tolerance_m`` of the face's plane;
- the whole lip disc, ``cup_diameter_m`` across, centred on the lip's centre projected onto the
  face's plane, lies within the face (shapely: the centre inside the face polygon, at least the
  lip's radius from its boundary).

Vacuum: while sealed, the vacuum builds up linearly from 0 to full over ``build_up_s``; when it
is full the object is held (the grasp rule; no contacts or dwell). Open (vacuum on, no seal) the
cup holds no vacuum. Vacuum off vents it linearly to 0 over ``vent_s``.

Carry (every physics step the object is held): the holding force is the vacuum fraction times
``SuctionCupSpec.holding_force(class)`` (vacuum x lip area x the class's seal efficiency, from the
cell's class table); it is
checked against ``mass (g + |a|)``, ``a`` the TCP's measured acceleration
(:class:`twin.tools.TcpAccelerometer`). Exceeded with the vacuum on, the object drops
(``suction_overload``); with the vacuum off (venting), it is let go (``released``). Should the
object be pushed off the lip while held (the lip's centre moved by more than
``contact_tolerance_m`` from where it sealed, in the object's frame), the seal is lost
(``seal_lost``). After such a drop the cup grasps nothing until its vacuum has been turned off.

Unintended contacts: the cup has no contact links; a touch of its stem (or any other robot link)
on an object other than the one under the cup (overlapping its TCP box) is unintended.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as pb
from shapely.geometry import Point, Polygon
from shapely.ops import unary_union

from interfaces.materials import ClassTable, shipped_table
from interfaces.tools import SuctionCupSpec
from twin.robot import Robot
from twin.tools import (
    RELEASED,
    SEAL_LOST,
    SUCTION_OVERLOAD,
    Candidate,
    FloatArray,
    HeldObject,
    Pose,
    TcpAccelerometer,
    link_pose,
    offset_pose,
)
from twin.top_view import rotation_matrix

ON_THRESHOLD = 0.5
"""A command at least this is vacuum on."""

_NORMAL_DECIMALS = 3
"""Triangles whose unit normals agree to this many decimals (and planes to 0.1 mm) are one
face."""


@dataclass(frozen=True)
class Face:
    """A planar face of a mesh, in its mesh frame: unit outward ``normal`` ``(3,)``, the plane
    ``normal . p = offset``, an ``origin`` ``(3,)`` on it and in-plane axes ``u``, ``v`` ``(3,)``
    in which ``polygon`` is the face's outline."""

    normal: FloatArray
    offset: float
    origin: FloatArray
    u: FloatArray
    v: FloatArray
    polygon: Polygon


def planar_faces(triangles: FloatArray) -> tuple[Face, ...]:
    """The planar faces of a closed mesh's ``(n, 3, 3)`` triangles (counter-clockwise seen from
    outside, as OBJ files have them): coplanar triangles with the same normal merged into one
    polygon each."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    cross = np.cross(b - a, c - a)
    twice_area = np.linalg.norm(cross, axis=1)
    keep = twice_area > 1e-12
    normals = cross[keep] / twice_area[keep, None]
    tris = triangles[keep]
    offsets = np.einsum("ij,ij->i", normals, tris[:, 0])
    keys = np.column_stack(
        (np.round(normals, _NORMAL_DECIMALS), np.round(offsets * 1e4))
    )  # plane to 0.1 mm
    groups: dict[tuple[float, ...], list[int]] = {}
    for i, key in enumerate(map(tuple, keys)):
        groups.setdefault(key, []).append(i)
    return tuple(_face(normals[idx], offsets[idx], tris[idx]) for idx in groups.values())


def _face(normals: FloatArray, offsets: FloatArray, tris: FloatArray) -> Face:
    normal = normals.mean(axis=0)
    normal /= np.linalg.norm(normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    origin = tris[0, 0]
    flat = tris - origin
    pieces = [Polygon(np.column_stack((t @ u, t @ v))) for t in flat]
    outline = unary_union(pieces).buffer(1e-7).buffer(-1e-7)
    if not isinstance(outline, Polygon):  # a face in several pieces: its largest
        outline = max(getattr(outline, "geoms", ()), key=lambda g: g.area, default=Polygon())
    return Face(
        normal=normal,
        offset=float(offsets.mean()),
        origin=origin,
        u=u,
        v=v,
        polygon=outline,
    )


def seals_on(
    spec: SuctionCupSpec, faces: tuple[Face, ...], mesh_pose: Pose, tcp_pose: Pose
) -> bool:
    """Whether a cup of ``spec`` at ``tcp_pose`` seals on the upturned face of an object with
    ``faces`` (mesh frame) at ``mesh_pose`` (see the module docstring)."""
    if not faces:
        return False
    position, orientation = mesh_pose
    rotation = rotation_matrix(orientation)
    normals = np.array([f.normal for f in faces])
    up = int(np.argmax(normals @ rotation[2]))  # world z of every face normal
    face = faces[up]
    tcp_position, tcp_orientation = tcp_pose
    axis = rotation_matrix(tcp_orientation)[:, 2]
    if float(rotation @ face.normal @ -axis) < math.cos(spec.max_tilt_rad):
        return False
    local = rotation.T @ (np.asarray(tcp_position) - np.asarray(position))
    distance = float(face.normal @ local) - face.offset
    if abs(distance) > spec.contact_tolerance_m:
        return False
    centre = local - distance * face.normal - face.origin
    point = Point(float(centre @ face.u), float(centre @ face.v))
    polygon = face.polygon
    return bool(
        polygon.contains(point) and polygon.boundary.distance(point) >= 0.5 * spec.cup_diameter_m
    )


class SuctionCup:
    """A suction cup on ``robot``'s flange (see the module docstring)."""

    def __init__(
        self,
        spec: SuctionCupSpec,
        robot: Robot,
        *,
        gravity_mps2: float = 9.81,
        materials: ClassTable | None = None,
    ) -> None:
        self.spec = spec
        self.materials = materials if materials is not None else shipped_table()
        self.body = robot.body
        self.client = robot.client
        self.tcp_link = robot.link_index(spec.tcp_link, "TCP link")
        self.contact_links: dict[int, int] = {}
        self.joint_names = (spec.vacuum_joint,)
        self.max_command = 1.0
        self.engaged_radius_m = 0.0
        self._offset = None if not any(spec.tcp_offset_m) else spec.tcp_offset_m
        self._gravity_mps2 = gravity_mps2
        self._accelerometer = TcpAccelerometer(self.body, self.tcp_link, self.client)
        self._faces: dict[tuple[str, float], tuple[Face, ...]] = {}
        self._on = False
        self._level = 0.0
        self._now_s = 0.0
        self._seal_id: int | None = None
        self._seal_since_s = 0.0
        self._seal_seen_s = -math.inf
        self._held: HeldObject | None = None
        self._lip_in_object: tuple[float, float, float] | None = None
        self._lost = False

    def reset_state(self) -> None:
        """Vacuum off and vented, nothing sealed or held."""
        self._on = False
        self._level = 0.0
        self._now_s = 0.0
        self._seal_id = None
        self._seal_seen_s = -math.inf
        self._lost = False
        self._accelerometer.reset()
        self.release()

    def command(self, value: float) -> None:
        """Vacuum on (``value >= 0.5``) or off."""
        self._on = value >= ON_THRESHOLD

    def apply(self) -> None:
        """No motors: the vacuum follows the command in :meth:`tick`."""

    @property
    def vacuum_on(self) -> bool:
        """The commanded vacuum."""
        return self._on

    def measured(self) -> float:
        """The vacuum reached, as a fraction of full vacuum."""
        return self._level

    def joint_report(self) -> tuple[list[float], list[float]]:
        """``<name>_vacuum``: the vacuum fraction, velocity 0."""
        return [self._level], [0.0]

    def link_pose(self) -> Pose:
        """Pose of the TCP link's frame, world."""
        return link_pose(self.body, self.tcp_link, self.client)

    def tcp_pose(self) -> Pose:
        """Pose of the TCP (the centre of the lip), world."""
        return offset_pose(self.link_pose(), self._offset)

    def contact_name(self, index: int) -> str:
        """The cup has no contact links."""
        return self.spec.name

    def tick(self, time_s: float) -> None:
        """The vacuum at ``time_s``: building up on a seal seen at the last step (or full on a
        held object), venting with the vacuum off, none on an open cup; the TCP's velocity
        sampled for the carry's acceleration."""
        self._accelerometer.sample(time_s)
        dt_s = max(time_s - self._now_s, 0.0)
        sealed = self._seal_id is not None and self._seal_seen_s >= self._now_s - 1e-9
        self._now_s = time_s
        if not self._on:
            self._level = max(0.0, self._level - dt_s / self.spec.vent_s)
            self._seal_id = None
            self._lost = False
        elif self._held is not None:
            self._level = min(1.0, self._level + dt_s / self.spec.build_up_s)
        elif sealed:
            self._level = min(1.0, (time_s - self._seal_since_s) / self.spec.build_up_s)
        else:
            self._level = 0.0
            self._seal_id = None

    def grasps(self, candidate: Candidate) -> bool:
        """The vacuum is on (and was turned off since a drop), the cup seals on the object and
        the vacuum has built up."""
        if not self._on or self._lost:
            return False
        faces = self._faces.get(candidate.shape_key)
        if faces is None:
            faces = planar_faces(candidate.triangles())
            self._faces[candidate.shape_key] = faces
        if not seals_on(self.spec, faces, candidate.mesh_pose(), candidate.tcp_pose):
            if self._seal_id == candidate.object_id:
                self._seal_id = None
            return False
        if self._seal_id != candidate.object_id:
            self._seal_id = candidate.object_id
            self._seal_since_s = candidate.time_s
        self._seal_seen_s = candidate.time_s
        return candidate.time_s - self._seal_since_s >= self.spec.build_up_s - 1e-9

    def hold(self, held: HeldObject, time_s: float) -> None:
        """Start carrying ``held``: where the lip sits on it."""
        del time_s
        self._held = held
        self._lip_in_object = self._lip_on(held)

    def carry(self, time_s: float) -> str | None:
        """``seal_lost``, ``suction_overload`` or (vacuum off) ``released`` once the holding
        force gives way; None while it holds."""
        held = self._held
        if held is None:
            return RELEASED
        load = held.mass_kg * (self._gravity_mps2 + self._accelerometer.magnitude(time_s))
        force = self._level * self.spec.holding_force(held.class_name, self.materials)
        if self._lip_in_object is not None and (
            math.dist(self._lip_on(held), self._lip_in_object) > self.spec.contact_tolerance_m
        ):
            self._lost = True
            return SEAL_LOST
        if force < load:
            if not self._on:
                return RELEASED
            self._lost = True
            return SUCTION_OVERLOAD
        return None

    def release(self) -> None:
        """Nothing held (the seal goes with the object)."""
        self._held = None
        self._lip_in_object = None
        self._seal_id = None

    def _lip_on(self, held: HeldObject) -> tuple[float, float, float]:
        """The lip's centre in the held object's body frame."""
        position, orientation = pb.getBasePositionAndOrientation(
            held.body, physicsClientId=self.client
        )
        inv_pos, inv_orn = pb.invertTransform(position, orientation)
        lip, _ = pb.multiplyTransforms(inv_pos, inv_orn, self.tcp_pose()[0], (0.0, 0.0, 0.0, 1.0))
        return (lip[0], lip[1], lip[2])
