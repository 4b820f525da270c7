"""The pick controller's values: what a tick takes and gives, and the state its parts share.

The pick (:mod:`control.pick`: the phase machine), the intercept planning
(:mod:`control.intercept`) and the motion (:mod:`control.motion`) are three parts of one
controller: they share its current target (:class:`Pursuit`), the state of the motion between
ticks (:class:`MotionState`) and its counters (:class:`PickBook`), each mutable and owned by the
:class:`control.pick.PickController` that builds them. The frozen values (:class:`Command`,
:class:`PickStats`, :class:`TcpMeasurement`, :class:`TickInput`, :class:`Goal`,
:class:`Transition`) pass between the controller and its callers or its handlers.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from control.allocation import Claim
from control.planner import CartesianState, CartesianTarget
from control.poses import JointApproach, JointGoal
from control.tracking import Track
from interfaces.phases import Phase
from interfaces.run_records import PickStats

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]


@dataclass(frozen=True, kw_only=True)
class TcpMeasurement:
    """Measured tool: TCP ``position_m`` ``(x, y, z)`` in the world frame, ``yaw_rad``, and the
    tool's measured command value ``tool_measured`` (a gripper's opening in m, a suction cup's
    vacuum fraction, from its joints; NaN when not measured, which turns off the grip check)."""

    position_m: Vec3
    yaw_rad: float
    tool_measured: float = math.nan


@dataclass(frozen=True, kw_only=True)
class Command:
    """Everything the arm and tool are told in one control tick.

    ``setpoint`` is the Ruckig state, ``commanded_position_m`` the setpoint plus feedback that
    went into the IK, ``joint_positions_rad`` ``(n_arm,)`` is always within the joint limits,
    ``tool_command`` the tool's command (a gripper's opening in m, a cup's vacuum 1 or 0),
    ``grasp_point_m`` is the predicted grasp point of the target (None without a target),
    ``claims`` the station's claims made in this tick (:mod:`control.allocation`).
    """

    t_s: float
    phase: Phase
    target_id: int | None
    setpoint: CartesianState
    commanded_position_m: Vec3
    joint_positions_rad: tuple[float, ...]
    tool_command: float
    grasp_point_m: Vec3 | None
    claims: tuple[Claim, ...] = ()


@dataclass(frozen=True, kw_only=True)
class TickInput:
    """What one pass of the phase machine sees: the time, the tracks and the belt velocity."""

    t_s: float
    tracks: Sequence[Track]
    belt_velocity_mps: tuple[float, float]


@dataclass(frozen=True, kw_only=True)
class Goal:
    """A handler's result: this tick's Ruckig goal, and the target's grasp point (if any)."""

    target: CartesianTarget | JointGoal
    aim_m: Vec3 | None = None
    min_duration_s: float | None = None
    """Reach the Cartesian target no sooner than this (s) from now (None: time-optimal)."""


@dataclass(frozen=True, kw_only=True)
class Transition:
    """A handler switched to ``phase``: its handler runs next, in the same tick.

    It sees ``tracks`` (none after an abort: no new target is chosen in the tick of an abort).
    ``checked``: the target checks already ran in this pass (the approach hands over to the
    descent), so they do not run again before the new handler.
    """

    phase: Phase
    tracks: Sequence[Track]
    checked: bool = False


@dataclass(kw_only=True)
class Pursuit:
    """The current target and what the pick knows about it."""

    target: Track | None = None
    seen_s: float = -math.inf
    grasp_yaw_rad: float
    intercept_estimate_s: float = math.nan
    tracking_start_s: float = math.nan
    carrying: bool = False
    lift_target: CartesianTarget | None = None
    counted: bool = False
    """Whether this pick counted its target as a new one (a grip retry does not)."""
    seal_depth_m: float = 0.0
    """How far below the grasp point the seal search has taken the setpoint."""
    seal_wait_s: float = 0.0
    """How long the close has waited for a seal to start (its deadlines move on by it)."""
    clear_rise_m: float = 0.0
    """How much higher the approach ends to pass over the neighbours (at the pick's start)."""
    overlap_s: float = math.nan
    """When the measured TCP's grasp box came down onto the target (``pick.dwell_from_overlap``;
    NaN: not yet)."""


@dataclass(kw_only=True, eq=False)
class MotionState:
    """State of the motion between ticks: joint-space or Cartesian, and what is left of it."""

    drop_q: FloatArray
    joint_mode: bool = False
    joint_remaining_s: float = 0.0
    yaw_remaining_s: float = 0.0
    meet_s: float = -math.inf
    """When the Cartesian approach plans to be above the target (the scheduler's estimate)."""
    joint_approach: JointApproach | None = None
    ticks_since_command: int = 1


@dataclass(kw_only=True)
class PickBook:
    """Counters of targets and errors, and the tracks that must not be chosen again."""

    targeted: int = 0
    completed: int = 0
    completed_by_class: Counter[str] = field(default_factory=Counter)
    aborted: Counter[str] = field(default_factory=Counter)
    errors: Counter[str] = field(default_factory=Counter)
    untargeted: dict[int, str] = field(default_factory=dict)
    targeted_ids: set[int] = field(default_factory=set)
    excluded: set[int] = field(default_factory=set)
    grip_misses: Counter[int] = field(default_factory=Counter)
    last_error: str = ""

    def error(self, kind: str, message: str) -> None:
        """Count an error of ``kind`` and keep its message."""
        self.errors[kind] += 1
        self.last_error = message


Handler = Callable[[TickInput], Goal | Transition]
"""A phase's handler: the tick's goal, or the phase it switched to."""


__all__ = [
    "Command",
    "FloatArray",
    "Goal",
    "Handler",
    "MotionState",
    "PickBook",
    "PickStats",
    "Pursuit",
    "TcpMeasurement",
    "TickInput",
    "Transition",
    "Vec3",
]
