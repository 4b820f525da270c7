"""The true state of one object, as the monitor observes it: a value type of its own.

:class:`twin.monitor.Monitor` builds these after a step; the node publishes them
(``/objects/ground_truth``, the scene), perception and the suction-point model read them.
Kept out of the monitor so that readers need not import its behaviour.
"""

from __future__ import annotations

from dataclasses import dataclass

from twin.top_view import TopView


@dataclass(frozen=True)
class GroundTruth:
    """The true state of one object (world frame, SI units).

    ``orientation_xyzw`` is the object (mesh) frame's; ``length_m``, ``width_m`` and ``height_m``
    are the object's own extents (footprint and extrusion, whatever way it lies); ``top_view`` is
    what a camera above sees: the heading and extents of the face turned up. ``in_workspace``:
    in some station's pick window; ``held``: by some station's tool.
    """

    id: int
    source_id: str
    class_name: str
    position_m: tuple[float, float, float]
    orientation_xyzw: tuple[float, float, float, float]
    linear_velocity_mps: tuple[float, float, float]
    angular_velocity_radps: tuple[float, float, float]
    top_view: TopView
    length_m: float
    width_m: float
    area_m2: float
    volume_m3: float
    height_m: float
    mass_kg: float
    on_belt: bool
    in_workspace: bool
    held: bool
    in_bin: bool


__all__ = ["GroundTruth"]
