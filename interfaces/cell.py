"""The cell description: belt, belt drive, physics and stations, as data both sides read.

One YAML file describes a sorting cell. The twin builds its scene from it; each controller
process reads the same file and takes its own station (``--station NAME``); ``cdw-twin run``
copies the resolved description into the run folder. The built-in reference cell is
``interfaces/cells/default.yaml``: one Franka Emika Panda with its hand beside a 0.6 m belt and
one bin per class.

World frame (REP 103): metres, z up, origin at the first station's robot base in the reference
cell. The belt travels along +x; its centreline is at ``y = belt.centre_y_m`` and its top
surface at ``z = belt.surface_z_m``. Objects enter at ``belt.infeed_x_m`` and leave over the end
at ``belt.end_x_m``.

A station is one robot with one tool, its pick window (an x interval over the belt's width) and
its bins; its per-robot topics live under its ROS ``namespace`` (``""`` keeps the bare names of
a one-station cell). ``robot`` and ``tool`` are either a name from the catalogue
(``interfaces/catalog.yaml``: robots ``panda``, ``xarm6``; tools ``panda_hand``,
``xarm_gripper``) or a full mapping. A bin sorts one class; the classes a cell sorts are those
of its bins. A bin that names no class is a slot (:mod:`interfaces.bins`): :func:`resolve_cell`
gives it one of the dataset's classes when an episode starts (the shipped cells' bins are all
slots); read without a dataset, the slots take the classes of the cell's class table in order.

The optional ``materials:`` section is the class table of the pieces the cell sorts
(:mod:`interfaces.materials`: density, height range, friction, restitution, seal efficiency and
colour per class, over the shipped table); without it the shipped table. A run's resolved cell
carries its dataset's, every bin with its class.

The belt drive is a co-simulation FMU: ``builtin`` is ours (``fmus/belt_drive``, FMI 3), any
other value a path (relative to the cell file) to a third-party FMU whose variables
``mapping`` names; ``parameters`` are set before initialisation. Every error names the file and
the dotted key.

The optional ``cameras:`` list declares the cell's RGB-D cameras (:class:`interfaces.camera.
RgbdCameraSpec`: name, pose of ``NAME_link`` in the world, image size, field of view, rate,
depth range, depth noise), which a scenario with ``perception.source: camera`` renders and
detects on (``docs/camera.md``); every camera must see the belt, and together they must see the
belt's centreline :data:`CAMERA_UPSTREAM_VIEW_M` upstream of the first pick window. The
``camera`` field-of-view interval stays: the oracle's detections come from it.

An impossible cell is refused when it is loaded (:func:`check_layout`): every physical quantity
is finite and within its range (a positive size, gravity pointing down, a vacuum below the
atmosphere's pressure), every pick window lies on the belt downstream of the infeed, no two
robot bases stand within :data:`MIN_BASE_SEPARATION_M` of each other, no two bins overlap, no
bin reaches over the belt or below the floor. What needs the robots' URDFs (each pick window
within its robot's reach) is checked with the scenario (:mod:`twin.scenario_check`). The file
is read through :func:`interfaces.yamlio.load_yaml_file`: at most 1 MB of UTF-8 without NUL,
no key given twice, no alias bomb; an empty file is refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import yaml

from interfaces.bins import MAX_COORDINATE_M, BinsMap, BinSpec, assign_bins
from interfaces.camera import RgbdCameraSpec, belt_view_x_m, sees_point
from interfaces.dataclass_io import from_data, to_data
from interfaces.errors import ConfigError, cut, cut_message, require
from interfaces.fileio import write_atomic
from interfaces.materials import ClassTable, shipped_table, table_from_data
from interfaces.robots import RobotSpec, robot_from_data
from interfaces.tools import ToolSpec, tool_from_data
from interfaces.yamlio import load_yaml_file

CELLS_DIR = Path(__file__).resolve().parent / "cells"
"""Folder of the cell files shipped with the project (``default``, ``two_pandas``, ...)."""

DEFAULT_CELL = CELLS_DIR / "default.yaml"
"""The reference cell."""

MAX_STATIONS = 64
"""Most stations a cell may have."""


class CellError(ConfigError):
    """A cell description is malformed or inconsistent (the message names file and key)."""


def _finite(values: tuple[float, ...]) -> bool:
    return all(math.isfinite(v) for v in values)


# -- belt, drive, physics -------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class BeltSpec:
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
        require(
            0 < self.width_m <= MAX_BELT_WIDTH_M,
            "belt.width_m",
            self.width_m,
            f"must be in (0, {MAX_BELT_WIDTH_M:g}] m",
        )
        require(
            self.end_x_m > self.start_x_m, "belt.end_x_m", self.end_x_m, "must exceed start_x_m"
        )
        require(
            self.end_x_m - self.start_x_m <= MAX_BELT_LENGTH_M,
            "belt.end_x_m",
            self.end_x_m,
            f"the belt may be at most {MAX_BELT_LENGTH_M:g} m long (end_x_m - start_x_m)",
        )
        for key in ("start_x_m", "end_x_m", "infeed_x_m", "centre_y_m", "surface_z_m"):
            value: float = getattr(self, key)
            require(
                abs(value) <= MAX_COORDINATE_M,
                f"belt.{key}",
                value,
                f"must be within +-{MAX_COORDINATE_M:g} m (finite)",
            )
        require(
            self.start_x_m <= self.infeed_x_m < self.end_x_m,
            "belt.infeed_x_m",
            self.infeed_x_m,
            "must lie on the belt",
        )
        require(
            0 < self.thickness_m <= 1.0, "belt.thickness_m", self.thickness_m, "must be in (0, 1] m"
        )
        require(
            0 <= self.lateral_friction <= MAX_FRICTION,
            "belt.lateral_friction",
            self.lateral_friction,
            f"must be in [0, {MAX_FRICTION:g}]",
        )

    @property
    def length_m(self) -> float:
        """Belt length along x."""
        return self.end_x_m - self.start_x_m

    def on_belt_xy(self, x_m: float, y_m: float) -> bool:
        """Whether a point's projection lies on the belt surface."""
        half = 0.5 * self.width_m
        return self.start_x_m <= x_m <= self.end_x_m and abs(y_m - self.centre_y_m) <= half


