"""What a camera above the belt sees of an object: its footprint's heading and extents from above.

An object is a prism: its footprint (length along the footprint's long axis, width across it)
extruded by its height. Upright (within :data:`UPRIGHT_TILT_RAD`), a camera above sees that
footprint and the height is the extrusion: the recorded measurements are used as they are. Any
other object (a wooden stick rolled onto its side, a brick on its end, a tile propped on
another piece) is seen as a depth camera sees it: of the footprint's long axis, its width axis
and its extrusion axis, the one nearest the vertical is taken as the height's, and the other
two, projected on the belt, give the seen footprint's directions (the longer one its long
axis). The extents are those of the mesh's vertices, turned with the object: the silhouette's
extents along those directions, the height from the lowest vertex to the highest and the
underside at the lowest. A propped piece is therefore as tall as its raised end, not as its
thickness (the controllers came down onto the raised end when it was reported as lying flat).
Pure geometry, no simulator.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

UPRIGHT_TILT_RAD = math.radians(5.0)
"""Up to this tilt of the extrusion axis an object counts as upright (its recorded footprint)."""


@dataclass(frozen=True)
class TopView:
    """The object as seen from above (world frame, m and rad).

    ``yaw_rad`` is the heading of the seen footprint's long axis about the world z axis (not
    wrapped; the axis has no direction), ``length_m`` the footprint's extent along it,
    ``width_m`` across it on the belt plane, ``height_m`` the object's vertical extent and
    ``below_m`` how far its lowest point lies below its centre of mass.
    """

    yaw_rad: float
    length_m: float
    width_m: float
    height_m: float
    below_m: float


def rotation_matrix(quat_xyzw: tuple[float, float, float, float]) -> FloatArray:
    """3x3 rotation matrix of a unit xyzw quaternion."""
    x, y, z, w = quat_xyzw
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def top_view(
    orientation_xyzw: tuple[float, float, float, float],
    footprint_yaw_rad: float,
    *,
    length_m: float,
    width_m: float,
    height_m: float,
    vertices_m: Callable[[], FloatArray],
) -> TopView:
    """The top view of a prism with the body frame's ``orientation_xyzw``.

    In the body frame (origin at the centre of mass, z the extrusion axis) the footprint's long
    axis lies at ``footprint_yaw_rad`` about z; ``length_m``, ``width_m`` and ``height_m`` are
    its recorded extents; ``vertices_m()`` gives its mesh's ``(n, 3)`` vertices, asked for only
    when the object is not upright (reading a mesh is not for every upright object).
    """
    x, y, z, w = orientation_xyzw
    yaw_body = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    recorded = TopView(  # the footprint as meshgen measured it, turned with the body
        yaw_rad=yaw_body + footprint_yaw_rad,
        length_m=length_m,
        width_m=width_m,
        height_m=height_m,
        below_m=0.5 * height_m,
    )
    if 1.0 - 2.0 * (x * x + y * y) >= math.cos(UPRIGHT_TILT_RAD):  # extrusion axis near up
        return recorded
    rotation = rotation_matrix(orientation_xyzw)
    c, s = math.cos(footprint_yaw_rad), math.sin(footprint_yaw_rad)
    axes = rotation @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # unit columns
    vertical = int(np.argmax(np.abs(axes[2])))
    points = vertices_m() @ rotation.T  # world offsets from the centre of mass

    def seen_extent(i: int) -> float:
        heading = axes[:2, i] / max(float(np.hypot(*axes[:2, i])), 1e-12)
        return float(np.ptp(points[:, :2] @ heading))

    long_axis = max((i for i in range(3) if i != vertical), key=seen_extent)
    yaw = math.atan2(float(axes[1, long_axis]), float(axes[0, long_axis]))
    along = np.array([math.cos(yaw), math.sin(yaw)])
    across = np.array([-along[1], along[0]])
    return TopView(
        yaw_rad=yaw,
        length_m=float(np.ptp(points[:, :2] @ along)),
        width_m=float(np.ptp(points[:, :2] @ across)),
        height_m=float(np.ptp(points[:, 2])),
        below_m=float(-points[:, 2].min()),
    )
