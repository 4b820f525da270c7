"""What the camera draws of a running twin: its objects and robot links, their poses, the cell.

The rig (:mod:`twin.camera.rig`) asks PyBullet once per body per frame: an object's
``getBasePositionAndOrientation`` (the pose of its inertial frame, turned back to the mesh
frame by the object's principal-axes rotation), one ``getLinkStates`` call per robot with
forward kinematics (as :meth:`twin.robot.Robot.link_poses`). Quaternions become matrices in one
vectorised step for all bodies.

:class:`TwinObjects` is the one place that reads the twin's object table (which PyBullet body
and which meshgen spec and sampled height each object id has), through the read-only accessors
``object_shape`` and ``body_of`` of :class:`twin.sim_view.CameraSim` (the running twin as the
camera sees it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pybullet as pb

from interfaces.cell import Cell
from twin.objects import ObjectSpec, inertia_of
from twin.scene import LinkVisual, bin_triangles, box_triangles
from twin.sim_view import CameraSim

if TYPE_CHECKING:
    from twin.robot import Robot

__all__ = [
    "RobotLinks",
    "SceneObject",
    "TwinObjects",
    "belt_triangles",
    "floor_triangles",
    "pose_matrices",
    "quat_matrices",
]

FLOOR_HALF_SIZE_M = 10.0
"""Half the side of the floor square drawn under the cell."""


def quat_matrices(quats_xyzw: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(n, 3, 3)`` of unit quaternions ``(n, 4)`` (x, y, z, w)."""
    q = np.asarray(quats_xyzw, dtype=float).reshape(-1, 4)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    m = np.empty((len(q), 3, 3))
    m[:, 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    m[:, 0, 1] = 2.0 * (x * y - z * w)
    m[:, 0, 2] = 2.0 * (x * z + y * w)
    m[:, 1, 0] = 2.0 * (x * y + z * w)
    m[:, 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    m[:, 1, 2] = 2.0 * (y * z - x * w)
    m[:, 2, 0] = 2.0 * (x * z - y * w)
    m[:, 2, 1] = 2.0 * (y * z + x * w)
    m[:, 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return m


def pose_matrices(positions_m: np.ndarray, quats_xyzw: np.ndarray) -> np.ndarray:
    """Homogeneous poses ``(n, 4, 4)`` of positions ``(n, 3)`` and quaternions ``(n, 4)``."""
    rotations = quat_matrices(quats_xyzw)
    m = np.zeros((len(rotations), 4, 4))
    m[:, :3, :3] = rotations
    m[:, :3, 3] = np.asarray(positions_m, dtype=float).reshape(-1, 3)
    m[:, 3, 3] = 1.0
    return m


@dataclass(frozen=True, kw_only=True, eq=False)
class SceneObject:
    """One simulated object: its twin id, PyBullet body, meshgen spec, sampled height (its
    mesh is stretched along z by ``height_m / spec.height_m``) and the rotation of the body's
    inertial frame to the mesh frame, ``inertialMobject`` ``(4, 4)``."""

    object_id: int
    body: int
    spec: ObjectSpec
    height_m: float
    inertialMobject: np.ndarray

    @property
    def mesh_key(self) -> tuple[str, float]:
        """The key of its drawn mesh: one per mesh file and height."""
        return (str(self.spec.mesh_path), self.height_m)


class TwinObjects:
    """The objects of a twin's current episode that are still simulated (spawned, not fallen
    off, not in a bin), in id order. Object ids count up from 1 in spawn order and never come
    back once an object is gone, so each call looks only at the new ids and the live ones."""

    def __init__(self, twin: CameraSim) -> None:
        self.twin = twin
        self._live: dict[int, SceneObject] = {}
        self._next_id = 1

    def live(self) -> list[SceneObject]:
        """Every simulated object now."""
        twin = self.twin
        while (shape := twin.object_shape(self._next_id)) is not None:
            spec, height_m = shape
            body = twin.body_of(self._next_id)
            if body is not None:
                frame = inertia_of(spec, height_m / spec.height_m).frame_quat_xyzw
                inverse = np.eye(4)
                inverse[:3, :3] = quat_matrices(np.array([frame]))[0].T
                self._live[self._next_id] = SceneObject(
                    object_id=self._next_id,
                    body=body,
                    spec=spec,
                    height_m=height_m,
                    inertialMobject=inverse,
                )
            self._next_id += 1
        gone = [i for i in self._live if twin.body_of(i) is None]
        for object_id in gone:
            del self._live[object_id]
        return list(self._live.values())

    def poses(self, objects: list[SceneObject]) -> np.ndarray:
        """The mesh frame of each object in the world, ``(n, 4, 4)`` (one PyBullet query per
        body)."""
        if not objects:
            return np.zeros((0, 4, 4))
        client = self.twin.client
        get = pb.getBasePositionAndOrientation
        states = [get(o.body, physicsClientId=client) for o in objects]
        worldMinertial = pose_matrices(  # noqa: N806 (a pose name)
            np.array([s[0] for s in states]), np.array([s[1] for s in states])
        )
        inertialMobject = np.stack([o.inertialMobject for o in objects])  # noqa: N806
        poses: np.ndarray = worldMinertial @ inertialMobject
        return poses


@dataclass(frozen=True, kw_only=True, eq=False)
class RobotLinks:
    """The drawn links of one robot: their visuals, PyBullet link indices (-1: the root link,
    whose pose is fixed) and the root link's pose ``(4, 4)``."""

    robot: Robot
    visuals: tuple[LinkVisual, ...]
    indices: tuple[int, ...]
    worldMroot: np.ndarray

    @classmethod
    def of(cls, robot: Robot, visuals: tuple[LinkVisual, ...]) -> RobotLinks:
        """The links of ``robot`` that have a visual (from :func:`twin.link_visuals.link_visuals`
        of its URDF); a visual of a link the body lacks is left out."""
        root = robot.root_link
        kept = [v for v in visuals if v.link == root or v.link in robot.links]
        position, orientation = robot.root_pose()
        return cls(
            robot=robot,
            visuals=tuple(kept),
            indices=tuple(-1 if v.link == root else robot.links[v.link] for v in kept),
            worldMroot=pose_matrices(np.array([position]), np.array([orientation]))[0],
        )

    def poses(self) -> np.ndarray:
        """Each drawn link's URDF frame in the world now, ``(k, 4, 4)`` (one ``getLinkStates``
        call with forward kinematics)."""
        moving = [i for i in self.indices if i >= 0]
        out = np.repeat(self.worldMroot[None], len(self.indices), axis=0)
        if moving:
            states = pb.getLinkStates(
                self.robot.body,
                moving,
                computeForwardKinematics=1,
                physicsClientId=self.robot.client,
            )
            frames = pose_matrices(
                np.array([s[4] for s in states]), np.array([s[5] for s in states])
            )
            rows = [k for k, i in enumerate(self.indices) if i >= 0]
            out[rows] = frames
        return out


@dataclass(frozen=True, kw_only=True)
class WorldBodies:
    """The PyBullet bodies of the cell's static scene: belt, floor and bins (with their
    classes, in the cell's order)."""

    belt: int
    floor: int
    bins: tuple[tuple[int, str], ...]


def world_bodies(twin: CameraSim) -> WorldBodies | None:
    """The static bodies of the twin's current episode (None before its first reset)."""
    world = twin.world
    if world is None:
        return None
    classes = [spec.class_name for spec in twin.cell.bins]
    return WorldBodies(
        belt=world.belt, floor=world.floor, bins=tuple(zip(world.bins, classes, strict=True))
    )


def belt_triangles(cell: Cell) -> np.ndarray:
    """The belt as drawn: a box from its start to its end, its width, top at its surface,
    ``(12, 3, 3)`` in the world."""
    belt = cell.belt
    return box_triangles(
        (0.5 * (belt.end_x_m - belt.start_x_m), 0.5 * belt.width_m, 0.5 * belt.thickness_m),
        (
            0.5 * (belt.start_x_m + belt.end_x_m),
            belt.centre_y_m,
            belt.surface_z_m - 0.5 * belt.thickness_m,
        ),
    )


def floor_triangles(cell: Cell) -> np.ndarray:
    """The floor under the cell: a square of side ``2 FLOOR_HALF_SIZE_M`` at its height,
    centred under the belt, ``(2, 3, 3)``."""
    belt, z = cell.belt, cell.physics.floor_z_m
    cx, cy, h = 0.5 * (belt.start_x_m + belt.end_x_m), belt.centre_y_m, FLOOR_HALF_SIZE_M
    corners = np.array(
        [[cx - h, cy - h, z], [cx + h, cy - h, z], [cx + h, cy + h, z], [cx - h, cy + h, z]]
    )
    return np.stack([corners[[0, 1, 2]], corners[[0, 2, 3]]])


def bins_triangles(cell: Cell) -> list[tuple[str, np.ndarray]]:
    """Every bin's class and its floor and walls ``(60, 3, 3)`` in the world."""
    return [(spec.class_name, bin_triangles(spec)) for spec in cell.bins]
