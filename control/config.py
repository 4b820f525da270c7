"""Controller configuration: the station it drives (from the cell file) and its tuning.

What the cell *is* comes from the cell description both processes read
(:mod:`interfaces.cell`): the station's robot, tool, base pose, pick window and bins, the belt,
the physics step and the classes. The controller's parameter file holds only how it behaves,
in the layout ROS 2 uses for node parameters::

    controller:
      ros__parameters:
        tracking: {...}
        ik: {...}
        motion: {...}
        pick: {...}
        scheduler: {...}
        node: {...}

Every key is optional (the defaults are the reference tuning), unknown keys are errors, and
every error names the file and the dotted key that was wrong. A key that moved to the cell file
(``robot``, ``belt``, ``bins``, ...) is refused with a message saying where it lives now.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from functools import cache
from pathlib import Path
from typing import Any, Literal, cast

from control.errors import ControlConfigError
from control.tools import ControllerTool, GraspTiming, make_tool
from interfaces.cell import BeltSpec, Cell, StationSpec, default_cell
from interfaces.dataclass_io import from_data
from interfaces.errors import ConfigError, cut, cut_message
from interfaces.robots import RobotSpec
from interfaces.yamlio import load_yaml_file

Vec3 = tuple[float, float, float]

PARAMS_DIR = Path(__file__).resolve().parent / "config"
"""The shipped controller parameter files (``default``, ``throughput``, ``line``, ...)."""

DEFAULT_PARAMS = PARAMS_DIR / "default.yaml"
"""The reference cell's parameter file."""


def _require(condition: bool, key: str, value: object, requirement: str) -> None:
    if not condition:
        msg = f"{key} = {value!r}: {requirement}"
        raise ControlConfigError(msg)


@dataclass(frozen=True, kw_only=True)
class TrackingConfig:
    """Kalman tracking: noise models, gating, birth and death.

    ``process_accel_std_mps2`` is the white-noise acceleration of the constant-velocity model,
    ``initial_velocity_std_mps`` the spread of a new track's velocity around the belt velocity.
    ``gate_mahalanobis_sq`` is the squared Mahalanobis gate (9.21 is the 99 % chi-square, 2 dof).
    A track is confirmed after ``confirm_hits`` updates and deleted after ``max_coast_s``
    without one.
    ``smoothing`` is the exponential weight of a new yaw/size measurement.
    """

    min_confidence: float = 0.0
    position_std_m: float = 0.002
    process_accel_std_mps2: float = 0.01
    initial_velocity_std_mps: float = 0.05
    gate_mahalanobis_sq: float = 16.0
    gate_min_m: float = 0.01
    confirm_hits: int = 3
    max_coast_s: float = 0.3
    smoothing: float = 0.2

    def __post_init__(self) -> None:
        """Validate every field."""
        for name in (
            "position_std_m",
            "process_accel_std_mps2",
            "initial_velocity_std_mps",
            "gate_mahalanobis_sq",
            "max_coast_s",
        ):
            value = cast(float, getattr(self, name))
            _require(value > 0.0 and math.isfinite(value), f"tracking.{name}", value, "must be > 0")
        _require(self.gate_min_m >= 0.0, "tracking.gate_min_m", self.gate_min_m, "must be >= 0")
        _require(self.confirm_hits >= 1, "tracking.confirm_hits", self.confirm_hits, "must be >= 1")
        _require(
            0.0 < self.smoothing <= 1.0, "tracking.smoothing", self.smoothing, "must be in (0, 1]"
        )


@dataclass(frozen=True, kw_only=True)
class IkConfig:
    """Damped-least-squares IK: ``log6`` error tolerance, damping, step and iteration limit.

    Iterations stop below ``tolerance``; a solution is accepted below ``accept_tolerance``
    (1e-4 of the ``log6`` norm: 0.1 mm, 0.1 mrad) when the iteration limit comes first. Warm
    started from the last solution, a reachable pose converges in 2 to 11 iterations (default
    and suction-throughput episodes); a pose that has not after ``max_iterations`` is beyond
    the arm, and more iterations only cost time (about 30 us each).
    """

    tolerance: float = 1e-9
    accept_tolerance: float = 1e-4
    damping: float = 1e-8
    step: float = 1.0
    max_iterations: int = 30
    max_joint_step_rad: float = 0.5

    def __post_init__(self) -> None:
        """Validate every field."""
        for name in ("tolerance", "accept_tolerance", "step", "max_joint_step_rad"):
            value = cast(float, getattr(self, name))
            _require(value > 0.0, f"ik.{name}", value, "must be > 0")
        _require(self.damping >= 0.0, "ik.damping", self.damping, "must be >= 0")
        _require(self.max_iterations >= 1, "ik.max_iterations", self.max_iterations, "must be >= 1")


