"""Robot arms: what the twin loads and a controller plans with, and where their URDFs are."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from interfaces.catalog import entry, is_part_name, missing_fields
from interfaces.dataclass_io import from_data
from interfaces.errors import ConfigError, require


@dataclass(frozen=True, kw_only=True)
class RobotSpec:
    """A robot arm from a URDF: what the twin loads and the controller plans with.

    ``urdf`` is a path, a path under ``pybullet_data`` when it does not exist as given, or a
    ``package://`` URI of a package that ships robots (``package://example-robot-data/...``;
    :func:`resolve_urdf`). ``home_joint_positions`` is where the twin starts the arm.
    ``joint_position_limits_rad`` and ``joint_max_velocity_rps`` are the datasheet's (one per
    arm joint; empty: the URDF's); the URDF a station loads carries them
    (:func:`interfaces.urdf.station_urdf`), so the twin's joints and the controller's model
    agree. ``flange_link`` is where a flange-mounted tool attaches; whatever the URDF hangs
    below it (a hand it ships with) is replaced by that tool.
    The ready pose is in the robot's base frame: the TCP at ``ready_tcp_position_m`` pointing
    down with ``ready_yaw_rad``; ``ready_joint_positions_rad`` seeds the controller's IK towards
    it. ``joint_max_acceleration_rps2`` and ``joint_max_jerk_rps3`` are the datasheet limits
    (one per arm joint). ``position_gain`` and ``velocity_gain`` are the twin's joint motor
    gains. ``inertia_from_file`` takes the links' inertia tensors from the URDF; otherwise
    PyBullet computes them from the collision shapes and the URDF masses (pybullet_data's Panda
    carries placeholder inertias of 0.1 kg m^2 on every link, 10-100 times the identified ones).
    """

    name: str
    urdf: str
    arm_joints: tuple[str, ...]
    home_joint_positions: tuple[float, ...]
    ready_tcp_position_m: tuple[float, float, float]
    ready_yaw_rad: float
    ready_joint_positions_rad: tuple[float, ...]
    joint_max_acceleration_rps2: tuple[float, ...]
    joint_max_jerk_rps3: tuple[float, ...]
    joint_position_limits_rad: tuple[tuple[float, float], ...] = ()
    joint_max_velocity_rps: tuple[float, ...] = ()
    flange_link: str = ""
    position_gain: float = 0.1
    velocity_gain: float = 1.0
    inertia_from_file: bool = False

    def __post_init__(self) -> None:
        require(
            is_part_name(self.name),
            "robot.name",
            self.name,
            "1 to 64 letters, digits, '_', '-' or '.', not starting with '.'",
        )
        n = len(self.arm_joints)
        require(n > 0, "robot.arm_joints", self.arm_joints, "must not be empty")
        require(
            len(set(self.arm_joints)) == n, "robot.arm_joints", self.arm_joints, "must be unique"
        )
        for key in (
            "home_joint_positions",
            "ready_joint_positions_rad",
            "joint_max_acceleration_rps2",
            "joint_max_jerk_rps3",
        ):
            values: tuple[float, ...] = getattr(self, key)
            require(len(values) == n, f"robot.{key}", values, f"needs {n} values, one per joint")
        for key in ("joint_max_acceleration_rps2", "joint_max_jerk_rps3"):
            values = getattr(self, key)
            require(all(v > 0 for v in values), f"robot.{key}", values, "must be positive")
        for key in ("joint_position_limits_rad", "joint_max_velocity_rps"):
            values = getattr(self, key)
            require(len(values) in (0, n), f"robot.{key}", values, f"needs 0 or {n} values")
        require(
            all(lo < hi for lo, hi in self.joint_position_limits_rad),
            "robot.joint_position_limits_rad",
            self.joint_position_limits_rad,
            "every pair needs lower < upper",
        )
        require(
            all(v > 0 for v in self.joint_max_velocity_rps),
            "robot.joint_max_velocity_rps",
            self.joint_max_velocity_rps,
            "must be positive",
        )
        for key in ("position_gain", "velocity_gain"):
            gain: float = getattr(self, key)
            require(0 < gain <= MAX_GAIN, f"robot.{key}", gain, f"must be in (0, {MAX_GAIN}]")
        limits = self.joint_position_limits_rad
        for key in ("home_joint_positions", "ready_joint_positions_rad") if limits else ():
            values = getattr(self, key)
            for i, (q, (lo, hi)) in enumerate(zip(values, limits, strict=True)):
                require(
                    lo - 1e-6 <= q <= hi + 1e-6,
                    f"robot.{key}[{i}]",
                    q,
                    f"outside the joint's position limits [{lo}, {hi}] (joint_position_limits_rad)",
                )


MAX_GAIN = 100.0
"""Largest joint motor gain (PyBullet's position and velocity gains are fractions near 1)."""


def robot_from_data(value: object, where: str) -> RobotSpec:
    """A robot from a catalogue name or a mapping (a mapping lacking a required key, such as
    ``name``, is refused naming ``where`` and the key)."""
    data = entry(value, "robots", where)
    missing_fields(RobotSpec, data, where, "robot")
    return from_data(RobotSpec, data, where)


def package_root(package: str) -> Path:
    """The folder a ``package://<package>/`` URI points into, for the packages that ship robots
    here: ``pybullet_data`` and ``example-robot-data`` (its cmeel share folder)."""
    if package == "pybullet_data":
        import pybullet_data

        return Path(pybullet_data.getDataPath())
    if package == "example-robot-data":
        from importlib import metadata

        try:
            dist = metadata.distribution("example-robot-data")
        except metadata.PackageNotFoundError:
            msg = "package://example-robot-data: the example-robot-data wheel is not installed"
            raise ConfigError(msg) from None
        return Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data")))
    msg = f"package://{package}: unknown package (known: pybullet_data, example-robot-data)"
    raise ConfigError(msg)


def resolve_urdf(urdf: str) -> Path:
    """The URDF file ``urdf`` names: a ``package://`` URI (:func:`package_root`), a path as
    given if it exists, else a path under ``pybullet_data``."""
    if urdf.startswith("package://"):
        package, _, rest = urdf.removeprefix("package://").partition("/")
        candidate = package_root(package) / rest
        if candidate.is_file():
            return candidate
        msg = f"robot.urdf = {urdf!r}: no such file ({candidate})"
        raise ConfigError(msg)
    path = Path(urdf).expanduser()
    if path.is_file():
        return path.resolve()
    if not path.is_absolute():
        import pybullet_data

        candidate = Path(pybullet_data.getDataPath()) / urdf
        if candidate.is_file():
            return candidate
    msg = f"robot.urdf = {urdf!r}: neither a file nor a file under pybullet_data"
    raise ConfigError(msg)