MAX_BELT_WIDTH_M = 5.0
"""Widest belt a cell may have."""

MAX_BELT_LENGTH_M = 1000.0
"""Longest belt a cell may have."""

MAX_FRICTION = 10.0
"""Largest friction coefficient (real surfaces stay below 2)."""


@dataclass(frozen=True, kw_only=True)
class DriveMapping:
    """Names of the FMU variables that play each role; the defaults are our BeltDrive FMU's.

    ``load_mass``, ``motor_torque`` and ``motor_current`` may be None for drives without them.
    """

    speed_setpoint: str = "speed_setpoint_mps"
    load_mass: str | None = "load_mass_kg"
    belt_speed: str = "belt_speed_mps"
    belt_position: str = "belt_position_m"
    motor_torque: str | None = "motor_torque_Nm"
    motor_current: str | None = "motor_current_A"


@dataclass(frozen=True, kw_only=True)
class PerturbationMapping:
    """The FMU parameters a scenario's stochastic belt perturbation sets (ours has all three)."""

    force_std: str = "perturbation_std_N"
    correlation_time: str = "perturbation_correlation_time_s"
    seed: str = "perturbation_seed"


@dataclass(frozen=True, kw_only=True)
class DriveSpec:
    """The belt drive: an FMI 2 or 3 co-simulation FMU and how the twin talks to it.

    ``fmu`` is ``builtin`` (ours) or a path; a relative path is resolved against the cell file
    when the cell is loaded. ``step_s`` is the communication step (None: every physics step).
    ``perturbation`` names the parameters a scenario's perturbation sets (None: the drive has
    none, and a scenario that enables one is refused).
    """

    fmu: str = "builtin"
    mapping: DriveMapping = field(default_factory=DriveMapping)
    parameters: dict[str, float] = field(default_factory=dict)
    perturbation: PerturbationMapping | None = field(default_factory=PerturbationMapping)
    step_s: float | None = None

    def __post_init__(self) -> None:
        require(bool(self.fmu), "drive.fmu", self.fmu, "must not be empty")
        require(
            len(self.fmu) <= 4096 and "\0" not in self.fmu,
            "drive.fmu",
            self.fmu,
            "a path of at most 4096 characters, without NUL",
        )
        if self.step_s is not None:
            require(
                0 < self.step_s <= MAX_DRIVE_STEP_S,
                "drive.step_s",
                self.step_s,
                f"must be in (0, {MAX_DRIVE_STEP_S}] s",
            )

    @property
    def builtin(self) -> bool:
        """Whether the drive is our own BeltDrive FMU."""
        return self.fmu == "builtin"