@dataclass(frozen=True, kw_only=True)
class MotionConfig:
    """Cartesian trajectory limits for (x, y, z, yaw) and the feedback on the tracking error.

    ``feedback_kp`` (1) and ``feedback_ki_per_s`` (1/s) act on setpoint minus measured TCP
    position while following an object; the correction is clipped to ``feedback_max_m``.
    ``transfer_speed_scale`` (0, 1] scales the URDF joint velocity limits for the joint-space
    carry and return moves (their acceleration and jerk limits are the robot's, from the cell).
    ``command_latency_s`` is the time between computing a command and the measured TCP
    reflecting it; targets are predicted that far ahead and the feedback compares the measured
    TCP with the setpoint of that long ago.
    ``joint_velocity_margin`` scales the URDF joint velocity limits that bound every per-tick
    joint step of the Cartesian moves (a faster IK solution is approached at that speed).
    ``posture_acceleration_margin`` in (0, 1] scales every Cartesian move's acceleration limits
    down, where the current posture needs it, so that no joint needs more than this fraction of
    its datasheet acceleration to follow them (near the base and at the edge of the reach a
    vertical tool's height takes large shoulder and elbow accelerations: a descent the joints
    cannot follow lags, then overshoots the grasp point catching up); 0 (the default) leaves
    the limits as they are. It budgets every axis at its limit at once; in the descent, where
    the tool follows the object at its constant velocity and mostly goes down,
    ``vertical_posture_axes`` (x, y, z, yaw in [0, 1]) says which share of each axis's limit the
    budget counts (all 1: the same budget as every other move); the same in the lift.
    """

    control_period_s: float = 1.0 / 120.0
    command_latency_s: float = 0.01
    max_velocity: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 2.4)
    max_acceleration: tuple[float, float, float, float] = (2.5, 2.5, 2.5, 20.0)
    max_jerk: tuple[float, float, float, float] = (60.0, 60.0, 60.0, 400.0)
    feedback_kp: float = 0.5
    feedback_ki_per_s: float = 5.0
    feedback_max_m: float = 0.03
    transfer_speed_scale: float = 0.9
    joint_velocity_margin: float = 1.0
    posture_acceleration_margin: float = 0.0
    vertical_posture_axes: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        """Validate every field."""
        _require(
            self.control_period_s > 0.0,
            "motion.control_period_s",
            self.control_period_s,
            "must be > 0",
        )
        _require(
            self.command_latency_s >= 0.0,
            "motion.command_latency_s",
            self.command_latency_s,
            "must be >= 0",
        )
        for name in ("max_velocity", "max_acceleration", "max_jerk"):
            value = cast(tuple[float, ...], getattr(self, name))
            _require(
                all(v > 0.0 and math.isfinite(v) for v in value),
                f"motion.{name}",
                value,
                "every component must be finite and > 0",
            )
        _require(
            0.0 < self.transfer_speed_scale <= 1.0,
            "motion.transfer_speed_scale",
            self.transfer_speed_scale,
            "must be in (0, 1]",
        )
        for name in ("feedback_kp", "feedback_ki_per_s", "feedback_max_m"):
            scalar = cast(float, getattr(self, name))
            _require(scalar >= 0.0, f"motion.{name}", scalar, "must be >= 0")
        _require(
            self.joint_velocity_margin > 0.0,
            "motion.joint_velocity_margin",
            self.joint_velocity_margin,
            "must be > 0",
        )
        _require(
            0.0 <= self.posture_acceleration_margin <= 1.0,
            "motion.posture_acceleration_margin",
            self.posture_acceleration_margin,
            "must be in [0, 1] (0: off)",
        )
        _require(
            len(self.vertical_posture_axes) == 4
            and all(0.0 <= v <= 1.0 for v in self.vertical_posture_axes),
            "motion.vertical_posture_axes",
            self.vertical_posture_axes,
            "must be four numbers in [0, 1] (x, y, z, yaw)",
        )


APPROACH_SPACES = ("cartesian", "joint")
"""Values of ``pick.approach_space``."""


