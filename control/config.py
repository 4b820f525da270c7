"""Controller configuration: frozen dataclasses and a loader for the ROS-parameters YAML file.

The YAML file has the layout ROS 2 uses for node parameters::

    controller:
      ros__parameters:
        robot: {urdf_path: franka_panda/panda.urdf, tcp_link: panda_grasptarget, ...}
        belt: {...}
        bins: {concrete: [-0.60, 0.07, 0.15], ...}
        ...

Every key is optional (the defaults describe the reference cell), unknown keys are errors, and
every error names the file and the dotted key that was wrong.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any, TypeVar, cast

import yaml

from control.errors import ControlConfigError

CLASS_NAMES: tuple[str, ...] = ("concrete", "brick", "wood", "rubber")
"""The waste classes of the reference cell, in the order the perception model reports them."""

_T = TypeVar("_T")


def _meta(kind: str) -> dict[str, str]:
    return {"kind": kind}


def _require(condition: bool, key: str, value: object, requirement: str) -> None:
    if not condition:
        msg = f"{key}: {value!r} is invalid, {requirement}"
        raise ControlConfigError(msg)


def _finite(values: tuple[float, ...]) -> bool:
    return all(math.isfinite(v) for v in values)


@dataclass(frozen=True, kw_only=True)
class RobotConfig:
    """The arm: URDF, base pose, tool frame, joints, gripper and the ready pose.

    ``urdf_path`` is absolute, relative to the working directory, or relative to
    ``pybullet_data.getDataPath()`` (resolved by :func:`resolve_urdf_path`).
    ``tcp_offset_m`` is the TCP position in the ``tcp_link`` frame (zero when the URDF already
    has a TCP link such as ``panda_grasptarget``). ``finger_joint_names`` may be empty (no
    gripper). The ready pose is the TCP position ``ready_tcp_position_m`` pointing down with
    ``ready_yaw_rad``; ``ready_joint_positions_rad`` seeds the IK towards it.
    """

    urdf_path: str = field(default="franka_panda/panda.urdf", metadata=_meta("str"))
    base_position_m: tuple[float, float, float] = field(
        default=(0.0, 0.0, 0.0), metadata=_meta("vec")
    )
    base_orientation_xyzw: tuple[float, float, float, float] = field(
        default=(0.0, 0.0, 0.0, 1.0), metadata=_meta("vec")
    )
    tcp_link: str = field(default="panda_grasptarget", metadata=_meta("str"))
    tcp_offset_m: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), metadata=_meta("vec"))
    arm_joint_names: tuple[str, ...] = field(
        default=tuple(f"panda_joint{i}" for i in range(1, 8)), metadata=_meta("strs")
    )
    finger_joint_names: tuple[str, ...] = field(
        default=("panda_finger_joint1", "panda_finger_joint2"), metadata=_meta("strs")
    )
    gripper_max_opening_m: float = field(default=0.08, metadata=_meta("float"))
    ready_tcp_position_m: tuple[float, float, float] = field(
        default=(-0.3, 0.5, 0.2), metadata=_meta("vec")
    )
    ready_yaw_rad: float = field(default=math.pi / 2, metadata=_meta("float"))
    ready_joint_positions_rad: tuple[float, ...] = field(
        default=(math.pi / 2, -0.3, 0.0, -2.2, 0.0, 1.9, math.pi / 4), metadata=_meta("floats")
    )

    def __post_init__(self) -> None:
        """Validate every field."""
        _require(bool(self.urdf_path), "robot.urdf_path", self.urdf_path, "must not be empty")
        _require(bool(self.tcp_link), "robot.tcp_link", self.tcp_link, "must not be empty")
        norm = math.sqrt(sum(v * v for v in self.base_orientation_xyzw))
        _require(
            abs(norm - 1.0) < 1e-6,
            "robot.base_orientation_xyzw",
            self.base_orientation_xyzw,
            "must be a unit quaternion",
        )
        _require(
            len(self.arm_joint_names) > 0, "robot.arm_joint_names", self.arm_joint_names, "empty"
        )
        _require(
            len(set(self.arm_joint_names + self.finger_joint_names))
            == len(self.arm_joint_names) + len(self.finger_joint_names),
            "robot.arm_joint_names",
            self.arm_joint_names,
            "joint names must be unique across arm and fingers",
        )
        _require(
            self.gripper_max_opening_m > 0.0,
            "robot.gripper_max_opening_m",
            self.gripper_max_opening_m,
            "must be > 0",
        )
        _require(
            len(self.ready_joint_positions_rad) == len(self.arm_joint_names),
            "robot.ready_joint_positions_rad",
            self.ready_joint_positions_rad,
            f"needs one value per arm joint ({len(self.arm_joint_names)})",
        )
        for name in ("base_position_m", "tcp_offset_m", "ready_tcp_position_m"):
            value = cast(tuple[float, ...], getattr(self, name))
            _require(_finite(value), f"robot.{name}", value, "must be finite")


@dataclass(frozen=True, kw_only=True)
class BeltConfig:
    """The conveyor: travels +x, centreline at ``centreline_y_m``, top surface at ``surface_z_m``.

    ``pick_window_x_m`` is the (min, max) x range in which the arm may grasp.
    """

    centreline_y_m: float = field(default=0.5, metadata=_meta("float"))
    width_m: float = field(default=0.6, metadata=_meta("float"))
    surface_z_m: float = field(default=0.0, metadata=_meta("float"))
    pick_window_x_m: tuple[float, float] = field(default=(-0.35, 0.35), metadata=_meta("vec"))
    min_speed_mps: float = field(default=0.2, metadata=_meta("float"))
    max_speed_mps: float = field(default=0.6, metadata=_meta("float"))

    def __post_init__(self) -> None:
        """Validate every field."""
        _require(self.width_m > 0.0, "belt.width_m", self.width_m, "must be > 0")
        lo, hi = self.pick_window_x_m
        _require(lo < hi, "belt.pick_window_x_m", self.pick_window_x_m, "needs min < max")
        _require(
            0.0 <= self.min_speed_mps <= self.max_speed_mps,
            "belt.max_speed_mps",
            self.max_speed_mps,
            "needs 0 <= min_speed_mps <= max_speed_mps",
        )


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

    class_names: tuple[str, ...] = field(default=CLASS_NAMES, metadata=_meta("strs"))
    min_confidence: float = field(default=0.0, metadata=_meta("float"))
    position_std_m: float = field(default=0.002, metadata=_meta("float"))
    process_accel_std_mps2: float = field(default=0.01, metadata=_meta("float"))
    initial_velocity_std_mps: float = field(default=0.05, metadata=_meta("float"))
    gate_mahalanobis_sq: float = field(default=16.0, metadata=_meta("float"))
    gate_min_m: float = field(default=0.01, metadata=_meta("float"))
    confirm_hits: int = field(default=3, metadata=_meta("int"))
    max_coast_s: float = field(default=0.3, metadata=_meta("float"))
    smoothing: float = field(default=0.2, metadata=_meta("float"))

    def __post_init__(self) -> None:
        """Validate every field."""
        _require(len(self.class_names) > 0, "tracking.class_names", self.class_names, "empty")
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
    (1e-4 of the ``log6`` norm: 0.1 mm, 0.1 mrad) when the iteration limit comes first.
    """

    tolerance: float = field(default=1e-9, metadata=_meta("float"))
    accept_tolerance: float = field(default=1e-4, metadata=_meta("float"))
    damping: float = field(default=1e-8, metadata=_meta("float"))
    step: float = field(default=1.0, metadata=_meta("float"))
    max_iterations: int = field(default=100, metadata=_meta("int"))
    max_joint_step_rad: float = field(default=0.5, metadata=_meta("float"))

    def __post_init__(self) -> None:
        """Validate every field."""
        for name in ("tolerance", "accept_tolerance", "step", "max_joint_step_rad"):
            value = cast(float, getattr(self, name))
            _require(value > 0.0, f"ik.{name}", value, "must be > 0")
        _require(self.damping >= 0.0, "ik.damping", self.damping, "must be >= 0")
        _require(self.max_iterations >= 1, "ik.max_iterations", self.max_iterations, "must be >= 1")