MAX_DRIVE_STEP_S = 1.0
"""Longest belt-drive communication step (``twin.belt_drive.MAX_STEP_S`` refuses longer)."""


@dataclass(frozen=True, kw_only=True)
class PhysicsSpec:
    """Solver settings. The step is fixed.

    ``hull_merge_tolerance`` and ``max_convex_pieces`` bound the collision-shape complexity of
    concave objects (see :mod:`twin.collision`).
    """

    physics_hz: float = 240.0
    solver_iterations: int = 10
    hull_merge_tolerance: float = 0.1
    max_convex_pieces: int = 6
    floor_z_m: float = -0.8
    gravity_mps2: float = 9.81

    def __post_init__(self) -> None:
        require(
            0 < self.physics_hz <= MAX_PHYSICS_HZ,
            "physics.physics_hz",
            self.physics_hz,
            f"must be in (0, {MAX_PHYSICS_HZ:g}] Hz",
        )
        require(
            1 <= self.solver_iterations <= 1000,
            "physics.solver_iterations",
            self.solver_iterations,
            "must be in [1, 1000]",
        )
        require(
            0 <= self.hull_merge_tolerance <= 10,
            "physics.hull_merge_tolerance",
            self.hull_merge_tolerance,
            "must be in [0, 10]",
        )
        require(
            1 <= self.max_convex_pieces <= 256,
            "physics.max_convex_pieces",
            self.max_convex_pieces,
            "must be in [1, 256]",
        )
        require(
            0 < self.gravity_mps2 <= MAX_GRAVITY_MPS2,
            "physics.gravity_mps2",
            self.gravity_mps2,
            f"must be in (0, {MAX_GRAVITY_MPS2:g}] m/s^2: the magnitude of gravity, which "
            "points down (-z)",
        )
        require(
            abs(self.floor_z_m) <= MAX_COORDINATE_M,
            "physics.floor_z_m",
            self.floor_z_m,
            f"must be within +-{MAX_COORDINATE_M:g} m",
        )

    @property
    def dt_s(self) -> float:
        """The physics step."""
        return 1.0 / self.physics_hz


MAX_PHYSICS_HZ = 10_000.0
"""Highest physics rate a cell may ask for."""

MAX_GRAVITY_MPS2 = 100.0
"""Largest gravity a cell may ask for (10 g)."""


@dataclass(frozen=True, kw_only=True)
class CameraSpec:
    """The camera over the belt: it sees objects on the belt with x in ``[fov_min_x_m,
    fov_max_x_m]`` (a line's camera must see upstream of its first pick window)."""

    fov_min_x_m: float = -1.4
    fov_max_x_m: float = 0.45

    def __post_init__(self) -> None:
        require(
            self.fov_max_x_m > self.fov_min_x_m,
            "camera.fov_max_x_m",
            self.fov_max_x_m,
            "must exceed fov_min_x_m",
        )


