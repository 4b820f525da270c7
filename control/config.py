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

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any, cast

from control.config_sections import (
    ALLOCATION_STRATEGIES,
    APPROACH_SPACES,
    RANKS,
    AllocationConfig,
    IkConfig,
    MotionConfig,
    NodeConfig,
    PickConfig,
    SchedulerConfig,
    TrackingConfig,
    _require,
)
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


__all__ = [
    "ALLOCATION_STRATEGIES",
    "APPROACH_SPACES",
    "DEFAULT_PARAMS",
    "OVERRIDES",
    "PARAMS_DIR",
    "RANKS",
    "SECTIONS",
    "AllocationConfig",
    "ControllerConfig",
    "IkConfig",
    "MotionConfig",
    "NodeConfig",
    "PickConfig",
    "SchedulerConfig",
    "TrackingConfig",
    "config_from_mapping",
    "load_config",
    "merged_params",
    "params_path",
    "station_configs",
]