@dataclass(frozen=True, kw_only=True)
class PickConfig:
    """Pick sequence geometry and timing.

    A gripper's grasp point is ``grasp_below_top_m`` below the object's top (the Panda's palm
    touches the object when the TCP is lower than about 2 cm below the top), but not below
    ``height * grasp_height_fraction`` nor ``min_grasp_height_m`` above the belt surface:
    ``surface_z + max(height - grasp_below_top_m, height * grasp_height_fraction,
    min_grasp_height_m)``. A suction cup's is on the top, ``top_press_m`` into it so that the
    lip seals (:meth:`control.tools.ControllerTool.grasp_height_m`). The approach ends
    ``approach_height_m`` above the grasp point.
    ``arrive_tolerance_m`` and ``arrive_speed_tolerance_mps`` decide when a Ruckig segment has
    caught its moving target; the descent starts once the yaw is within ``yaw_tolerance_rad``
    of the grasp yaw or will be within ``descend_yaw_lead_s`` (the fingertips are still above
    the object then), and the gripper closes only once the yaw is within the tolerance.
    The next target is chosen at the ready pose, or ``schedule_before_ready_s`` before the return
    move reaches it (a pursuit starts near the belt, not from the bin).
    ``ik_failures_to_abort`` consecutive IK failures (the last command held meanwhile) abort a
    pick.
    ``close_overlap_s`` of the gripper's ``close_s`` overlap the end of the dwell: the twin's
    grasp rule (the reference's) counts the dwell from the TCP's overlap with the object and
    checks the fingers' grip at its end, so a gripper that starts closing that much earlier holds
    the object as the dwell ends instead of ``close_s`` later (0: close after the dwell).
    ``approach_space`` is ``"cartesian"`` (the default: the next target is chosen at the ready
    pose, or ``schedule_before_ready_s`` before the return reaches it, and approached in a
    straight Cartesian line) or ``"joint"`` (throughput first: the next target is chosen as soon
    as the release ends, and the return goes straight to the predicted meeting point above it
    as one joint-space move that arrives with the object's velocity; the Cartesian approach
    takes over for the last correction). ``"joint"`` skips the ready pose and shortens the
    cycle; the pursuit, and so the tracking time, then starts at the bin.
    ``lost_timeout_s`` aborts an approach whose target track vanished for that long (later
    phases extrapolate it with the belt velocity). ``grip_squeeze_m`` is how much narrower than
    the object the gripper is commanded to close.
    ``drop_tolerance_m``: the release point may lie this far from the bin's drop point along x
    and y (less half the object's length).
    ``ready_tcp_position_m`` (base frame; empty: the robot's ``ready_tcp_position_m``): where
    the arm waits for its next target, pointing down with the robot's ready yaw; nearer the
    belt and the window's entry, every pursuit from it is shorter.
    ``dwell_from_overlap``: a jaw's dwell counts from when the measured TCP's grasp box first
    reaches onto the target on the way down (as the twin's grasp rule counts it), not from the
    end of the descent (:meth:`control.pick.PickController._note_overlap`).
    ``approach_clear_radius_m`` (0: off): the approach ends at least ``approach_clear_m`` above
    the top of every other object whose footprint comes this near the grasp point
    (:func:`control.scheduler.clearance_rise_m`), not only above the target's.
    ``handover_tolerance_m`` (joint approach; 0: off): when the joint-space move ends with the
    setpoint this near the moving target (and moving with it), the descent starts at once,
    without waiting for the joint command to settle on the Cartesian setpoint (the descent
    itself corrects the last millimetres on the way down).

    The waits come from the tool (:meth:`control.tools.ControllerTool.timing`): a gripper's are
    ``dwell_s``, ``close_s``, ``close_overlap_s`` and ``release_s``; a suction cup does not
    dwell, waits its build-up plus ``seal_margin_s`` for the seal and vents for its ``vent_s``
    plus ``vent_margin_s`` over the bin.

    Seal search (a tool that measures its grasp, a suction cup, with ``seal_search_m`` > 0):
    while the cup reads no vacuum at all during its close, nothing touches the lip yet, so the
    close waits (its deadlines move on, up to ``seal_search_max_s`` in all) and, once the
    measured TCP is within ``seal_search_settled_m`` of the setpoint's height (the arm has
    caught up), the setpoint goes down at ``seal_search_speed_mps``, at most ``seal_search_m``
    below the grasp point: as a picker lowers its bellows cup until its vacuum switch reacts,
    for an arm still on its way down or a top lower than seen.

    Grip check (skipped when ``joint_states`` carries no tool joints): when the close ends,
    and through the lift, a tool that holds nothing by its measurement (a gripper measured within
    ``grip_check_margin_m`` of its grasp command, a cup whose vacuum did not build up) aborts the
    pick as ``grip_missed`` and the object may be targeted ``grip_retries`` more times.
    """

    approach_height_m: float = 0.06
    ik_failures_to_abort: int = 3
    schedule_before_ready_s: float = 0.1
    grasp_below_top_m: float = 0.02
    grasp_height_fraction: float = 0.5
    min_grasp_height_m: float = 0.01
    lift_height_m: float = 0.2
    dwell_s: float = 0.6
    close_s: float = 0.25
    close_overlap_s: float = 0.0
    release_s: float = 0.25
    drop_tolerance_m: float = 0.08
    arrive_tolerance_m: float = 0.005
    arrive_speed_tolerance_mps: float = 0.1
    yaw_tolerance_rad: float = 0.02
    descend_yaw_lead_s: float = 0.1
    lost_timeout_s: float = 0.3
    grip_squeeze_m: float = 0.01
    grip_check_margin_m: float = 0.001
    grip_retries: int = 1
    approach_space: Literal["cartesian", "joint"] = "cartesian"
    top_press_m: float = 0.003
    seal_margin_s: float = 0.05
    vent_margin_s: float = 0.05
    seal_search_m: float = 0.0
    seal_search_speed_mps: float = 0.04
    seal_search_max_s: float = 0.3
    seal_search_settled_m: float = 0.002
    handover_tolerance_m: float = 0.0
    ready_tcp_position_m: tuple[float, ...] = ()
    approach_clear_radius_m: float = 0.0
    approach_clear_m: float = 0.02
    dwell_from_overlap: bool = False

    def __post_init__(self) -> None:
        """Validate every field."""
        _require(
            self.approach_space in APPROACH_SPACES,
            "pick.approach_space",
            self.approach_space,
            f"must be one of {', '.join(APPROACH_SPACES)}",
        )
        _require(
            len(self.ready_tcp_position_m) in (0, 3)
            and all(math.isfinite(v) for v in self.ready_tcp_position_m),
            "pick.ready_tcp_position_m",
            self.ready_tcp_position_m,
            "must be empty (the robot's ready pose) or three finite numbers (m, base frame)",
        )
        for item in fields(self):
            if item.name in ("approach_space", "ready_tcp_position_m"):
                continue
            value = cast(float, getattr(self, item.name))
            _require(value >= 0.0 and math.isfinite(value), f"pick.{item.name}", value, ">= 0")
        _require(
            self.grasp_height_fraction <= 1.0,
            "pick.grasp_height_fraction",
            self.grasp_height_fraction,
            "must be in [0, 1]",
        )
        _require(
            self.close_overlap_s <= min(self.dwell_s, self.close_s),
            "pick.close_overlap_s",
            self.close_overlap_s,
            f"must not exceed dwell_s ({self.dwell_s}) nor close_s ({self.close_s})",
        )


