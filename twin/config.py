"""The cell: belt, workspace, bins, robot and physics settings of the twin.

World frame (REP 103): metres, z up, origin at the robot base. The belt travels along +x; its
centreline is at ``y = belt.centre_y_m`` and its top surface at ``z = belt.surface_z_m``. Objects
enter at ``belt.infeed_x_m`` and leave over the end at ``belt.end_x_m``. The workspace is the part
of the belt the robot can pick from; bins stand beside the belt, either side of the base.

Every dataclass here is frozen and validated on construction: a bad value raises
:class:`twin.errors.ConfigError` naming the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from twin.belt_drive import MAX_STEP_S
from twin.errors import ConfigError


def _require(condition: bool, field_name: str, value: object, what: str) -> None:
    if not condition:
        msg = f"{field_name} = {value!r}: {what}"
        raise ConfigError(msg)


@dataclass(frozen=True)
class BeltConfig:
    """Geometry of the conveyor belt, in the world frame."""

    width_m: float = 0.6
    start_x_m: float = -2.2
    end_x_m: float = 1.2
    infeed_x_m: float = -1.9
    centre_y_m: float = 0.5
    surface_z_m: float = 0.0
    thickness_m: float = 0.04
    lateral_friction: float = 0.8

    def __post_init__(self) -> None:
        _require(self.width_m > 0, "belt.width_m", self.width_m, "must be positive")
        _require(
            self.end_x_m > self.start_x_m, "belt.end_x_m", self.end_x_m, "must exceed start_x_m"
        )
        _require(
            self.start_x_m <= self.infeed_x_m < self.end_x_m,
            "belt.infeed_x_m",
            self.infeed_x_m,
            "must lie on the belt",
        )
        _require(self.thickness_m > 0, "belt.thickness_m", self.thickness_m, "must be positive")
        _require(
            self.lateral_friction >= 0,
            "belt.lateral_friction",
            self.lateral_friction,
            "must be >= 0",
        )

    @property
    def length_m(self) -> float:
        """Belt length along x."""
        return self.end_x_m - self.start_x_m

    def on_belt_xy(self, x_m: float, y_m: float) -> bool:
        """Whether a point's projection lies on the belt surface."""
        half = 0.5 * self.width_m
        return self.start_x_m <= x_m <= self.end_x_m and abs(y_m - self.centre_y_m) <= half


@dataclass(frozen=True)
class WorkspaceConfig:
    """The pick window on the belt (an x interval over the full belt width).

    An object is in it while it lies on the belt with its centre of mass's x in
    ``[min_x_m, max_x_m]``; a grasp is credited (``pick_success``) only there, and an object
    that leaves it downstream unpicked is ``missed`` (see :mod:`twin.monitor`).
    """

    min_x_m: float = -0.35
    max_x_m: float = 0.35

    def __post_init__(self) -> None:
        _require(self.max_x_m > self.min_x_m, "workspace.max_x_m", self.max_x_m, "must exceed min")


@dataclass(frozen=True)
class BinConfig:
    """An open-top bin on the floor; objects dropped into it are sorted as ``class_name``."""

    class_name: str
    centre_x_m: float
    centre_y_m: float
    size_m: float = 0.24
    top_z_m: float = -0.10
    floor_z_m: float = -0.40
    wall_m: float = 0.01

    def __post_init__(self) -> None:
        _require(
            self.size_m > 2 * self.wall_m,
            f"bins[{self.class_name}].size_m",
            self.size_m,
            "must exceed twice the wall thickness",
        )
        _require(
            self.top_z_m > self.floor_z_m,
            f"bins[{self.class_name}].top_z_m",
            self.top_z_m,
            "must be above floor_z_m",
        )

    @property
    def inner_half_m(self) -> float:
        """Half the side of the bin's inner area (inside the walls)."""
        return 0.5 * self.size_m - self.wall_m

    def contains_xy(self, x_m: float, y_m: float) -> bool:
        """Whether a point lies over the bin's inner area."""
        half = self.inner_half_m
        return abs(x_m - self.centre_x_m) <= half and abs(y_m - self.centre_y_m) <= half