# -- stations and bins ----------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class StationSpec:
    """One robot with its tool, pick window and bins; its topics under ``namespace``."""

    name: str
    namespace: str = ""
    robot: RobotSpec
    tool: ToolSpec
    base_position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    base_yaw_rad: float = 0.0
    pick_window_x_m: tuple[float, float] = (-0.35, 0.35)
    bins: tuple[BinSpec, ...] = ()
    bin_layout: tuple[BinSpec, ...] = field(default=(), compare=False, repr=False)
    """The bins as the cell file lists them, slots included (:func:`resolve_cell` assigns
    them again from here); empty when ``bins`` are the file's own. Never written out."""

    def __post_init__(self) -> None:
        require(
            bool(self.name) and len(self.name) <= 64 and self.name.replace("_", "").isalnum(),
            "station.name",
            self.name,
            "1 to 64 letters, digits and underscores only",
        )
        require(
            self.namespace == ""
            or (len(self.namespace) <= 64 and self.namespace.replace("_", "").isalnum()),
            "station.namespace",
            self.namespace,
            "empty, or letters, digits and underscores (a ROS namespace without slashes)",
        )
        lo, hi = self.pick_window_x_m
        require(lo < hi, "station.pick_window_x_m", self.pick_window_x_m, "needs min < max")
        require(
            _finite(self.base_position_m)
            and all(abs(v) <= MAX_COORDINATE_M for v in self.base_position_m),
            "station.base_position_m",
            self.base_position_m,
            f"must be finite, within +-{MAX_COORDINATE_M:g} m",
        )
        require(
            math.isfinite(self.base_yaw_rad) and abs(self.base_yaw_rad) <= 4 * math.pi,
            "station.base_yaw_rad",
            self.base_yaw_rad,
            "must be finite, within +-4 pi",
        )
        classes = [b.class_name for b in self.bins if not b.slot]
        require(
            len(set(classes)) == len(classes),
            "station.bins",
            classes,
            "one bin per class at a station",
        )

    def bin_for(self, class_name: str) -> BinSpec | None:
        """The station's bin that sorts ``class_name``, if any (a slot sorts nothing)."""
        if not class_name:
            return None
        return next((b for b in self.bins if b.class_name == class_name), None)

    def in_window(self, x_m: float) -> bool:
        """Whether ``x_m`` lies in the station's pick window."""
        lo, hi = self.pick_window_x_m
        return lo <= x_m <= hi

    def ready_tcp_position_world_m(self) -> tuple[float, float, float]:
        """The robot's ready TCP position in the world frame."""
        return self.to_world(self.robot.ready_tcp_position_m)

    def to_world(self, p: tuple[float, float, float]) -> tuple[float, float, float]:
        """A point of the robot's base frame in the world frame."""
        c, s = math.cos(self.base_yaw_rad), math.sin(self.base_yaw_rad)
        bx, by, bz = self.base_position_m
        x, y, z = p
        if self.base_yaw_rad == 0.0:
            return (bx + x, by + y, bz + z)
        return (bx + c * x - s * y, by + s * x + c * y, bz + z)