RANKS = ("urgency", "cycle")
"""Values of ``scheduler.rank``."""


@dataclass(frozen=True, kw_only=True)
class SchedulerConfig:
    """Target selection: class priorities (larger is picked first) and safety margins.

    ``class_priorities`` overrides the priority of some of the cell's classes (the others get
    1.0). ``max_reach_m`` bounds the distance from the robot base to a grasp point, and
    ``min_reach_m`` from below (a tool on a long stem held vertical near the base needs the
    arm folded beyond its joint speeds and limits, as it does stretched at full reach);
    ``grasp_width_margin_m`` is the margin of the tool's size check
    (:meth:`~control.tools.ControllerTool.misfit`): what an object's narrow side must leave of a
    gripper's opening, what it must have to spare around a suction cup's lip;
    ``time_margin_s`` is added to every intercept estimate. ``clearance_m`` grows the
    footprints the tool needs free around a grasp (:meth:`ControllerTool.footprints`).
    ``rank`` orders the candidates after the class priority: ``urgency`` (the least time left
    in the window first, so that fewer objects pass) or ``cycle`` (the least time to meet the
    object and carry it to its bin first, so that more objects are picked per minute; objects
    near the end of the window are left to stations downstream).
    ``settle_tolerance_mps``: a track whose velocity differs from the belt's measured one by
    more than this is left ``unsettled`` until it agrees (:func:`control.scheduler.unsettled`;
    unset: every track counts as settled).
    ``replan_period_s``: a station that found no target looks again only that much later (0:
    every control update); with joint-space approaches every candidate's meeting is an IK
    solve and a joint plan, and the tracks change only with the camera's frames.
    ``base_turn_fraction`` (0: off): the fraction of the first joint's datasheet velocity that
    following a target past the base may take (:func:`control.scheduler._followable`); a target
    that needs more is ``out_of_reach``.
    ``check_mass``: leave ``too_heavy`` an object the tool could not carry at
    ``carry_acceleration_mps2`` (:func:`control.scheduler.holds_estimate`), its mass estimated
    from its seen box, ``fill_fraction`` full, and its class's density: the cell's class table's
    (``materials:``, the dataset's in a run's resolved cell), or ``class_density_kg_m3``'s, an
    explicit override per class; without ``check_mass`` only the classes that names are
    checked.
    """

    class_priorities: dict[str, float] = field(default_factory=dict)
    max_reach_m: float = 0.8
    min_reach_m: float = 0.0
    grasp_width_margin_m: float = 0.015
    time_margin_s: float = 0.05
    min_confidence: float = 0.3
    clearance_m: float = 0.008
    rank: Literal["urgency", "cycle"] = "urgency"
    check_mass: bool = False
    class_density_kg_m3: dict[str, float] = field(default_factory=dict)
    fill_fraction: float = 0.85
    carry_acceleration_mps2: float = 10.0
    settle_tolerance_mps: float = math.inf
    replan_period_s: float = 0.0
    base_turn_fraction: float = 0.0

    def __post_init__(self) -> None:
        """Validate every field."""
        _require(
            0.0 <= self.base_turn_fraction <= 1.0,
            "scheduler.base_turn_fraction",
            self.base_turn_fraction,
            "must be in [0, 1] (0: off)",
        )
        _require(
            self.replan_period_s >= 0.0 and math.isfinite(self.replan_period_s),
            "scheduler.replan_period_s",
            self.replan_period_s,
            "must be finite and >= 0",
        )
        _require(
            self.rank in RANKS, "scheduler.rank", self.rank, f"must be one of {', '.join(RANKS)}"
        )
        _require(
            self.settle_tolerance_mps > 0.0,
            "scheduler.settle_tolerance_mps",
            self.settle_tolerance_mps,
            "must be > 0 (unset: every track counts as settled)",
        )
        for name, value in self.class_density_kg_m3.items():
            _require(
                value > 0.0 and math.isfinite(value),
                f"scheduler.class_density_kg_m3.{name}",
                value,
                "must be finite and > 0",
            )
        _require(
            0.0 < self.fill_fraction <= 1.0,
            "scheduler.fill_fraction",
            self.fill_fraction,
            "must be in (0, 1]",
        )
        _require(
            self.carry_acceleration_mps2 >= 0.0 and math.isfinite(self.carry_acceleration_mps2),
            "scheduler.carry_acceleration_mps2",
            self.carry_acceleration_mps2,
            "must be finite and >= 0",
        )
        _require(
            self.clearance_m >= 0.0 and math.isfinite(self.clearance_m),
            "scheduler.clearance_m",
            self.clearance_m,
            "must be finite and >= 0",
        )
        for name, value in self.class_priorities.items():
            _require(
                math.isfinite(value), f"scheduler.class_priorities.{name}", value, "must be finite"
            )
        _require(self.max_reach_m > 0.0, "scheduler.max_reach_m", self.max_reach_m, "must be > 0")
        _require(
            0.0 <= self.min_reach_m < self.max_reach_m,
            "scheduler.min_reach_m",
            self.min_reach_m,
            "must be >= 0 and below scheduler.max_reach_m",
        )
        _require(self.time_margin_s >= 0.0, "scheduler.time_margin_s", self.time_margin_s, ">= 0")


