"""An object's ground truth and mesh as the monitor reads them from the physics.

The monitor (:mod:`twin.monitor`) keeps one :class:`twin.monitor_records.ObjectRecord` per object
and polls its pose; these turn a record into its :class:`twin.ground_truth.GroundTruth` (reading
its velocity from PyBullet) and give its mesh, read once per shape.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import pybullet as pb

from interfaces.bins import BinSpec
from twin.ground_truth import GroundTruth
from twin.monitor_records import ObjectRecord
from twin.objects import read_obj_triangles
from twin.tools import Pose
from twin.top_view import FloatArray, top_view


def shape_key(record: ObjectRecord) -> tuple[str, float]:
    """Objects with the same key have the same mesh (scaled to the same height)."""
    return (str(record.placement.spec.mesh_path), record.height_m)


def mesh_pose(record: ObjectRecord) -> Pose:
    """The pose of the object's mesh frame, world (its pose as of its last poll)."""
    _, orientation = pb.multiplyTransforms(
        (0.0, 0.0, 0.0), record.orientation, (0.0, 0.0, 0.0), record.inertial_inv
    )
    q = (orientation[0], orientation[1], orientation[2], orientation[3])
    return record.position, q


class MeshCache:
    """Each shape's mesh vertices, read once (:func:`shape_key`)."""

    def __init__(self) -> None:
        self._vertices: dict[tuple[str, float], FloatArray] = {}

    def triangles(self, record: ObjectRecord) -> FloatArray:
        """The object's mesh triangles ``(n, 3, 3)`` in its mesh frame, m (cached)."""
        return self.vertices(record).reshape(-1, 3, 3)

    def vertices(self, record: ObjectRecord) -> FloatArray:
        """The object's mesh vertices ``(3 n, 3)`` in its body frame, m (z scaled to its
        height); cached."""
        spec = record.placement.spec
        key = shape_key(record)
        vertices = self._vertices.get(key)
        if vertices is None:
            vertices = read_obj_triangles(spec.mesh_path).reshape(-1, 3)
            vertices[:, 2] *= record.height_m / spec.height_m
            self._vertices[key] = vertices
        return vertices


def truth_of(
    record: ObjectRecord, *, client: int, vertices: Callable[[], FloatArray]
) -> GroundTruth:
    """The ground truth of a record just polled: its velocity read from PyBullet (``client``)
    while it is simulated, zero once it is not; ``vertices`` gives its mesh for the top view."""
    if record.active:
        lin, ang = pb.getBaseVelocity(record.body, physicsClientId=client)
    else:
        lin, ang = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    spec = record.placement.spec
    scale = record.height_m / spec.height_m
    _, orientation = pb.multiplyTransforms(
        (0.0, 0.0, 0.0), record.orientation, (0.0, 0.0, 0.0), record.inertial_inv
    )
    return GroundTruth(
        id=record.id,
        source_id=spec.object_id,
        class_name=spec.class_name,
        position_m=record.position,
        orientation_xyzw=tuple(orientation),
        linear_velocity_mps=tuple(lin),
        angular_velocity_radps=tuple(ang),
        top_view=top_view(
            orientation,
            spec.yaw_rad,
            length_m=spec.length_m,
            width_m=spec.width_m,
            height_m=record.height_m,
            vertices_m=vertices,
        ),
        length_m=spec.length_m,
        width_m=spec.width_m,
        area_m2=spec.area_m2,
        volume_m3=spec.volume_m3 * scale,
        height_m=record.height_m,
        mass_kg=record.mass_kg,
        on_belt=record.on_belt,
        in_workspace=record.in_workspace,
        held=record.held,
        in_bin=record.in_bin,
    )


def landing(
    records: Iterable[ObjectRecord],
    bin_at: Callable[[float, float], tuple[BinSpec, str] | None],
    *,
    since_step: float,
    client: int,
) -> list[int]:
    """Ids of the simulated objects released over a bin (``bin_at``: the bin under a point)
    at or after step ``since_step`` that have not reached it yet (still above its top): their
    fate is not decided at this instant, so an episode that ends now counts them neither placed
    nor lost. (An object left lying on a bin's rim for longer is not landing.)"""
    ids: list[int] = []
    for record in records:
        if record.held or record.in_bin or record.released_step < since_step:
            continue
        (x, y, z), _ = pb.getBasePositionAndOrientation(record.body, physicsClientId=client)
        over = bin_at(x, y)
        if over is not None and z >= over[0].top_z_m:
            ids.append(record.id)
    return ids


__all__ = ["MeshCache", "landing", "mesh_pose", "shape_key", "truth_of"]