# -- the cell -------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class Cell:
    """Everything physical about the cell; ``source`` is the file it was read from.

    ``materials`` is the class table of the pieces it sorts (:mod:`interfaces.materials`: the
    density, heights, friction, restitution, seal efficiency and colour of every class): a
    run's resolved cell carries its dataset's (:func:`resolve_cell`), a cell file without a
    ``materials:`` section the shipped one.
    """

    name: str = "cell"
    belt: BeltSpec = field(default_factory=BeltSpec)
    camera: CameraSpec = field(default_factory=CameraSpec)
    cameras: tuple[RgbdCameraSpec, ...] = ()
    drive: DriveSpec = field(default_factory=DriveSpec)
    physics: PhysicsSpec = field(default_factory=PhysicsSpec)
    stations: tuple[StationSpec, ...] = ()
    materials: ClassTable = field(default_factory=shipped_table)
    source: str = ""

    def __post_init__(self) -> None:
        require(len(self.stations) > 0, "stations", self.stations, "list at least one station")
        names = [s.name for s in self.stations]
        require(len(set(names)) == len(names), "stations", names, "station names must differ")
        spaces = [s.namespace for s in self.stations]
        require(
            len(set(spaces)) == len(spaces),
            "stations",
            spaces,
            "station namespaces must differ (two stations cannot share their topics)",
        )
        cams = [c.name for c in self.cameras]
        require(len(set(cams)) == len(cams), "cameras", cams, "camera names must differ")
        for i, station in enumerate(self.stations):
            for j, b in enumerate(station.bins):
                require(
                    not self.belt.on_belt_xy(b.centre_x_m, b.centre_y_m),
                    bin_key(i, j, b),
                    (b.centre_x_m, b.centre_y_m),
                    "stands on the belt",
                )
        check_layout(self)

    @property
    def classes(self) -> tuple[str, ...]:
        """Every class some station has a bin for, in the order the bins are listed."""
        seen: dict[str, None] = {}
        for station in self.stations:
            for b in station.bins:
                if not b.slot:
                    seen.setdefault(b.class_name)
        return tuple(seen)

    @property
    def bins(self) -> tuple[BinSpec, ...]:
        """Every bin of every station."""
        return tuple(b for s in self.stations for b in s.bins)

    def bin_at(self, x_m: float, y_m: float) -> BinSpec | None:
        """The first bin whose inner area holds the point ``(x_m, y_m)``, if any."""
        for station in self.stations:
            for bin_spec in station.bins:
                if bin_spec.contains_xy(x_m, y_m):
                    return bin_spec
        return None

    def station(self, name: str) -> StationSpec:
        """The station called ``name`` (:class:`CellError` naming the known ones otherwise)."""
        for station in self.stations:
            if station.name == name:
                return station
        known = ", ".join(s.name for s in self.stations)
        msg = f"{self.source or 'cell'}: no station named {name!r} (the cell has: {known})"
        raise CellError(msg)

    @property
    def last_window_max_x_m(self) -> float:
        """The downstream end of the most downstream pick window (past it, an object is lost
        to the line)."""
        return max(s.pick_window_x_m[1] for s in self.stations)

    def to_yaml(self) -> str:
        """The resolved cell as YAML (every robot and tool written out in full, every bin with
        its class, the class table as ``materials:``)."""
        data = to_data(self)
        data.pop("source", None)
        for station in data["stations"]:
            station.pop("bin_layout", None)
        data["materials"] = self.materials.to_data()
        return yaml.safe_dump(data, sort_keys=False)

    def save(self, path: Path) -> None:
        """Write the resolved cell atomically (e.g. into a run folder)."""
        write_atomic(path, self.to_yaml())


# -- layout ---------------------------------------------------------------------------------
def bin_key(station: int, index: int, bin_spec: BinSpec) -> str:
    """How an error names a bin: ``stations[i].bins[<class>]``, a slot by its index."""
    return f"stations[{station}].bins[{bin_spec.class_name or index}]"


MIN_BASE_SEPARATION_M = 0.3
"""Closest two stations' robot bases may stand (their footprints would overlap)."""

CAMERA_UPSTREAM_VIEW_M = 0.1
"""How far upstream of the first pick window a cell's cameras must see the belt's centreline
(a piece is detected before it enters the first window)."""


def check_cameras(cell: Cell) -> None:
    """Refuse cameras that cannot serve the line (:class:`ConfigError` naming the key): a
    camera that sees none of the belt's centreline, or cameras none of which sees the
    centreline :data:`CAMERA_UPSTREAM_VIEW_M` upstream of the first pick window."""
    if not cell.cameras:
        return
    belt = cell.belt
    for i, spec in enumerate(cell.cameras):
        seen = belt_view_x_m(spec, centre_y_m=belt.centre_y_m, surface_z_m=belt.surface_z_m)
        require(
            seen is not None and seen[1] > belt.start_x_m and seen[0] < belt.end_x_m,
            f"cameras[{i}] ({spec.name}).position_m",
            spec.position_m,
            "the camera sees none of the belt's centreline (check its pose, field of view and "
            "depth range)",
        )
    first_x_m = min(s.pick_window_x_m[0] for s in cell.stations)
    point = (first_x_m - CAMERA_UPSTREAM_VIEW_M, belt.centre_y_m, belt.surface_z_m)
    require(
        any(sees_point(spec, point) for spec in cell.cameras),
        "cameras",
        [spec.name for spec in cell.cameras],
        f"no camera sees the belt's centreline at x = {point[0]:.3g} m, "
        f"{CAMERA_UPSTREAM_VIEW_M:g} m upstream of the first pick window",
    )