ALLOCATION_STRATEGIES = ("first_fit", "class_priority", "tool_fit")
"""Values of ``allocation.strategy`` (:mod:`control.allocation`)."""


@dataclass(frozen=True, kw_only=True)
class AllocationConfig:
    """How the stations of a line share the stream (:mod:`control.allocation`).

    ``strategy``: ``first_fit`` (never target what another station claimed, else anything the
    tool can pick), ``class_priority`` (also leave an object of a class this station does not
    prefer to a downstream station that prefers it and can pick it) or ``tool_fit`` (also leave
    an object to a downstream station whose tool fits it by ``fit_advantage_m`` more).
    ``preferred_classes`` names, per station of the cell, the classes it prefers (a station not
    named prefers the classes only it has bins for, if any). A claim whose object is predicted
    more than ``claim_expiry_m`` past the claiming station's window is stale (its controller
    is gone) and ignored. A claim covers another station's track within its radius, half the
    object's narrow side but at least ``min_claim_radius_m``.
    """

    strategy: Literal["first_fit", "class_priority", "tool_fit"] = "first_fit"
    preferred_classes: dict[str, tuple[str, ...]] = field(default_factory=dict)
    fit_advantage_m: float = 0.02
    claim_expiry_m: float = 0.3
    min_claim_radius_m: float = 0.01

    def __post_init__(self) -> None:
        """Validate every field."""
        _require(
            self.strategy in ALLOCATION_STRATEGIES,
            "allocation.strategy",
            self.strategy,
            f"must be one of {', '.join(ALLOCATION_STRATEGIES)}",
        )
        for name in ("fit_advantage_m", "claim_expiry_m", "min_claim_radius_m"):
            value = cast(float, getattr(self, name))
            _require(
                value >= 0.0 and math.isfinite(value), f"allocation.{name}", value, "must be >= 0"
            )


@dataclass(frozen=True, kw_only=True)
class NodeConfig:
    """The ROS 2 node around the pure controller.

    The control update runs every ``motion.control_period_s`` over the cell's physics step
    (one ``/joint_states`` message and one lockstep tick per step), which must be a whole
    number. ``target_refresh_every`` and ``gripper_refresh_every`` repeat an unchanged
    ``controller/target`` or ``gripper/command`` every that many control updates (a change is
    always sent at once). ``log_throttle_s`` is the least time between two log lines about the
    same kind of bad input (wall clock, logging only).
    """

    target_refresh_every: int = 12
    gripper_refresh_every: int = 12
    log_throttle_s: float = 2.0

    def __post_init__(self) -> None:
        """Validate every field."""
        for name in ("target_refresh_every", "gripper_refresh_every"):
            value = cast(int, getattr(self, name))
            _require(value >= 1, f"node.{name}", value, "must be >= 1")
        _require(self.log_throttle_s >= 0.0, "node.log_throttle_s", self.log_throttle_s, ">= 0")


@cache
def _default_cell() -> Cell:
    return default_cell()


