"""The fixed filters every camera frame goes through before its detector (the cell's, not learned).

- the belt's region of interest: :func:`belt_plane_depth` says where each pixel's ray meets the
  belt plane and whether that point lies off the belt (beyond :data:`ROI_MARGIN_M` of its edges);
- the robot self-filter: :func:`filtered_frame` sets the pixels of the robots (known from their
  poses: the rig's mask) and of the objects their tools hold (together :func:`occluder_mask`)
  to the belt plane's depth; :func:`occluded_labels` says which instances those pixels border
  (a piece partly under an arm is only partly seen, as one cut by the image's border).

Both the camera source (:mod:`twin.perception_source`) and the overlay pictures
(:mod:`twin.camera.overlay`) filter frames this way.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from interfaces.camera import RgbdCameraSpec, RgbdFrame
from interfaces.cell import BeltSpec

__all__ = [
    "ROI_MARGIN_M",
    "belt_plane_depth",
    "filtered_frame",
    "occluded_labels",
    "occluder_mask",
]

ROI_MARGIN_M = 0.02
"""How far beyond the belt's edges the region of interest reaches (a piece overhanging them)."""


def belt_plane_depth(spec: RgbdCameraSpec, belt: BeltSpec) -> tuple[np.ndarray, np.ndarray]:
    """Where each pixel's ray meets the belt plane: the depth ``(H, W) float32`` (NaN where it
    never does) and whether that point lies off the belt, ``(H, W) bool`` (beyond
    :data:`ROI_MARGIN_M` of its edges)."""
    k = spec.intrinsics
    v, u = np.mgrid[0 : k.height_px, 0 : k.width_px]
    rays = np.stack(((u - k.cx_px) / k.fx_px, (v - k.cy_px) / k.fy_px, np.ones(u.shape)), axis=-1)
    worldMoptical = spec.worldMoptical()  # noqa: N806 (a pose name, aMb)
    direction = rays @ worldMoptical[:3, :3].T
    origin = worldMoptical[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = (belt.surface_z_m - origin[2]) / direction[..., 2]
    depth = np.where(depth > 0, depth, np.nan)
    x = origin[0] + depth * direction[..., 0]
    y = origin[1] + depth * direction[..., 1]
    half = 0.5 * belt.width_m + ROI_MARGIN_M
    with np.errstate(invalid="ignore"):
        off = ~(
            (np.abs(y - belt.centre_y_m) <= half)
            & (x >= belt.start_x_m - ROI_MARGIN_M)
            & (x <= belt.end_x_m + ROI_MARGIN_M)
        )
    return depth.astype(np.float32), off


def occluder_mask(frame: RgbdFrame, robot: np.ndarray, *, held_ids: list[int]) -> np.ndarray:
    """What hides the belt in ``frame`` ``(H, W) bool``: the robots' pixels ``robot`` and the
    objects ``held_ids`` their tools hold."""
    if held_ids and frame.instance_ids is not None:
        return robot | np.isin(frame.instance_ids, held_ids)
    return robot


def filtered_frame(frame: RgbdFrame, mask: np.ndarray, *, belt_depth_m: np.ndarray) -> RgbdFrame:
    """The frame as the detector gets it: the pixels of ``mask`` ``(H, W) bool`` (what hides
    the belt, :func:`occluder_mask`, and what lies off it) set to the belt plane's depth
    ``belt_depth_m`` ``(H, W)`` (nothing stands there), without the truth (``instance_ids``
    None)."""
    depth = np.where(mask, belt_depth_m, frame.depth_m).astype(np.float32)
    return replace(frame, depth_m=depth, instance_ids=None)


def occluded_labels(labels: np.ndarray, occluder: np.ndarray) -> np.ndarray:
    """Which instances of ``labels`` ``(H, W) int`` (0: none) touch ``occluder`` ``(H, W)
    bool``, within one pixel: ``(max label + 1,) bool``. Such an instance may be a piece partly
    under the occluder, seen only in part: its centroid, extents and suction point are those of
    the visible part."""
    out = np.zeros(int(labels.max(initial=0)) + 1, dtype=bool)
    if not occluder.any():
        return out
    near = occluder.copy()
    near[1:] |= occluder[:-1]
    near[:-1] |= occluder[1:]
    near[:, 1:] |= near[:, :-1].copy()
    near[:, :-1] |= near[:, 1:].copy()
    out[labels[near]] = True
    out[0] = False
    return out