PANDA_MAX_ACCELERATION_RPS2: tuple[float, ...] = (15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0)
"""Joint acceleration limits of the Franka Emika Panda (datasheet), joints 1 to 7."""
PANDA_MAX_JERK_RPS3: tuple[float, ...] = (7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0)
"""Joint jerk limits of the Franka Emika Panda (datasheet), joints 1 to 7."""


@dataclass(frozen=True, kw_only=True)
class MotionConfig:
    """Cartesian trajectory limits for (x, y, z, yaw) and the feedback on the tracking error.

    ``feedback_kp`` (1) and ``feedback_ki_per_s`` (1/s) act on setpoint minus measured TCP
    position while following an object; the correction is clipped to ``feedback_max_m``.
    ``transfer_speed_scale`` (0, 1] scales the URDF joint velocity limits for the joint-space
    carry and return moves, which use ``joint_max_acceleration_rps2`` and ``joint_max_jerk_rps3``
    (one value per arm joint, or one for all; the defaults are the Panda's datasheet limits).
    ``command_latency_s`` is the time between computing a command and the measured TCP
    reflecting it; targets are predicted that far ahead and the feedback compares the measured
    TCP with the setpoint of that long ago.
    ``joint_velocity_margin`` scales the URDF joint velocity limits that bound every per-tick
    joint step of the Cartesian moves (a faster IK solution is approached at that speed).
    """

    control_period_s: float = field(default=1.0 / 120.0, metadata=_meta("float"))
    command_latency_s: float = field(default=0.01, metadata=_meta("float"))
    max_velocity: tuple[float, float, float, float] = field(
        default=(0.8, 0.8, 0.8, 2.4), metadata=_meta("vec")
    )
    max_acceleration: tuple[float, float, float, float] = field(
        default=(12.0, 12.0, 12.0, 20.0), metadata=_meta("vec")
    )
    max_jerk: tuple[float, float, float, float] = field(
        default=(300.0, 300.0, 300.0, 400.0), metadata=_meta("vec")
    )
    feedback_kp: float = field(default=0.5, metadata=_meta("float"))
    feedback_ki_per_s: float = field(default=5.0, metadata=_meta("float"))
    feedback_max_m: float = field(default=0.03, metadata=_meta("float"))
    transfer_speed_scale: float = field(default=0.9, metadata=_meta("float"))
    joint_max_acceleration_rps2: tuple[float, ...] = field(
        default=PANDA_MAX_ACCELERATION_RPS2, metadata=_meta("floats")
    )
    joint_max_jerk_rps3: tuple[float, ...] = field(
        default=PANDA_MAX_JERK_RPS3, metadata=_meta("floats")
    )
    joint_velocity_margin: float = field(default=1.0, metadata=_meta("float"))

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
        for name in ("joint_max_acceleration_rps2", "joint_max_jerk_rps3"):
            value = cast(tuple[float, ...], getattr(self, name))
            _require(
                len(value) > 0 and all(v > 0.0 and math.isfinite(v) for v in value),
                f"motion.{name}",
                value,
                "needs one value for every joint (or one for all), each finite and > 0",
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


APPROACH_SPACES = ("cartesian", "joint")
"""Values of ``pick.approach_space``."""


@dataclass(frozen=True, kw_only=True)
class PickConfig:
    """Pick sequence geometry and timing.

    The grasp point is ``grasp_below_top_m`` below the object's top (the Panda's palm touches
    the object when the TCP is lower than about 2 cm below the top), but not below
    ``height * grasp_height_fraction`` nor ``min_grasp_height_m`` above the belt surface:
    ``surface_z + max(height - grasp_below_top_m, height * grasp_height_fraction,
    min_grasp_height_m)``. The approach ends ``approach_height_m`` above it.
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

    Grip check (skipped when ``/joint_states`` carries no finger joints): when the close ends,
    and through the lift, a gripper measured within ``grip_check_margin_m`` of its commanded
    opening has closed on nothing: the pick is aborted as ``grip_missed`` and the object may be
    targeted ``grip_retries`` more times.
    """

    approach_height_m: float = field(default=0.06, metadata=_meta("float"))
    ik_failures_to_abort: int = field(default=3, metadata=_meta("int"))
    schedule_before_ready_s: float = field(default=0.1, metadata=_meta("float"))
    grasp_below_top_m: float = field(default=0.02, metadata=_meta("float"))
    grasp_height_fraction: float = field(default=0.5, metadata=_meta("float"))
    min_grasp_height_m: float = field(default=0.01, metadata=_meta("float"))
    lift_height_m: float = field(default=0.2, metadata=_meta("float"))
    dwell_s: float = field(default=0.6, metadata=_meta("float"))
    close_s: float = field(default=0.25, metadata=_meta("float"))
    close_overlap_s: float = field(default=0.0, metadata=_meta("float"))
    release_s: float = field(default=0.25, metadata=_meta("float"))
    drop_tolerance_m: float = field(default=0.08, metadata=_meta("float"))
    arrive_tolerance_m: float = field(default=0.005, metadata=_meta("float"))
    arrive_speed_tolerance_mps: float = field(default=0.1, metadata=_meta("float"))
    yaw_tolerance_rad: float = field(default=0.02, metadata=_meta("float"))
    descend_yaw_lead_s: float = field(default=0.1, metadata=_meta("float"))
    lost_timeout_s: float = field(default=0.3, metadata=_meta("float"))
    grip_squeeze_m: float = field(default=0.01, metadata=_meta("float"))
    grip_check_margin_m: float = field(default=0.001, metadata=_meta("float"))
    grip_retries: int = field(default=1, metadata=_meta("int"))
    approach_space: str = field(default="cartesian", metadata=_meta("str"))

    def __post_init__(self) -> None:
        """Validate every field."""
        _require(
            self.approach_space in APPROACH_SPACES,
            "pick.approach_space",
            self.approach_space,
            f"must be one of {', '.join(APPROACH_SPACES)}",
        )
        for item in fields(self):
            if item.name == "approach_space":
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


@dataclass(frozen=True, kw_only=True)
class SchedulerConfig:
    """Target selection: class priorities (larger is picked first) and safety margins.

    ``max_reach_m`` bounds the distance from the robot base to a grasp point;
    ``grasp_width_margin_m`` is subtracted from the gripper opening before comparing it with the
    object's narrow side; ``time_margin_s`` is added to every intercept estimate.
    An object is blocked when another lies in the rectangle its open fingers come down on:
    across its narrow side the opening plus two ``finger_depth_m`` and ``clearance_m``, along
    its long side ``finger_width_m`` plus ``clearance_m`` (Panda fingers: 2 cm by 1.2 cm); or
    when an object whose top reaches the palm (``palm_above_tcp_m`` above the grasp point) lies
    under the hand, ``hand_width_m`` in the closing direction by ``hand_depth_m`` across it
    (Panda hand: 21 by 7 cm, palm 3.5 cm above the TCP), both plus ``clearance_m``.
    Objects lower than ``min_height_m`` are too flat for the finger pads (about 2 cm tall).
    """

    class_priorities: dict[str, float] = field(
        default_factory=lambda: dict.fromkeys(CLASS_NAMES, 1.0), metadata=_meta("float_map")
    )
    max_reach_m: float = field(default=0.8, metadata=_meta("float"))
    grasp_width_margin_m: float = field(default=0.015, metadata=_meta("float"))
    time_margin_s: float = field(default=0.05, metadata=_meta("float"))
    min_confidence: float = field(default=0.3, metadata=_meta("float"))
    finger_width_m: float = field(default=0.02, metadata=_meta("float"))
    finger_depth_m: float = field(default=0.012, metadata=_meta("float"))
    clearance_m: float = field(default=0.008, metadata=_meta("float"))
    hand_width_m: float = field(default=0.21, metadata=_meta("float"))
    hand_depth_m: float = field(default=0.072, metadata=_meta("float"))
    palm_above_tcp_m: float = field(default=0.035, metadata=_meta("float"))
    min_height_m: float = field(default=0.02, metadata=_meta("float"))

    def __post_init__(self) -> None:
        """Validate every field."""
        lengths = (
            "finger_width_m",
            "finger_depth_m",
            "clearance_m",
            "min_height_m",
            "hand_width_m",
            "hand_depth_m",
            "palm_above_tcp_m",
        )
        for name in lengths:
            value = cast(float, getattr(self, name))
            ok = value >= 0.0 and math.isfinite(value)
            _require(ok, f"scheduler.{name}", value, "must be finite and >= 0")
        for name, value in self.class_priorities.items():
            _require(
                math.isfinite(value), f"scheduler.class_priorities.{name}", value, "must be finite"
            )
        _require(self.max_reach_m > 0.0, "scheduler.max_reach_m", self.max_reach_m, "must be > 0")
        _require(self.time_margin_s >= 0.0, "scheduler.time_margin_s", self.time_margin_s, ">= 0")


@dataclass(frozen=True, kw_only=True)
class NodeConfig:
    """The ROS 2 node around the pure controller.

    ``physics_dt_s`` is the cell's step (one ``/joint_states`` message and one lockstep tick per
    step); the control update runs every ``motion.control_period_s / physics_dt_s`` steps, which
    must be a whole number. ``target_refresh_every`` and ``gripper_refresh_every`` repeat an
    unchanged ``/controller/target`` or ``/gripper/command`` every that many control updates
    (a change is always sent at once). ``log_throttle_s`` is the least time between two log
    lines about the same kind of bad input (wall clock, logging only).
    """

    physics_dt_s: float = field(default=1.0 / 240.0, metadata=_meta("float"))
    target_refresh_every: int = field(default=12, metadata=_meta("int"))
    gripper_refresh_every: int = field(default=12, metadata=_meta("int"))
    log_throttle_s: float = field(default=2.0, metadata=_meta("float"))

    def __post_init__(self) -> None:
        """Validate every field."""
        _require(self.physics_dt_s > 0.0, "node.physics_dt_s", self.physics_dt_s, "must be > 0")
        for name in ("target_refresh_every", "gripper_refresh_every"):
            value = cast(int, getattr(self, name))
            _require(value >= 1, f"node.{name}", value, "must be >= 1")
        _require(self.log_throttle_s >= 0.0, "node.log_throttle_s", self.log_throttle_s, ">= 0")


def _default_bins() -> dict[str, tuple[float, float, float]]:
    return {
        "concrete": (-0.60, 0.07, 0.15),
        "brick": (-0.33, 0.07, 0.15),
        "wood": (0.33, 0.07, 0.15),
        "rubber": (0.60, 0.07, 0.15),
    }


@dataclass(frozen=True, kw_only=True)
class ControllerConfig:
    """The whole controller configuration; the defaults describe the reference cell.

    ``bins`` maps a class name to the drop point above its bin, ``(3,) float`` in metres.
    """

    robot: RobotConfig = field(default_factory=RobotConfig, metadata=_meta("nested"))
    belt: BeltConfig = field(default_factory=BeltConfig, metadata=_meta("nested"))
    bins: dict[str, tuple[float, float, float]] = field(
        default_factory=_default_bins, metadata=_meta("vec3_map")
    )
    tracking: TrackingConfig = field(default_factory=TrackingConfig, metadata=_meta("nested"))
    ik: IkConfig = field(default_factory=IkConfig, metadata=_meta("nested"))
    motion: MotionConfig = field(default_factory=MotionConfig, metadata=_meta("nested"))
    pick: PickConfig = field(default_factory=PickConfig, metadata=_meta("nested"))
    scheduler: SchedulerConfig = field(default_factory=SchedulerConfig, metadata=_meta("nested"))
    node: NodeConfig = field(default_factory=NodeConfig, metadata=_meta("nested"))

    @property
    def steps_per_update(self) -> int:
        """Cell steps per control update: ``motion.control_period_s / node.physics_dt_s``."""
        return max(round(self.motion.control_period_s / self.node.physics_dt_s), 1)

    def __post_init__(self) -> None:
        """Check that bins and priorities cover the tracked classes and the rates fit."""
        ratio = self.motion.control_period_s / self.node.physics_dt_s
        _require(
            ratio >= 1.0 - 1e-6 and abs(ratio - round(ratio)) < 1e-6,
            "motion.control_period_s",
            self.motion.control_period_s,
            f"must be a whole multiple of node.physics_dt_s ({self.node.physics_dt_s})",
        )
        for name, point in self.bins.items():
            _require(_finite(point), f"bins.{name}", point, "must be finite")
        for name in self.tracking.class_names:
            _require(name in self.bins, "bins", sorted(self.bins), f"has no bin for class {name!r}")
            _require(
                name in self.scheduler.class_priorities,
                "scheduler.class_priorities",
                sorted(self.scheduler.class_priorities),
                f"has no priority for class {name!r}",
            )


def resolve_urdf_path(urdf_path: str) -> Path:
    """Return the existing URDF file ``urdf_path`` names (absolute, cwd or pybullet_data).

    Raises ``ControlConfigError`` naming the path when none exists.
    """
    candidate = Path(urdf_path).expanduser()
    if candidate.is_file():
        return candidate.resolve()
    if not candidate.is_absolute():
        import pybullet_data

        in_data = Path(pybullet_data.getDataPath()) / candidate
        if in_data.is_file():
            return in_data
    msg = f"robot.urdf_path: {urdf_path!r} is neither a file nor a file under pybullet_data"
    raise ControlConfigError(msg)


def _as_float(raw: object, key: str) -> float:
    if isinstance(raw, bool) or not isinstance(raw, int | float):
        msg = f"{key}: expected a number, got {raw!r}"
        raise ControlConfigError(msg)
    value = float(raw)
    if not math.isfinite(value):
        msg = f"{key}: expected a finite number, got {raw!r}"
        raise ControlConfigError(msg)
    return value


def _as_floats(raw: object, key: str, length: int | None) -> tuple[float, ...]:
    if not isinstance(raw, list | tuple):
        msg = f"{key}: expected a list of numbers, got {raw!r}"
        raise ControlConfigError(msg)
    if length is not None and len(raw) != length:
        msg = f"{key}: expected {length} numbers, got {len(raw)} ({raw!r})"
        raise ControlConfigError(msg)
    return tuple(_as_float(v, f"{key}[{i}]") for i, v in enumerate(raw))


def _as_mapping(raw: object, key: str) -> Mapping[str, object]:
    if not isinstance(raw, Mapping) or not all(isinstance(k, str) for k in raw):
        msg = f"{key}: expected a mapping with string keys, got {raw!r}"
        raise ControlConfigError(msg)
    return cast(Mapping[str, object], raw)


def _convert(kind: str, raw: object, key: str, default: object, nested_type: object) -> object:
    if kind == "float":
        return _as_float(raw, key)
    if kind == "int":
        if isinstance(raw, bool) or not isinstance(raw, int):
            msg = f"{key}: expected an integer, got {raw!r}"
            raise ControlConfigError(msg)
        return raw
    if kind == "str":
        if not isinstance(raw, str):
            msg = f"{key}: expected a string, got {raw!r}"
            raise ControlConfigError(msg)
        return raw
    if kind == "vec":
        return _as_floats(raw, key, len(cast(tuple[float, ...], default)))
    if kind == "floats":
        return _as_floats(raw, key, None)
    if kind == "strs":
        if not isinstance(raw, list | tuple) or not all(isinstance(v, str) for v in raw):
            msg = f"{key}: expected a list of strings, got {raw!r}"
            raise ControlConfigError(msg)
        return tuple(raw)
    if kind == "float_map":
        return {k: _as_float(v, f"{key}.{k}") for k, v in _as_mapping(raw, key).items()}
    if kind == "vec3_map":
        return {k: _as_floats(v, f"{key}.{k}", 3) for k, v in _as_mapping(raw, key).items()}
    return _build(cast(type[Any], nested_type), _as_mapping(raw, key), key)


def _build(cls: type[_T], data: Mapping[str, object], prefix: str) -> _T:
    known = {item.name: item for item in fields(cast(Any, cls))}
    unknown = sorted(set(data) - set(known))
    if unknown:
        msg = f"{prefix}: unknown key(s) {unknown}, expected some of {sorted(known)}"
        raise ControlConfigError(msg)
    kwargs: dict[str, object] = {}
    for name, raw in data.items():
        item = known[name]
        default: object = None
        if item.default is not MISSING:
            default = item.default
        elif item.default_factory is not MISSING:
            default = item.default_factory()
        nested_type = type(default) if is_dataclass(default) else None
        kwargs[name] = _convert(
            item.metadata["kind"], raw, f"{prefix}.{name}", default, nested_type
        )
    try:
        return cls(**kwargs)
    except ControlConfigError as exc:
        msg = f"{prefix}: {exc}"
        raise ControlConfigError(msg) from exc


def config_from_mapping(
    params: Mapping[str, object], *, source: str = "<mapping>"
) -> ControllerConfig:
    """Build a :class:`ControllerConfig` from the ``ros__parameters`` mapping of the controller.

    Raises ``ControlConfigError`` naming ``source`` and the dotted key of the first bad value.
    """
    try:
        return _build(ControllerConfig, params, "controller.ros__parameters")
    except ControlConfigError as exc:
        msg = f"{source}: {exc}"
        raise ControlConfigError(msg) from exc


def load_config(path: str | os.PathLike[str], *, node_name: str = "controller") -> ControllerConfig:
    """Load and validate the controller configuration from a ROS-parameters YAML file.

    Raises ``ControlConfigError`` naming the file and the key (or YAML line) that was wrong.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        msg = f"{path}: cannot read controller config: {exc.strerror}"
        raise ControlConfigError(msg) from exc
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        msg = f"{path}:{where} invalid YAML: {exc}"
        raise ControlConfigError(msg) from exc
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
        msg = f"{path}: {node_name}.ros__parameters must be a mapping, got {params!r}"
        raise ControlConfigError(msg)
    return config_from_mapping(cast(Mapping[str, object], params), source=str(path))
