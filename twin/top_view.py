"""What a camera above the belt sees of an object: its footprint's heading and extents from above.

An object is a prism: its footprint (length along the footprint's long axis, width across it)
extruded by its height. Upright, a camera above sees that footprint and the height is the
extrusion. An object that has tipped over (a wooden stick rolled onto its side, a brick on its
end) shows another face: the box's axis nearest the vertical is the one seen as height, the
other two span the seen footprint, the longer of them (as projected on the belt) is its long
axis. Extents are those of the object's oriented bounding box projected on the world axes
(the box is centred on the body origin, the centre of mass), so a slightly tilted object looks
slightly larger, as it would to a camera. Pure geometry, no simulator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TopView:
    """The object as seen from above (world frame, m and rad).

    ``yaw_rad`` is the heading of the seen footprint's long axis about the world z axis (not
    wrapped; the axis has no direction), ``length_m`` the footprint's extent along it,
    ``width_m`` across it on the belt plane, ``height_m`` the object's vertical extent.
    """

    yaw_rad: float
    length_m: float
    width_m: float
    height_m: float


def rotation_matrix(quat_xyzw: tuple[float, float, float, float]) -> np.ndarray:
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
    length_m: float,
    width_m: float,
    height_m: float,
) -> TopView:
    """The top view of a box with the body frame's ``orientation_xyzw``.

    In the body frame the box's long axis lies at ``footprint_yaw_rad`` about z, its width axis
    across it, its height along z.
    """
    c, s = math.cos(footprint_yaw_rad), math.sin(footprint_yaw_rad)
    body_axes = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # unit axes as columns
    axes = rotation_matrix(orientation_xyzw) @ body_axes
    extents = np.array([length_m, width_m, height_m])
    edges = axes * extents  # each column: one edge of the box, world frame
    vertical = int(np.argmax(np.abs(axes[2])))
    flat = [i for i in range(3) if i != vertical]
    long_axis = max(flat, key=lambda i: float(np.hypot(edges[0, i], edges[1, i])))
    yaw = math.atan2(float(edges[1, long_axis]), float(edges[0, long_axis]))
    along = np.array([math.cos(yaw), math.sin(yaw)])
    across = np.array([-along[1], along[0]])
    return TopView(
        yaw_rad=yaw,
        length_m=float(np.sum(np.abs(along @ edges[:2]))),
        width_m=float(np.sum(np.abs(across @ edges[:2]))),
        height_m=float(np.sum(np.abs(edges[2]))),
    )