def default_bins() -> tuple[BinConfig, ...]:
    """One bin per sorted class, beside the belt's near edge, either side of the base.

    Close to the pick window so a carry is short (the reference layout put them behind the
    robot, which caps one arm at about 11 picks per minute). The centres sit 7 cm towards the
    belt from the base's line (the walls end 1 cm short of the belt): that takes about 10 degrees
    off each base turn between belt and bin, about 0.1 s per carry.
    """
    return (
        BinConfig(class_name="concrete", centre_x_m=-0.60, centre_y_m=0.07),
        BinConfig(class_name="brick", centre_x_m=-0.33, centre_y_m=0.07),
        BinConfig(class_name="wood", centre_x_m=0.33, centre_y_m=0.07),
        BinConfig(class_name="rubber", centre_x_m=0.60, centre_y_m=0.07),
    )


@dataclass(frozen=True)
class RobotConfig:
    """A robot arm from a URDF; everything the twin needs to know about it.

    ``urdf`` is a path, or a path relative to ``pybullet_data`` when it does not exist as given.
    ``finger_open`` and ``finger_closed`` are the joint positions of each finger joint when the
    gripper is fully open (``max_opening_m``) and closed. ``inertia_from_file`` takes the links'
    inertia tensors from the URDF; by default PyBullet computes them from the collision shapes
    and the URDF masses, because pybullet_data's Panda carries placeholder inertias (0.1 kg m^2
    on every link, 10-100 times the identified ones) that made the 12 N m wrist joints lag a
    feasible command by up to 0.7 rad.
    """

    name: str = "panda"
    urdf: str = "franka_panda/panda.urdf"
    base_position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    base_yaw_rad: float = 0.0
    tcp_link: str = "panda_grasptarget"
    arm_joints: tuple[str, ...] = tuple(f"panda_joint{i}" for i in range(1, 8))
    finger_joints: tuple[str, ...] = ("panda_finger_joint1", "panda_finger_joint2")
    finger_links: tuple[str, ...] = ("panda_leftfinger", "panda_rightfinger")
    finger_open: tuple[float, ...] = (0.04, 0.04)
    finger_closed: tuple[float, ...] = (0.0, 0.0)
    max_opening_m: float = 0.08
    home_joint_positions: tuple[float, ...] = (0.0, -0.35, 0.0, -2.3, 0.0, 1.95, 0.785)
    position_gain: float = 0.1
    velocity_gain: float = 1.0
    inertia_from_file: bool = False

    def __post_init__(self) -> None:
        _require(len(self.arm_joints) > 0, "robot.arm_joints", self.arm_joints, "must not be empty")
        _require(
            len(self.home_joint_positions) == len(self.arm_joints),
            "robot.home_joint_positions",
            self.home_joint_positions,
            f"needs {len(self.arm_joints)} values, one per arm joint",
        )
        _require(
            len(self.finger_open) == len(self.finger_joints),
            "robot.finger_open",
            self.finger_open,
            "needs one value per finger joint",
        )
        _require(
            len(self.finger_closed) == len(self.finger_joints),
            "robot.finger_closed",
            self.finger_closed,
            "needs one value per finger joint",
        )
        _require(
            self.max_opening_m > 0, "robot.max_opening_m", self.max_opening_m, "must be positive"
        )

    def resolve_urdf(self) -> Path:
        """The URDF file: as given if it exists, else inside ``pybullet_data``."""
        path = Path(self.urdf)
        if path.is_file():
            return path
        import pybullet_data

        candidate = Path(pybullet_data.getDataPath()) / self.urdf
        if candidate.is_file():
            return candidate
        msg = f"robot.urdf = {self.urdf!r}: no such file (also looked in {candidate.parent})"
        raise ConfigError(msg)


