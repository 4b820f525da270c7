"""The fallback renderer: PyBullet's TinyRenderer (CPU, in PyBullet itself, nothing to install).

It draws the PyBullet scene of one client as it is (every body's visual shapes, or its
collision shapes where it has none) in the bodies' visual colours: no photo textures. Its
segmentation mask holds PyBullet body ids; a lookup table turns them into the caller's instance
ids (0 for every body not in the map). The view and projection matrices are built from the
pinhole model so that a world point lands where :func:`interfaces.camera.project` puts it, up to
TinyRenderer's own rasterisation rules (about half a pixel).

About 8 times slower than :class:`twin.camera.gl.GlRenderer` at 640x480 on this project's
machines; it is what a machine without EGL and Mesa renders with.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pybullet as pb

from twin.camera.render_types import CameraView, RenderedImages

__all__ = ["TinyRenderer", "gl_view_matrix", "tiny_projection_matrix"]

LIGHT_DIRECTION = (-0.3, 0.35, 1.0)
"""Towards the light, world frame: as the OpenGL renderer's."""


def gl_view_matrix(worldMoptical: np.ndarray) -> np.ndarray:  # noqa: N803 (a pose name, aMb)
    """OpenGL's eye frame (x right, y up, z backwards) in the world's inverse: ``eyeMworld``
    ``(4, 4)`` of a camera whose optical frame (x right, y down, z forward) is
    ``worldMoptical``."""
    eyeMoptical = np.diag([1.0, -1.0, -1.0, 1.0])  # noqa: N806 (a pose name)
    view: np.ndarray = eyeMoptical @ np.linalg.inv(np.asarray(worldMoptical, dtype=float))
    return view


def tiny_projection_matrix(view: CameraView) -> np.ndarray:
    """The ``(4, 4)`` OpenGL projection of eye-frame points for the pinhole model: pixel
    ``(u, v)`` at ``x_ndc = 2 (u + 0.5) / W - 1``, ``y_ndc = 1 - 2 (v + 0.5) / H`` (row 0 at
    the top, as PyBullet returns images), ``z_ndc`` from -1 at ``near_m`` to 1 at ``far_m``."""
    k = view.intrinsics
    w, h = k.width_px, k.height_px
    near, far = view.near_m, view.far_m
    m = np.zeros((4, 4))
    m[0, 0] = 2.0 * k.fx_px / w
    m[0, 2] = -((2.0 * k.cx_px + 1.0) / w - 1.0)
    m[1, 1] = 2.0 * k.fy_px / h
    m[1, 2] = -(1.0 - (2.0 * k.cy_px + 1.0) / h)
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


class TinyRenderer:
    """Renders one PyBullet client's scene with ``ER_TINY_RENDERER`` (``client`` is passed to
    every call)."""

    def __init__(self, client: int) -> None:
        self.client = client

    def render(self, view: CameraView, body_ids: Mapping[int, int]) -> RenderedImages:
        """Colour, depth and instance ids of the scene from ``view``; ``body_ids`` maps a
        PyBullet body to the instance id its pixels get (every other body: 0)."""
        k = view.intrinsics
        width, height, rgba, depth_buffer, segmentation = pb.getCameraImage(
            k.width_px,
            k.height_px,
            viewMatrix=gl_view_matrix(view.worldMoptical).T.reshape(-1).tolist(),
            projectionMatrix=tiny_projection_matrix(view).T.reshape(-1).tolist(),
            renderer=pb.ER_TINY_RENDERER,
            shadow=0,
            lightDirection=list(LIGHT_DIRECTION),
            lightAmbientCoeff=0.5,
            lightDiffuseCoeff=0.5,
            lightSpecularCoeff=0.05,
            physicsClientId=self.client,
        )
        shape = (height, width)
        colour = np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)
        buffer = np.asarray(depth_buffer, dtype=np.float32).reshape(shape)
        near, far = view.near_m, view.far_m
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = (far * near / (far - (far - near) * buffer)).astype(np.float32)
        depth[buffer >= 1.0] = np.nan
        seg = np.asarray(segmentation, dtype=np.int64).reshape(shape)
        return RenderedImages(
            rgb=np.ascontiguousarray(colour[:, :, :3]),
            depth_m=depth,
            instance_ids=_instance_ids(seg, body_ids),
        )


def _instance_ids(segmentation: np.ndarray, body_ids: Mapping[int, int]) -> np.ndarray:
    """The instance id of every pixel ``(H, W) int32`` from PyBullet's body-id mask (-1:
    nothing), through a lookup table over the body ids."""
    top = max(int(segmentation.max()), max(body_ids, default=0))
    table = np.zeros(top + 2, dtype=np.int32)  # index body + 1: -1 (nothing) is index 0
    for body, instance in body_ids.items():
        if body >= 0:
            table[body + 1] = instance
    ids: np.ndarray = table[np.clip(segmentation, -1, top) + 1]
    return ids
