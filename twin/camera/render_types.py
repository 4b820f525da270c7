"""The values a renderer takes and gives: a camera view, mesh data, instances, rendered images.

Shared by the OpenGL renderer (:mod:`twin.camera.gl`), PyBullet's TinyRenderer fallback
(:mod:`twin.camera.tiny`) and the rig that renders a running twin (:mod:`twin.camera.rig`).
Poses are named ``aMb`` (the 4x4 transform of frame ``b`` in frame ``a``); image conventions are
those of :mod:`interfaces.camera` (row ``v`` down, column ``u`` right, pixel centres at integer
coordinates, depth in metres along the optical axis, NaN where nothing was seen).
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from dataclasses import dataclass

import numpy as np

from interfaces.camera import Intrinsics, RgbdCameraSpec
from twin.camera.errors import RenderError

RGB = tuple[float, float, float]

NEAR_M = 0.02
"""The near clipping distance a view of a camera spec gets by default (closer than any depth
sensor returns anything, so an arm passing under the lens still hides what is behind it)."""


@dataclass(frozen=True, kw_only=True, eq=False)
class CameraView:
    """What one render sees: the pinhole model, the optical frame in the world ``(4, 4)`` and
    the clipping range along the optical axis (m). Nothing nearer than ``near_m`` or farther
    than ``far_m`` is drawn."""

    intrinsics: Intrinsics
    worldMoptical: np.ndarray
    near_m: float
    far_m: float

    def __post_init__(self) -> None:
        if not (0.0 < self.near_m < self.far_m and math.isfinite(self.far_m)):
            msg = f"near_m = {self.near_m!r}, far_m = {self.far_m!r}: need 0 < near_m < far_m"
            raise RenderError(msg)
        pose = np.asarray(self.worldMoptical, dtype=float)
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            msg = f"worldMoptical: a finite (4, 4) pose is needed, not shape {pose.shape}"
            raise RenderError(msg)

    @classmethod
    def of(cls, spec: RgbdCameraSpec, near_m: float = NEAR_M) -> CameraView:
        """The view of a cell's camera: its intrinsics and optical frame, drawn from ``near_m``
        to its ``depth_max_m`` (the sensor returns nothing beyond)."""
        return cls(
            intrinsics=spec.intrinsics,
            worldMoptical=spec.worldMoptical(),
            near_m=min(near_m, 0.5 * spec.depth_min_m),
            far_m=spec.depth_max_m,
        )


SIDE_UV_INSET = 0.25
"""How far a side wall's texture coordinates move from the outline towards the uv's mean
(:meth:`MeshData.corner_texture_coordinates`)."""

SIDE_MAX_COS = 0.5
"""A face whose normal's z component (mesh frame, unit normal) is below this is a side wall."""


@dataclass(frozen=True, kw_only=True, eq=False)
class MeshData:
    """A mesh to upload once: ``vertices_m`` ``(n, 3) float`` in its own frame, ``faces``
    ``(m, 3) int`` (0-based), optional texture coordinates ``uv`` ``(n, 2) float`` and the key of
    an uploaded texture, multiplied by ``rgb``. Without ``uv`` the mesh is drawn in ``rgb``
    (with ``texture``, its uv are planar: x and y over ``planar_period_m``)."""

    vertices_m: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None = None
    texture: Hashable | None = None
    rgb: RGB = (1.0, 1.0, 1.0)
    planar_period_m: float = 0.2

    def __post_init__(self) -> None:
        vertices = np.asarray(self.vertices_m)
        faces = np.asarray(self.faces)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or not np.isfinite(vertices).all():
            msg = f"vertices_m: finite (n, 3) coordinates needed, not shape {vertices.shape}"
            raise RenderError(msg)
        if faces.ndim != 2 or faces.shape[1] != 3 or not len(faces):
            msg = f"faces: an (m, 3) index array with m > 0 needed, not shape {faces.shape}"
            raise RenderError(msg)
        if faces.min() < 0 or faces.max() >= len(vertices):
            msg = f"faces: index {int(faces.max())} or {int(faces.min())} is outside the vertices"
            raise RenderError(msg)
        if self.uv is not None and np.asarray(self.uv).shape != (len(vertices), 2):
            msg = f"uv: shape {np.asarray(self.uv).shape} needed ({len(vertices)}, 2)"
            raise RenderError(msg)
        if not self.planar_period_m > 0.0:
            msg = f"planar_period_m = {self.planar_period_m!r}: must be positive"
            raise RenderError(msg)

    def texture_coordinates(self) -> np.ndarray:
        """The uv ``(n, 2) float32`` drawn: the mesh's own, else planar from x and y."""
        if self.uv is not None:
            return np.asarray(self.uv, dtype=np.float32)
        xy = np.asarray(self.vertices_m, dtype=np.float64)[:, :2] / self.planar_period_m
        return xy.astype(np.float32)

    def face_normals(self) -> np.ndarray:
        """Every face's unit normal ``(m, 3) float64`` (mesh frame; zero for a face of no
        area)."""
        corners = np.asarray(self.vertices_m, dtype=np.float64)[np.asarray(self.faces)]
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        lengths = np.linalg.norm(normals, axis=1, keepdims=True)
        out: np.ndarray = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
        return out

    def corner_texture_coordinates(self, normals: np.ndarray | None = None) -> np.ndarray:
        """The uv of every face corner, ``(3 m, 2) float32`` (face by face): the vertex's, but
        on a side wall of a mesh with its own uv (a face whose normal is more than 60 degrees
        from the mesh's z, its extrusion axis) drawn from :data:`SIDE_UV_INSET` of the way in
        from the outline towards the uv's mean.

        A meshgen prism's every vertex carries the photo pixel of its polygon's corner (the top
        shows the photo), so a side wall would show the photo's pixels along the outline, half
        of them the belt or a neighbour the annotator drew around: a piece tipped onto its side
        would show a dark or foreign streak, which a camera's classifier (and a person) reads as
        another material. A broken piece's sides are its own material: this draws them with
        the piece's pixels just inside its outline. ``normals``: :meth:`face_normals`, when
        the caller has them."""
        corners = np.asarray(self.faces, dtype=np.int64).reshape(-1)
        uv = self.texture_coordinates()
        out = uv[corners]
        if self.uv is None:
            return out
        if normals is None:
            normals = self.face_normals()
        z = np.abs(normals[:, 2])
        side = (z < SIDE_MAX_COS) & np.any(normals != 0.0, axis=1)
        if side.any():
            centre = uv.mean(axis=0)
            corner_side = np.repeat(side, 3)
            out[corner_side] = centre + (out[corner_side] - centre) * (1.0 - SIDE_UV_INSET)
        return out


@dataclass(frozen=True, kw_only=True, eq=False)
class Instance:
    """One thing to draw: an uploaded mesh at ``worldMobject`` ``(4, 4)``, written as
    ``instance_id`` into the id image (0: not an object)."""

    mesh: Hashable
    worldMobject: np.ndarray
    instance_id: int = 0


@dataclass(frozen=True, kw_only=True, eq=False)
class RenderedImages:
    """One render: ``rgb`` ``(H, W, 3) uint8``; ``depth_m`` ``(H, W) float32`` along the
    optical axis, NaN where nothing was drawn; ``instance_ids`` ``(H, W) int32``, 0 where no
    object was drawn."""

    rgb: np.ndarray
    depth_m: np.ndarray
    instance_ids: np.ndarray


__all__ = [
    "NEAR_M",
    "RGB",
    "SIDE_MAX_COS",
    "SIDE_UV_INSET",
    "CameraView",
    "Instance",
    "MeshData",
    "RenderedImages",
]
