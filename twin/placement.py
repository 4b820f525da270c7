"""Where and how one object enters the belt: a value type of its own.

:mod:`twin.stream` decides the placements, the world spawns them and the monitor keeps each
object's; kept out of the stream so that its readers need not import its behaviour.
"""

from __future__ import annotations

from dataclasses import dataclass

from twin.objects import ObjectSpec


@dataclass(frozen=True)
class Placement:
    """Where and how one object enters the belt (world frame)."""

    spec: ObjectSpec
    position_m: tuple[float, float, float]
    yaw_rad: float
    height_m: float
    friction: float
    restitution: float


__all__ = ["Placement"]
