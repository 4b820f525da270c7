"""The static part of the PyBullet scene: belt, floor, bins; and spawning/removing objects.

The belt is a kinematic body: a fixed-base multibody of mass 0 whose base velocity is the belt
speed. Bullet's contact solver then sees a surface moving at that speed, so objects are carried
by friction (with realistic acceleration and slip), never teleported. The kinematic box really
moves, so it is put back to its home pose whenever it has drifted ``BELT_DRIFT_M`` downstream.
Re-posing clears Bullet's contact manifolds with the belt for one step, which is why it is not
done every step (a manifold rebuilt every step holds a single point and lets objects slip). The
box is longer upstream by the drift, so the infeed is always supported; the belt's downstream end
is exact to within half the drift (+-5 cm).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pybullet as pb

from interfaces.bins import BinSpec
from interfaces.cell import Cell
from twin.collision import merged_collision_file
from twin.errors import SceneError
from twin.objects import ObjectSpec, inertia_of

BELT_DRIFT_M = 0.1


@dataclass(frozen=True)
class SpawnedBody:
    """A PyBullet body made from an object spec.

    PyBullet reports a body's pose as the pose of its inertial (principal-axes) frame; the object
    frame (the mesh frame) is that pose times the inverse of ``inertial_quat_xyzw``.
    """

    body: int
    mass_kg: float
    height_m: float
    inertial_quat_xyzw: tuple[float, float, float, float]


class World:
    """Belt, floor and every station's bins in one PyBullet client; objects are added and
    removed over time."""

    def __init__(self, client: int, cell: Cell, cache_dir: Path) -> None:
        self.client = client
        self.cache_dir = cache_dir
        self.cell = cell
        belt = cell.belt
        box_start_x = belt.start_x_m - BELT_DRIFT_M
        box_end_x = belt.end_x_m - 0.5 * BELT_DRIFT_M
        self._belt_pos = (
            0.5 * (box_start_x + box_end_x),
            belt.centre_y_m,
            belt.surface_z_m - 0.5 * belt.thickness_m,
        )
        shape = pb.createCollisionShape(
            pb.GEOM_BOX,
            halfExtents=[
                0.5 * (box_end_x - box_start_x),
                0.5 * belt.width_m,
                0.5 * belt.thickness_m,
            ],
            physicsClientId=client,
        )
        self.belt = pb.createMultiBody(
            0.0, shape, basePosition=self._belt_pos, physicsClientId=client
        )
        pb.changeDynamics(
            self.belt, -1, lateralFriction=belt.lateral_friction, physicsClientId=client
        )
        floor = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client)
        self.floor = pb.createMultiBody(
            0.0, floor, basePosition=[0.0, 0.0, cell.physics.floor_z_m], physicsClientId=client
        )
        self.bins = [self._make_bin(b) for b in cell.bins]
        self._shapes: dict[tuple[str, float], int] = {}
        self.belt_speed_mps = 0.0
        self._drift_m = 0.0

    def _make_bin(self, config: BinSpec) -> int:
        c = self.client
        half = 0.5 * config.size_m
        wall_h = 0.5 * (config.top_z_m - config.floor_z_m)
        t = 0.5 * config.wall_m
        boxes = [
            ([half, half, t], [0.0, 0.0, -wall_h + t]),
            ([t, half, wall_h], [half - t, 0.0, 0.0]),
            ([t, half, wall_h], [-half + t, 0.0, 0.0]),
            ([half, t, wall_h], [0.0, half - t, 0.0]),
            ([half, t, wall_h], [0.0, -half + t, 0.0]),
        ]
        shape = pb.createCollisionShapeArray(
            shapeTypes=[pb.GEOM_BOX] * len(boxes),
            halfExtents=[b[0] for b in boxes],
            collisionFramePositions=[b[1] for b in boxes],
            physicsClientId=c,
        )
        centre = [config.centre_x_m, config.centre_y_m, config.floor_z_m + wall_h]
        return int(pb.createMultiBody(0.0, shape, basePosition=centre, physicsClientId=c))

    def set_belt_speed(self, speed_mps: float, dt_s: float) -> None:
        """Give the belt surface the velocity ``speed_mps`` along +x for the next ``dt_s``."""
        self._drift_m += speed_mps * dt_s
        moved = abs(self._drift_m) >= BELT_DRIFT_M
        if moved:
            pb.resetBasePositionAndOrientation(
                self.belt, self._belt_pos, (0.0, 0.0, 0.0, 1.0), physicsClientId=self.client
            )
            self._drift_m = speed_mps * dt_s
        if moved or speed_mps != self.belt_speed_mps:  # the body keeps its velocity otherwise
            pb.resetBaseVelocity(
                self.belt, (speed_mps, 0.0, 0.0), (0.0, 0.0, 0.0), physicsClientId=self.client
            )
        self.belt_speed_mps = speed_mps

    def _collision_shape(self, spec: ObjectSpec, z_scale: float) -> int:
        key = (str(spec.collision_path), z_scale)
        shape = self._shapes.get(key)
        if shape is None:
            path = spec.collision_path
            if spec.convex_path is not None:
                physics = self.cell.physics
                path = merged_collision_file(
                    spec.convex_path,
                    self.cache_dir,
                    physics.hull_merge_tolerance,
                    physics.max_convex_pieces,
                )
            try:
                shape = pb.createCollisionShape(
                    pb.GEOM_MESH,
                    fileName=str(path),
                    meshScale=[1.0, 1.0, z_scale],
                    physicsClientId=self.client,
                )
            except pb.error as exc:
                msg = f"{spec.collision_path}: PyBullet cannot build a collision shape: {exc}"
                raise SceneError(msg) from None
            if shape < 0:
                msg = f"{spec.collision_path}: PyBullet cannot build a collision shape"
                raise SceneError(msg)
            self._shapes[key] = shape
        return shape

    def prepare(self, specs: list[ObjectSpec]) -> None:
        """Build collision shapes and inertias ahead of time, so spawning never stalls a step."""
        for spec in specs:
            self._collision_shape(spec, 1.0)
            inertia_of(spec, 1.0)

    def spawn(
        self,
        spec: ObjectSpec,
        position_m: tuple[float, float, float],
        quat_xyzw: tuple[float, float, float, float],
        *,
        height_m: float,
        friction: float,
        restitution: float,
    ) -> SpawnedBody:
        """Add one object; ``height_m`` may differ from the spec's (the mesh is scaled in z)."""
        z_scale = height_m / spec.height_m
        mass_kg = spec.mass_kg * z_scale
        shape = self._collision_shape(spec, z_scale)
        inertia = inertia_of(spec, z_scale)
        body = pb.createMultiBody(
            baseMass=mass_kg,
            baseCollisionShapeIndex=shape,
            basePosition=position_m,
            baseOrientation=quat_xyzw,
            baseInertialFramePosition=[0.0, 0.0, 0.0],
            baseInertialFrameOrientation=inertia.frame_quat_xyzw,
            useMaximalCoordinates=True,
            physicsClientId=self.client,
        )
        moments = list(inertia.principal_kgm2)
        pb.changeDynamics(
            body,
            -1,
            lateralFriction=friction,
            restitution=restitution,
            spinningFriction=0.0,
            rollingFriction=0.0,
            mass=mass_kg,  # PyBullet zeroes a rigid body's mass when only the inertia is given
            localInertiaDiagonal=moments,
            activationState=pb.ACTIVATION_STATE_DISABLE_SLEEPING,  # a stalled belt restarts
            physicsClientId=self.client,
        )
        return SpawnedBody(
            body=body,
            mass_kg=mass_kg,
            height_m=height_m,
            inertial_quat_xyzw=inertia.frame_quat_xyzw,
        )

    def remove(self, body: int) -> None:
        """Take a body out of the simulation."""
        pb.removeBody(body, physicsClientId=self.client)