def _squares_overlap(a: BinSpec, b: BinSpec) -> bool:
    """Whether the outer squares of two bins overlap (touching is fine)."""
    reach = a.half_m + b.half_m - 1e-9
    return abs(a.centre_x_m - b.centre_x_m) < reach and abs(a.centre_y_m - b.centre_y_m) < reach


def _bin_over_belt(belt: BeltSpec, b: BinSpec) -> bool:
    """Whether a bin's outer square overlaps the belt's surface (seen from above)."""
    half_w = 0.5 * belt.width_m
    return (
        b.centre_x_m + b.half_m > belt.start_x_m + 1e-9
        and b.centre_x_m - b.half_m < belt.end_x_m - 1e-9
        and abs(b.centre_y_m - belt.centre_y_m) < half_w + b.half_m - 1e-9
    )


def check_layout(cell: Cell) -> None:
    """Refuse a cell whose parts cannot stand where it puts them (:class:`ConfigError` naming
    the key): a pick window that is not on the belt downstream of the infeed; two robot bases
    within :data:`MIN_BASE_SEPARATION_M`; two bins (of any stations) whose squares overlap; a
    bin that reaches over the belt; a bin or the belt below the physics floor; a camera that
    sees none of the belt. The robots' reach needs their URDFs: see
    :func:`interfaces.urdf.check_station_reach`."""
    belt, floor = cell.belt, cell.physics.floor_z_m
    require(
        floor < belt.surface_z_m - belt.thickness_m,
        "physics.floor_z_m",
        floor,
        f"must lie below the belt (surface_z_m {belt.surface_z_m:g} - thickness_m "
        f"{belt.thickness_m:g})",
    )
    camera = cell.camera
    require(
        camera.fov_max_x_m > belt.start_x_m and camera.fov_min_x_m < belt.end_x_m,
        "camera.fov_min_x_m",
        [camera.fov_min_x_m, camera.fov_max_x_m],
        f"the camera sees none of the belt (x from {belt.start_x_m:g} to {belt.end_x_m:g} m)",
    )
    for i, station in enumerate(cell.stations):
        lo, hi = station.pick_window_x_m
        require(
            belt.start_x_m <= lo and hi <= belt.end_x_m and hi > belt.infeed_x_m,
            f"stations[{i}].pick_window_x_m",
            station.pick_window_x_m,
            f"must lie on the belt (x from {belt.start_x_m:g} to {belt.end_x_m:g} m) and end "
            f"downstream of its infeed ({belt.infeed_x_m:g} m)",
        )
        for j, other in enumerate(cell.stations[:i]):
            gap = math.dist(station.base_position_m[:2], other.base_position_m[:2])
            require(
                gap >= MIN_BASE_SEPARATION_M,
                f"stations[{i}].base_position_m",
                station.base_position_m,
                f"{gap:.3g} m from the base of stations[{j}] ({other.name}): two robots "
                f"cannot stand closer than {MIN_BASE_SEPARATION_M:g} m",
            )
    placed: list[tuple[str, BinSpec]] = []
    for i, station in enumerate(cell.stations):
        for j, b in enumerate(station.bins):
            key = bin_key(i, j, b)
            require(
                not _bin_over_belt(belt, b),
                key,
                (b.centre_x_m, b.centre_y_m),
                f"its {b.size_m:g} m square reaches over the belt",
            )
            require(
                b.floor_z_m >= floor,
                f"{key}.floor_z_m",
                b.floor_z_m,
                f"lies below the floor (physics.floor_z_m {floor:g})",
            )
            for other_key, earlier in placed:
                require(
                    not _squares_overlap(b, earlier),
                    key,
                    (b.centre_x_m, b.centre_y_m),
                    f"overlaps {other_key} at {(earlier.centre_x_m, earlier.centre_y_m)}: two bins "
                    "cannot stand in one place",
                )
            placed.append((key, b))
    check_cameras(cell)


