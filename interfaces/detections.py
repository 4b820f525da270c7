"""What a detector reports: one frame's detections, in the world frame, as value types.

The oracle camera (:mod:`twin.perception`), the camera-based detector (:mod:`detector`) and the
ROS encoders all produce or consume these; the wire form is ``cdw_interfaces/DetectionArray``
(``docs/interfaces.md``), whose field comments define every quantity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Detection", "DetectionFrame", "wrap_half_pi"]


@dataclass(frozen=True)
class Detection:
    """One detected object (world frame). ``z_m`` is its underside: the belt surface, or the top of
    the object it lies on (what a depth camera sees around it). ``suction_point_m`` and
    ``suction_radius_m``: where a round cup fits best on its top face and the largest lip radius
    that fits there (:mod:`twin.suction_point`), ``suction_tilt_rad`` that face's tilt from
    level; NaN when the camera reports none."""

    class_name: str
    confidence: float
    x_m: float
    y_m: float
    z_m: float
    yaw_rad: float
    length_m: float
    width_m: float
    height_m: float
    suction_point_m: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    suction_radius_m: float = math.nan
    suction_tilt_rad: float = math.nan


@dataclass(frozen=True)
class DetectionFrame:
    """The detections of one capture."""

    capture_time_s: float
    release_time_s: float
    detections: tuple[Detection, ...]


def wrap_half_pi(angle_rad: float) -> float:
    """An axis direction folded into (-pi/2, pi/2]."""
    a = math.fmod(angle_rad, math.pi)
    if a <= -math.pi / 2:
        a += math.pi
    elif a > math.pi / 2:
        a -= math.pi
    return a