def xarm6_robot() -> RobotConfig:
    """The second robot shipped with ``pybullet_data``: UFactory xArm 6 with its gripper."""
    return RobotConfig(
        name="xarm6",
        urdf="xarm/xarm6_with_gripper.urdf",
        tcp_link="xarm_gripper_base_link",
        arm_joints=tuple(f"joint{i}" for i in range(1, 7)),
        finger_joints=("drive_joint", "right_outer_knuckle_joint"),
        finger_links=("left_finger", "right_finger"),
        finger_open=(0.0, 0.0),
        finger_closed=(0.85, 0.85),
        max_opening_m=0.085,
        home_joint_positions=(0.0, -0.4, -0.6, 0.0, 1.0, 0.0),
        inertia_from_file=True,  # this URDF carries the manufacturer's inertias
    )


ROBOTS: dict[str, RobotConfig] = {"panda": RobotConfig(), "xarm6": xarm6_robot()}


@dataclass(frozen=True)
class GraspConfig:
    """The reference grasp approximation: finger contacts, a TCP overlap volume, a dwell."""

    dwell_s: float = 0.6
    tcp_half_extents_m: tuple[float, float, float] = (0.01, 0.01, 0.02)

    def __post_init__(self) -> None:
        _require(self.dwell_s >= 0, "grasp.dwell_s", self.dwell_s, "must be >= 0")
        _require(
            all(v > 0 for v in self.tcp_half_extents_m),
            "grasp.tcp_half_extents_m",
            self.tcp_half_extents_m,
            "must be positive",
        )


@dataclass(frozen=True)
class PhysicsConfig:
    """Solver settings. The step is fixed; the FMU communication step is a multiple or equal.

    ``hull_merge_tolerance`` and ``max_convex_pieces`` bound the collision-shape complexity of
    concave objects (see :mod:`twin.collision`).
    """

    physics_hz: float = 240.0
    fmu_step_s: float | None = None
    solver_iterations: int = 10
    hull_merge_tolerance: float = 0.1
    max_convex_pieces: int = 6
    floor_z_m: float = -0.8
    gravity_mps2: float = 9.81

    def __post_init__(self) -> None:
        _require(
            self.physics_hz > 0 and math.isfinite(self.physics_hz),
            "physics.physics_hz",
            self.physics_hz,
            "must be positive",
        )
        if self.fmu_step_s is not None:
            _require(
                0 < self.fmu_step_s <= MAX_STEP_S,
                "physics.fmu_step_s",
                self.fmu_step_s,
                f"must be in (0, {MAX_STEP_S}] s (the belt drive's longest step)",
            )
        _require(
            self.solver_iterations >= 1,
            "physics.solver_iterations",
            self.solver_iterations,
            "must be >= 1",
        )
        _require(
            self.hull_merge_tolerance >= 0,
            "physics.hull_merge_tolerance",
            self.hull_merge_tolerance,
            "must be >= 0",
        )
        _require(
            self.max_convex_pieces >= 1,
            "physics.max_convex_pieces",
            self.max_convex_pieces,
            "must be >= 1",
        )

    @property
    def dt_s(self) -> float:
        """The physics step."""
        return 1.0 / self.physics_hz

    @property
    def fmu_every_n_steps(self) -> int:
        """How many physics steps one FMU communication step spans (at least 1)."""
        if self.fmu_step_s is None:
            return 1
        return max(1, round(self.fmu_step_s * self.physics_hz))


@dataclass(frozen=True)
class CellConfig:
    """Everything physical about the cell."""

    belt: BeltConfig = field(default_factory=BeltConfig)
    workspace: WorkspaceConfig = field(default_factory=WorkspaceConfig)
    bins: tuple[BinConfig, ...] = field(default_factory=default_bins)
    robot: RobotConfig = field(default_factory=RobotConfig)
    grasp: GraspConfig = field(default_factory=GraspConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)

    def bin_at(self, x_m: float, y_m: float) -> BinConfig | None:
        """The first bin whose inner area holds the point ``(x_m, y_m)``, if any."""
        for bin_config in self.bins:
            if bin_config.contains_xy(x_m, y_m):
                return bin_config
        return None

    def bin_for(self, class_name: str) -> BinConfig | None:
        """The bin that sorts ``class_name``, if any."""
        for bin_config in self.bins:
            if bin_config.class_name == class_name:
                return bin_config
        return None