# -- loading --------------------------------------------------------------------------------
def _station_from_data(raw: object, where: str) -> StationSpec:
    if not isinstance(raw, dict):
        msg = f"{where} = {cut(raw)}: expected a mapping"
        raise CellError(msg)
    data = dict(raw)
    for key in ("robot", "tool"):
        if key not in data:
            msg = f"{where}: missing {key!r}"
            raise CellError(msg)
    if "bin_layout" in data:
        msg = f"{where}: unknown key 'bin_layout' (a station lists its bins under bins)"
        raise CellError(msg)
    robot = robot_from_data(data.pop("robot"), f"{where}.robot")
    tool = tool_from_data(data.pop("tool"), f"{where}.tool")
    return from_data(StationSpec, {**data, "robot": robot, "tool": tool}, where)


def _cameras_from_data(raw: object, where: str) -> tuple[RgbdCameraSpec, ...]:
    """The ``cameras:`` list (None or absent: none); errors name ``cameras[i]``."""
    if raw is None:
        return ()
    if not isinstance(raw, list):
        msg = f"{where}: cameras = {cut(raw)}: expected a list of cameras"
        raise CellError(msg)
    cameras = []
    for i, item in enumerate(raw):
        try:
            cameras.append(from_data(RgbdCameraSpec, item, f"cameras[{i}]"))
        except ConfigError as exc:
            text = str(exc)
            if not text.startswith(f"cameras[{i}]"):
                text = f"cameras[{i}]: {text}"
            raise CellError(cut_message(f"{where}: {text}")) from None
    return tuple(cameras)


def cell_from_data(data: object, where: str, *, base_dir: Path | None = None) -> Cell:
    """Build a cell from plain data (a parsed YAML file); errors name ``where`` and the key.

    A relative ``drive.fmu`` path is resolved against ``base_dir``. The ``materials:``
    section, when there is one, is a class table over the shipped one
    (:func:`interfaces.materials.table_from_data`); the station's slots take its classes in
    its order (:func:`resolve_cell`) until a run resolves them against its dataset.
    """
    if not isinstance(data, dict):
        msg = f"{where}: the top level must be a mapping"
        raise CellError(msg)
    raw = dict(data)
    raw_stations = raw.pop("stations", None)
    raw["cameras"] = _cameras_from_data(raw.pop("cameras", []), where)
    if not isinstance(raw_stations, list) or not raw_stations:
        msg = f"{where}: stations = {cut(raw_stations)}: list at least one station"
        raise CellError(msg)
    if len(raw_stations) > MAX_STATIONS:
        msg = f"{where}: stations: {len(raw_stations)} stations, more than {MAX_STATIONS}"
        raise CellError(msg)
    try:
        if "materials" in raw:
            raw["materials"] = table_from_data(raw["materials"], "materials", shipped_table())
        stations = tuple(
            _station_from_data(s, f"stations[{i}]") for i, s in enumerate(raw_stations)
        )
    except ConfigError as exc:
        msg = cut_message(f"{where}: {exc}")
        raise CellError(msg) from None
    try:
        cell = from_data(Cell, {**raw, "stations": stations, "source": where}, "")
    except ConfigError as exc:
        msg = cut_message(f"{where}: {exc}")
        raise CellError(msg) from None
    fmu = cell.drive.fmu
    if not cell.drive.builtin and base_dir is not None and not Path(fmu).is_absolute():
        cell = replace(cell, drive=replace(cell.drive, fmu=str((base_dir / fmu).resolve())))
    return resolve_cell(cell, cell.materials, strict=False)


