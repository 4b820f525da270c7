"""The sections of a controller parameter file: one frozen dataclass each, every field checked.

``tracking``, ``ik``, ``motion``, ``pick``, ``scheduler``, ``allocation`` and ``node`` (see
:mod:`control.config`, which reads the file and builds the whole
:class:`control.config.ControllerConfig` from the cell and these). Values only: this module
imports nothing of the controller's behaviour (the tools and the tracker import it, not the
other way round). Every check is :func:`interfaces.errors.require`, raising
:class:`control.errors.ControlConfigError` with the dotted key and the value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Literal, cast

from control.errors import ControlConfigError
from interfaces.errors import require

Vec3 = tuple[float, float, float]


def _require(condition: bool, key: str, value: object, requirement: str) -> None:
    """:func:`interfaces.errors.require`, raising :class:`ControlConfigError`."""
    require(condition, key, value, requirement, error=ControlConfigError)


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


__all__ = [
    "ALLOCATION_STRATEGIES",
    "APPROACH_SPACES",
    "RANKS",
    "AllocationConfig",
    "IkConfig",
    "MotionConfig",
    "NodeConfig",
    "PickConfig",
    "SchedulerConfig",
    "TrackingConfig",
]
