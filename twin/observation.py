"""What the twin reports of one instant: every arm's state and the ground truth (value types).

:class:`twin.sim.Twin` builds them (and re-exports them); nothing here steps anything.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from interfaces.events import Event
from twin.belt_drive import BeltState
from twin.monitor import GroundTruth

__all__ = ["ArmState", "Observation"]


@dataclass(frozen=True)
class ArmState:
    """One station's arm and tool at one instant (ground truth)."""

    joint_positions: tuple[float, ...]
    joint_velocities: tuple[float, ...]
    tcp_position_m: tuple[float, float, float]
    tcp_orientation_xyzw: tuple[float, float, float, float]
    gripper_width_m: float


@dataclass(frozen=True)
class Observation:
    """What the twin knows at one instant (ground truth); ``arms`` has one entry per station.

    ``joint_positions`` ... ``gripper_width_m`` are the first station's (the only one of a
    one-station cell).
    """

    time_s: float
    step: int
    belt: BeltState
    setpoint_mps: float
    load_mass_kg: float
    objects: tuple[GroundTruth, ...]
    arms: tuple[ArmState, ...]
    events: tuple[Event, ...] = field(default=())

    @property
    def joint_positions(self) -> tuple[float, ...]:
        """The first station's arm joint positions."""
        return self.arms[0].joint_positions

    @property
    def joint_velocities(self) -> tuple[float, ...]:
        """The first station's arm joint velocities."""
        return self.arms[0].joint_velocities

    @property
    def tcp_position_m(self) -> tuple[float, float, float]:
        """The first station's TCP position."""
        return self.arms[0].tcp_position_m

    @property
    def tcp_orientation_xyzw(self) -> tuple[float, float, float, float]:
        """The first station's TCP orientation."""
        return self.arms[0].tcp_orientation_xyzw

    @property
    def gripper_width_m(self) -> float:
        """The first station's measured gripper opening."""
        return self.arms[0].gripper_width_m