def resolve_cell(
    cell: Cell,
    table: ClassTable,
    *,
    classes: tuple[str, ...] | None = None,
    bins: BinsMap | None = None,
    where: str = "",
    strict: bool = True,
) -> Cell:
    """``cell`` with every station's bin slots given a class (:func:`interfaces.bins.
    assign_bins`) and ``table`` as its class table: the one function that resolves a cell
    for an episode.

    The slots take ``classes`` (default: ``table``'s, in its order; an episode passes the
    classes of its dataset the scenario lets in), or the slot the scenario's ``bins`` map
    names; each station starts again from the bins its file lists (``bin_layout``), so a
    cell resolved once (with the shipped table, when it was loaded) can be resolved for any
    dataset. A cell whose bins all name their class is only given ``table``. Raises
    :class:`CellError` naming ``where`` (the scenario), the cell file, the station and what
    does not fit; not ``strict`` (when a cell file is read, before any dataset), a station with
    fewer free slots than classes sorts the first ones.
    """
    names = table.names if classes is None else classes
    slot_map = bins if bins is not None else BinsMap()
    prefix = f"{where}: " if where else ""
    stations = []
    for i, station in enumerate(cell.stations):
        layout = station.bin_layout or station.bins
        try:
            assigned = assign_bins(
                layout,
                names,
                slot_map.at(station.name),
                where=f"stations[{i}] ({station.name})",
                strict=strict,
            )
        except ConfigError as exc:
            msg = cut_message(f"{prefix}the cell {cell.source or cell.name}: {exc}")
            raise CellError(msg) from None
        has_slots = any(b.slot for b in layout)
        stations.append(replace(station, bins=assigned, bin_layout=layout if has_slots else ()))
    try:
        return replace(cell, stations=tuple(stations), materials=table)
    except ConfigError as exc:
        msg = cut_message(f"{prefix}the cell {cell.source or cell.name}: {exc}")
        raise CellError(msg) from None


def load_cell(path: Path | str | None = None) -> Cell:
    """Read a cell file: a path, a name of a shipped cell (``default``), or None (default)."""
    resolved = resolve_cell_path(path)
    try:
        data = load_yaml_file(resolved, what="cell file")
    except ConfigError as exc:
        raise CellError(cut_message(str(exc))) from None
    if data is None:
        msg = f"{resolved}: the cell file is empty"
        raise CellError(msg)
    try:
        return cell_from_data(data, str(resolved), base_dir=resolved.parent)
    except CellError as exc:
        raise CellError(cut_message(str(exc))) from None
    except ConfigError as exc:
        msg = cut_message(f"{resolved}: {exc}")
        raise CellError(msg) from None


def resolve_cell_path(path: Path | str | None, base_dir: Path | None = None) -> Path:
    """The cell file ``path`` names: None or ``default`` is the reference cell; a bare name
    without ``/`` or ``.yaml`` is a shipped cell; anything else a path (relative to
    ``base_dir`` when given)."""
    if path is None:
        return DEFAULT_CELL
    text = str(path)
    if not text or "\0" in text or len(text) > 4096:
        msg = f"cell = {cut(text)}: not a cell name or path (empty, NUL or over 4096 characters)"
        raise CellError(msg)
    if "/" not in text and not text.endswith((".yaml", ".yml")):
        shipped = CELLS_DIR / f"{text}.yaml"
        if not shipped.is_file():
            known = ", ".join(sorted(p.stem for p in CELLS_DIR.glob("*.yaml")))
            msg = f"cell = {cut(text)}: no shipped cell of that name (shipped: {known})"
            raise CellError(msg)
        return shipped
    resolved = Path(text).expanduser()
    if not resolved.is_absolute() and base_dir is not None:
        resolved = base_dir / resolved
    return resolved.resolve()


def default_cell() -> Cell:
    """The reference cell (``interfaces/cells/default.yaml``)."""
    return load_cell(DEFAULT_CELL)