@dataclass(frozen=True, kw_only=True)
class ControllerConfig:
    """The whole controller configuration: a station of a cell, and the tuning.

    ``station_name`` chooses the station of ``cell`` (empty: the first). The defaults are the
    reference cell's only station with the reference tuning. ``station``, ``tool``, ``bins``
    and ``class_priorities`` are derived from those.
    """

    cell: Cell = field(default_factory=_default_cell)
    station_name: str = ""
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    ik: IkConfig = field(default_factory=IkConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    pick: PickConfig = field(default_factory=PickConfig)
    scheduler: SchedulerConfig = field(default_factory=SchedulerConfig)
    allocation: AllocationConfig = field(default_factory=AllocationConfig)
    node: NodeConfig = field(default_factory=NodeConfig)

    station: StationSpec = field(init=False, repr=False, compare=False)
    """The station the controller drives."""
    tool: ControllerTool = field(init=False, repr=False, compare=False)
    """The controller's side of the station's tool."""
    timing: GraspTiming = field(init=False, repr=False, compare=False)
    """The pick sequence's waits for the tool (:meth:`ControllerTool.timing`)."""
    bins: Mapping[str, Vec3] = field(init=False, repr=False, compare=False)
    """Class name -> drop point above the station's bin for it (world frame)."""
    class_priorities: Mapping[str, float] = field(init=False, repr=False, compare=False)
    """Every class of the cell -> its priority (``scheduler.class_priorities``, else 1.0)."""

    def __post_init__(self) -> None:
        """Resolve the station, check the rates fit the cell and the priorities its classes."""
        station = (
            self.cell.station(self.station_name) if self.station_name else self.cell.stations[0]
        )
        object.__setattr__(self, "station", station)
        object.__setattr__(self, "tool", make_tool(station.tool, self.cell.materials))
        object.__setattr__(self, "timing", self.tool.timing(self.pick))
        object.__setattr__(self, "bins", {b.class_name: b.drop_point_m for b in station.bins})
        classes = self.cell.classes
        for name in self.scheduler.class_priorities:
            _require(
                name in classes,
                f"scheduler.class_priorities.{name}",
                self.scheduler.class_priorities[name],
                f"not a class of the cell (its classes: {', '.join(classes)})",
            )
        for name in self.scheduler.class_density_kg_m3:
            _require(
                name in classes,
                f"scheduler.class_density_kg_m3.{name}",
                self.scheduler.class_density_kg_m3[name],
                f"not a class of the cell (its classes: {', '.join(classes)})",
            )
        priorities = {c: self.scheduler.class_priorities.get(c, 1.0) for c in classes}
        object.__setattr__(self, "class_priorities", priorities)
        self._check_preferences()
        ratio = self.motion.control_period_s / self.physics_dt_s
        _require(
            ratio >= 1.0 - 1e-6 and abs(ratio - round(ratio)) < 1e-6,
            "motion.control_period_s",
            self.motion.control_period_s,
            f"must be a whole multiple of the cell's physics step ({self.physics_dt_s} s)",
        )

    def _check_preferences(self) -> None:
        """Every station and class ``allocation.preferred_classes`` names is the cell's."""
        names = [s.name for s in self.cell.stations]
        for station, preferred in self.allocation.preferred_classes.items():
            key = f"allocation.preferred_classes.{station}"
            _require(station in names, key, preferred, f"not a station of the cell ({names})")
            unknown = [c for c in preferred if c not in self.cell.classes]
            _require(not unknown, key, preferred, f"not classes of the cell: {unknown}")

    @property
    def robot(self) -> RobotSpec:
        """The station's robot."""
        return self.station.robot

    @property
    def belt(self) -> BeltSpec:
        """The cell's belt."""
        return self.cell.belt

    @property
    def classes(self) -> tuple[str, ...]:
        """The classes the cell sorts (the tracker's class list)."""
        return self.cell.classes

    @property
    def pick_window_x_m(self) -> tuple[float, float]:
        """The station's pick window along x (world frame)."""
        return self.station.pick_window_x_m

    @property
    def base_position_m(self) -> Vec3:
        """The robot base's position (world frame)."""
        return self.station.base_position_m

    @property
    def ready_tcp_position_m(self) -> Vec3:
        """The ready TCP position in the world frame: ``pick.ready_tcp_position_m`` if set,
        else the robot's."""
        wait = self.pick.ready_tcp_position_m
        if len(wait) == 3:
            return self.station.to_world((wait[0], wait[1], wait[2]))
        return self.station.ready_tcp_position_world_m()

    @property
    def ready_yaw_rad(self) -> float:
        """The ready TCP yaw in the world frame."""
        return self.station.robot.ready_yaw_rad + self.station.base_yaw_rad

    @property
    def physics_dt_s(self) -> float:
        """The cell's physics step (one joint state and one lockstep tick per step)."""
        return self.cell.physics.dt_s

    @property
    def steps_per_update(self) -> int:
        """Cell steps per control update: ``motion.control_period_s / physics_dt_s``."""
        return max(round(self.motion.control_period_s / self.physics_dt_s), 1)


SECTIONS: dict[str, type] = {
    "tracking": TrackingConfig,
    "ik": IkConfig,
    "motion": MotionConfig,
    "pick": PickConfig,
    "scheduler": SchedulerConfig,
    "allocation": AllocationConfig,
    "node": NodeConfig,
}
"""The sections of a parameter file and their dataclasses."""

OVERRIDES = ("robots", "tools")
"""Keys of a parameter file whose entries, by the station's robot or tool name, override the
sections for the stations with that robot or tool."""

MOVED_TO_CELL: dict[str, str] = {
    "robot": "the station's robot, tool and base pose",
    "belt": "the belt, and the station's pick_window_x_m",
    "bins": "the station's bins",
    "tracking.class_names": "the classes of the stations' bins",
    "motion.joint_max_acceleration_rps2": "the robot's joint_max_acceleration_rps2",
    "motion.joint_max_jerk_rps3": "the robot's joint_max_jerk_rps3",
    "scheduler.finger_width_m": "the tool's finger_width_m",
    "scheduler.finger_depth_m": "the tool's finger_depth_m",
    "scheduler.hand_width_m": "the tool's hand_width_m",
    "scheduler.hand_depth_m": "the tool's hand_depth_m",
    "scheduler.palm_above_tcp_m": "the tool's palm_above_tcp_m",
    "scheduler.min_height_m": "the tool's pad_height_m",
    "node.physics_dt_s": "the physics' physics_hz",
}
"""Parameter-file keys that moved to the cell file, and where they live there now."""


def _moved(key: str) -> None:
    where = MOVED_TO_CELL.get(key)
    if where is not None:
        msg = f"{key}: this now comes from the cell file (--cell: {where}); remove it"
        raise ControlConfigError(msg)


def _check_keys(params: Mapping[str, object], prefix: str = "") -> None:
    """Refuse keys that moved to the cell file and sections the controller does not have."""
    for key, value in params.items():
        _moved(key)
        if key not in SECTIONS:
            allowed = ", ".join(SECTIONS) + ("" if prefix else ", " + ", ".join(OVERRIDES))
            msg = f"{prefix}{key}: unknown section (allowed: {allowed})"
            raise ControlConfigError(msg)
        if isinstance(value, Mapping):
            for inner in value:
                _moved(f"{key}.{inner}")


def _override_entries(params: Mapping[str, object]) -> dict[str, dict[str, Mapping[str, Any]]]:
    """The ``robots`` and ``tools`` entries, checked: name -> sections, each a mapping."""
    out: dict[str, dict[str, Mapping[str, Any]]] = {}
    for key in OVERRIDES:
        entries = params.get(key) or {}
        if not isinstance(entries, Mapping):
            msg = f"{key} = {entries!r}: expected a mapping of names to sections"
            raise ControlConfigError(msg)
        for name, sections in entries.items():
            where = f"{key}.{name}"
            if not isinstance(sections, Mapping):
                msg = f"{where} = {sections!r}: expected a mapping of sections"
                raise ControlConfigError(msg)
            _check_keys(sections, f"{where}.")
            out[where] = {section: raw or {} for section, raw in sections.items()}
    return out


def _merged(base: Mapping[str, Any], override: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """``base``'s sections with ``override``'s keys replacing theirs, section by section."""
    merged = dict(base)
    for section, raw in override.items():
        if not isinstance(raw, Mapping):
            msg = f"{section} = {raw!r}: expected a mapping"
            raise ControlConfigError(msg)
        below = merged.get(section) or {}
        merged[section] = {**(below if isinstance(below, Mapping) else {}), **raw}
    return merged


def _sections(raw: Mapping[str, Any]) -> dict[str, Any]:
    return {name: from_data(SECTIONS[name], value, name) for name, value in raw.items()}


def config_from_mapping(
    params: Mapping[str, object],
    *,
    source: str = "<mapping>",
    cell: Cell | None = None,
    station: str = "",
) -> ControllerConfig:
    """A :class:`ControllerConfig` from the ``ros__parameters`` mapping, for ``station`` of
    ``cell`` (None: the reference cell; empty station: its first).

    The sections (``pick``, ``scheduler``, ...) apply to every station; ``robots.<name>`` and
    then ``tools.<name>`` hold sections whose keys replace those for a station whose robot or
    tool has that name (one file tunes a line of different robots and tools). Every entry is
    checked, whichever stations it applies to. Raises ``ControlConfigError`` naming ``source``
    and the dotted key of the first bad value.
    """
    try:
        base = {k: v for k, v in params.items() if k not in OVERRIDES}
        _check_keys(base)
        overrides = _override_entries(params)
        for where, override in overrides.items():
            try:
                _sections(_merged(base, override))
            except ConfigError as exc:
                msg = f"{where}: {exc}"
                raise ControlConfigError(msg) from None
        cell = cell if cell is not None else _default_cell()
        spec = cell.station(station) if station else cell.stations[0]
        raw = dict(base)
        for key in (f"robots.{spec.robot.name}", f"tools.{spec.tool.name}"):
            raw = _merged(raw, overrides.get(key, {}))
        return ControllerConfig(cell=cell, station_name=station, **_sections(raw))
    except ConfigError as exc:
        msg = f"{source}: {exc}"
        raise ControlConfigError(msg) from None


EXTENDS_DEPTH = 4
"""How many parameter files an ``extends:`` chain may stack."""


def load_config(
    path: str | os.PathLike[str],
    *,
    cell: Cell | None = None,
    station: str = "",
    node_name: str = "controller",
) -> ControllerConfig:
    """Load the tuning from a ROS-parameters YAML file, for ``station`` of ``cell``.

    A file may start from another: a top-level ``extends: NAME_OR_PATH`` (a file of
    ``control/config/`` by name, or a path relative to this file) is read first, and this
    file's keys replace its keys, section by section and in ``robots.*`` / ``tools.*`` entry by
    entry (:func:`merged_params`). Raises ``ControlConfigError`` naming the file and the key
    (or YAML line) that was wrong.
    """
    path = Path(path)
    params = _read_params(path, node_name, EXTENDS_DEPTH)
    return config_from_mapping(params, source=str(path), cell=cell, station=station)


def _read_params(path: Path, node_name: str, depth: int) -> Mapping[str, object]:
    """The ``ros__parameters`` mapping of ``path``, on top of the file it ``extends``."""
    try:
        document = load_yaml_file(path, what="controller config")
    except ConfigError as exc:
        raise ControlConfigError(str(exc)) from None
    if not isinstance(document, Mapping) or node_name not in document:
        msg = f"{path}: expected a top-level key {node_name!r}"
        raise ControlConfigError(msg)
    node = document[node_name]
    if not isinstance(node, Mapping) or "ros__parameters" not in node:
        msg = f"{path}: expected {node_name}.ros__parameters"
        raise ControlConfigError(msg)
    params = node["ros__parameters"]
    if params is None:
        params = {}
    if not isinstance(params, Mapping):
        msg = f"{path}: {node_name}.ros__parameters must be a mapping, got {cut(params)}"
        raise ControlConfigError(msg)
    unknown = set(document) - {node_name, "extends"}
    if unknown:
        msg = f"{path}: unknown top-level key(s) {sorted(unknown)} (expected {node_name}, extends)"
        raise ControlConfigError(msg)
    extends = document.get("extends")
    if extends is None:
        return cast(Mapping[str, object], params)
    if not isinstance(extends, str) or not extends:
        msg = f"{path}: extends = {cut(extends)}: expected a file name or path"
        raise ControlConfigError(msg)
    if depth <= 0:
        msg = f"{path}: extends = {extends!r}: more than {EXTENDS_DEPTH} files stacked (a cycle?)"
        raise ControlConfigError(msg)
    under = _read_params(params_path(extends, path.parent), node_name, depth - 1)
    return merged_params(under, cast(Mapping[str, object], params))


def merged_params(base: Mapping[str, object], over: Mapping[str, object]) -> dict[str, object]:
    """``over`` on top of ``base``: mappings merge key by key (sections, ``robots``/``tools``
    entries and their sections), any other value of ``over`` replaces ``base``'s."""
    merged = dict(base)
    for key, value in over.items():
        below = merged.get(key)
        if isinstance(value, Mapping) and isinstance(below, Mapping):
            merged[key] = merged_params(
                cast(Mapping[str, object], below), cast(Mapping[str, object], value)
            )
        else:
            merged[key] = value
    return merged


def params_path(value: str, base_dir: Path | None = None) -> Path:
    """The parameter file a scenario's ``controller`` (or ``--controller``) names: a bare name
    (no ``/``, no ``.yaml``) is a file shipped in ``control/config/`` (:data:`PARAMS_DIR`),
    anything else a path, relative to ``base_dir`` when given. :class:`ControlConfigError`
    when there is no such shipped file (the caller names the key and the value)."""
    if "/" not in value and not value.endswith((".yaml", ".yml")):
        path = PARAMS_DIR / f"{value}.yaml"
        if not path.is_file():
            known = ", ".join(sorted(p.stem for p in PARAMS_DIR.glob("*.yaml")))
            msg = f"no parameter file of that name (shipped: {known})"
            raise ControlConfigError(msg)
        return path
    path = Path(value).expanduser()
    if not path.is_absolute() and base_dir is not None:
        path = base_dir / path
    return path


def station_configs(path: str | os.PathLike[str], cell: Cell) -> tuple[ControllerConfig, ...]:
    """Every station's configuration from the parameter file ``path`` for ``cell``, in the
    cell's order: the file checked against the cell it drives (its classes, stations, robots
    and tools). :class:`ControlConfigError` naming the file, the station and the key."""
    configs = []
    for station in cell.stations:
        try:
            configs.append(load_config(path, cell=cell, station=station.name))
        except ControlConfigError as exc:
            where = f"station {station.name!r} of the cell {cell.source or cell.name}"
            msg = cut_message(f"{exc} (for {where})")
            raise ControlConfigError(msg) from None
    return tuple(configs)
