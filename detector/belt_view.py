"""How one camera sees the belt plane: depth to height above the belt, pixels to world points.

Built once per camera (intrinsics and pose) and reused for every frame: the per-pixel factor that
turns depth along the optical axis into world height is computed once, so a frame's height image
costs two operations per pixel. Conventions are :mod:`interfaces.camera`'s (REP 103 / 118, poses
``aMb``).
"""

from __future__ import annotations

import numpy as np

from detector.errors import FrameError
from interfaces.camera import Intrinsics


class BeltView:
    """A camera over a horizontal belt whose surface is at world ``z = belt_z_m``.

    ``up`` ``(H, W) float32``: the world z component of each pixel's ray per metre of optical
    depth (negative for a camera looking down), so a pixel at depth ``d`` lies at world
    ``z = d * up + t_z``.
    """

    def __init__(
        self,
        *,
        intrinsics: Intrinsics,
        worldMoptical: np.ndarray,  # noqa: N803 (a pose name, aMb)
        belt_z_m: float,
    ) -> None:
        pose = np.asarray(worldMoptical, dtype=np.float64)
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            msg = f"worldMoptical: expected a finite (4, 4) pose, got shape {pose.shape}"
            raise FrameError(msg)
        self.intrinsics = intrinsics
        self.worldMoptical = pose
        self.belt_z_m = float(belt_z_m)
        k = intrinsics
        rot = pose[:3, :3]
        u = (np.arange(k.width_px, dtype=np.float64) - k.cx_px) / k.fx_px
        v = (np.arange(k.height_px, dtype=np.float64) - k.cy_px) / k.fy_px
        up = rot[2, 0] * u[None, :] + rot[2, 1] * v[:, None] + rot[2, 2]
        self.up: np.ndarray = up.astype(np.float32)
        optical = np.stack(
            np.broadcast_arrays(u[None, :], v[:, None], np.ones((1, 1))), axis=-1
        ).reshape(-1, 3)
        self.rays: np.ndarray = (
            (optical @ rot.T).reshape(k.height_px, k.width_px, 3).astype(np.float32)
        )
        """``(H, W, 3) float32``: each pixel's world direction per metre of optical depth."""
        self._offset_m = np.float32(pose[2, 3] - self.belt_z_m)
        centre = self.up[k.height_px // 2, k.width_px // 2]
        centre_depth = float(-self._offset_m / centre) if centre != 0 else float("nan")
        self.belt_metres_per_px = (
            self.metres_per_px(centre_depth) if centre_depth > 0 else float("nan")
        )
        """The size of a pixel on the belt at the image centre (nan if the centre's ray misses
        the belt), m."""

    def matches(self, intrinsics: Intrinsics, worldMoptical: np.ndarray) -> bool:  # noqa: N803
        """Whether this view was built for that camera (same intrinsics and pose)."""
        return intrinsics == self.intrinsics and np.array_equal(worldMoptical, self.worldMoptical)

    def heights_m(self, depth_m: np.ndarray) -> np.ndarray:
        """Height above the belt of every pixel, ``(H, W) float32`` m (NaN where depth is)."""
        self._check_shape(depth_m)
        out: np.ndarray = depth_m * self.up + self._offset_m
        return out.astype(np.float32, copy=False)

    def belt_depth_m(self) -> np.ndarray:
        """Depth at which each pixel's ray meets the belt plane, ``(H, W) float32`` m (NaN or
        negative where the ray never meets it in front of the camera)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            out: np.ndarray = (-self._offset_m / self.up).astype(np.float32)
        return out

    def point_image_m(self, depth_m: np.ndarray) -> np.ndarray:
        """Every pixel's world point, ``(H, W, 3) float32`` (NaN where depth is NaN)."""
        self._check_shape(depth_m)
        origin = self.worldMoptical[:3, 3].astype(np.float32)
        out: np.ndarray = depth_m[..., None] * self.rays + origin
        return out

    def points_m(self, rows: np.ndarray, cols: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
        """World points of pixels ``(rows[i], cols[i])`` at depths ``depth_m[i]``, ``(n, 3)``."""
        k = self.intrinsics
        d = depth_m.astype(np.float64)
        x = (cols - k.cx_px) / k.fx_px * d
        y = (rows - k.cy_px) / k.fy_px * d
        pts = np.stack((x, y, d), axis=-1)
        out: np.ndarray = pts @ self.worldMoptical[:3, :3].T + self.worldMoptical[:3, 3]
        return out

    def metres_per_px(self, depth_m: float) -> float:
        """The side of one pixel on a surface facing the camera at ``depth_m``, m."""
        return float(depth_m) / float(np.sqrt(self.intrinsics.fx_px * self.intrinsics.fy_px))

    def _check_shape(self, image: np.ndarray) -> None:
        k = self.intrinsics
        if image.shape[:2] != (k.height_px, k.width_px):
            msg = (
                f"depth_m: shape {image.shape} does not match the camera's "
                f"{k.height_px}x{k.width_px} (rows x columns)"
            )
            raise FrameError(msg)


__all__ = ["BeltView"]
