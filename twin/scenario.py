"""Scenarios: what one episode contains, as a frozen dataclass that round-trips to YAML.

Three levels, as in the reference: the *object* level (which images and objects, heights
re-sampled within class ranges, orientation jitter), the *system* level (belt speed, stochastic
perturbation, order and spacing of the stream) and *physics* (friction and restitution ranges per
class); besides them the perception (``perception``,
:class:`twin.perception_config.PerceptionConfig`)
and injected ``faults`` (detection dropout and belt stall windows, controller restarts), the
``controller``'s parameter file (the name of one shipped in ``control/config/``, such as
``default`` or ``throughput``, or a path relative to the scenario file) and the ``bins`` map
(which slot of a station's bins each class goes to, :class:`interfaces.bins.BinsMap`). Class
facts (height ranges, friction, restitution) are the dataset's class table's
(:mod:`interfaces.materials`, carried by the episode's resolved cell); the scenario's
``objects.height_ranges_m``, ``physics.friction`` and ``physics.restitution`` override them per
class. All randomness of an episode comes from one ``numpy.random.SeedSequence(seed)``; see
:func:`seed_tree`.

Example ``experiments/scenarios/default.yaml``::

    name: default
    dataset: builtin
    cell: default
    duration_s: 60.0
    system:
      belt_speed_mps: 0.4
    perception:
      position_noise_m: 0.002
    faults:
      detection_dropout: [[20.0, 25.0]]
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np
import yaml

from interfaces.bins import BinsMap, check_map
from interfaces.cell import Cell, load_cell, resolve_cell, resolve_cell_path
from interfaces.dataclass_io import from_data, to_data
from interfaces.errors import cut, cut_message, require
from interfaces.fileio import read_text_capped, write_atomic
from interfaces.materials import ClassTable
from interfaces.yamlio import load_yaml_strict
from twin.errors import ConfigError
from twin.perception_config import PerceptionConfig


def _check_range(key: str, lo_hi: tuple[float, float], lo: float, hi: float) -> None:
    a, b = lo_hi
    require(lo <= a <= b <= hi, key, list(lo_hi), f"needs {lo} <= low <= high <= {hi}")


@dataclass(frozen=True)
class ObjectLevel:
    """Which objects enter the belt and how they vary from their source annotation.

    ``classes``: only objects of these classes enter; empty (the default) lets every class of
    the dataset in. ``resample_heights`` draws every piece's height anew from its class's range:
    ``height_ranges_m``'s, else the class table's (``height_min_m``, ``height_max_m``).
    """

    images: tuple[str, ...] = ()
    max_objects: int | None = None
    resample_heights: bool = False
    height_ranges_m: dict[str, tuple[float, float]] = field(default_factory=dict)
    orientation_jitter_rad: float = 0.0
    classes: tuple[str, ...] = ()
    max_width_m: float | None = None
    """Only objects whose footprint's narrow side is at most this enter (e.g. what fits a
    gripper); None lets every object in."""
    min_height_m: float | None = None
    """Only objects at least this tall (after any resampling) enter (e.g. what the finger pads
    can hold); None lets every object in."""

    def __post_init__(self) -> None:
        if self.max_objects is not None:
            require(self.max_objects >= 1, "objects.max_objects", self.max_objects, "must be >= 1")
        if self.max_width_m is not None:
            require(self.max_width_m > 0.0, "objects.max_width_m", self.max_width_m, "must be > 0")
        if self.min_height_m is not None:
            require(
                0.0 < self.min_height_m < 1.0,
                "objects.min_height_m",
                self.min_height_m,
                "must be in (0, 1)",
            )
        require(
            0.0 <= self.orientation_jitter_rad <= np.pi,
            "objects.orientation_jitter_rad",
            self.orientation_jitter_rad,
            "must be in [0, pi]",
        )
        for name, rng in self.height_ranges_m.items():
            _check_range(f"objects.height_ranges_m.{name}", rng, 0.001, 1.0)
        require(
            len(set(self.classes)) == len(self.classes),
            "objects.classes",
            list(self.classes),
            "names a class twice",
        )


@dataclass(frozen=True)
class PerturbationLevel:
    """The belt drive's stochastic perturbation: an Ornstein-Uhlenbeck force on the belt (FMU)."""

    enabled: bool = False
    force_std_N: float = 40.0
    correlation_time_s: float = 0.5

    def __post_init__(self) -> None:
        require(
            self.force_std_N >= 0.0,
            "system.perturbation.force_std_N",
            self.force_std_N,
            "must be >= 0",
        )
        require(
            self.correlation_time_s > 0.0,
            "system.perturbation.correlation_time_s",
            self.correlation_time_s,
            "must be positive",
        )


@dataclass(frozen=True)
class SystemLevel:
    """Belt speed and the stream of objects.

    ``speed_schedule`` lists ``[time_s, speed_mps]`` setpoint changes. ``prefill_m`` starts the
    episode with the stream already carried that far: the belt is full from the first step.
    """

    belt_speed_mps: float = 0.4
    perturbation: PerturbationLevel = field(default_factory=PerturbationLevel)
    object_order: Literal["dataset", "shuffled"] = "dataset"
    image_gap_m: float = 0.25
    repeat_images: bool = True
    speed_schedule: tuple[tuple[float, float], ...] = ()
    prefill_m: float = 0.0

    def __post_init__(self) -> None:
        require(
            0.0 <= self.prefill_m <= 100.0,
            "system.prefill_m",
            self.prefill_m,
            "must be in [0, 100] m",
        )
        require(
            0.0 <= self.belt_speed_mps <= 2.0,
            "system.belt_speed_mps",
            self.belt_speed_mps,
            "must be in [0, 2] m/s",
        )
        require(
            0.0 <= self.image_gap_m <= 10.0,
            "system.image_gap_m",
            self.image_gap_m,
            "must be in [0, 10] m",
        )
        for i, (t_s, v) in enumerate(self.speed_schedule):
            require(
                t_s >= 0.0 and 0.0 <= v <= 2.0,
                f"system.speed_schedule[{i}]",
                [t_s, v],
                "needs time >= 0 and speed in [0, 2] m/s",
            )


@dataclass(frozen=True)
class PhysicsLevel:
    """Per-class contact properties, each drawn uniformly from its range per object: the
    ranges given here, else the class table's (``friction``, ``restitution`` of
    :class:`interfaces.materials.Material`)."""

    friction: dict[str, tuple[float, float]] = field(default_factory=dict)
    restitution: dict[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name, rng in self.friction.items():
            _check_range(f"physics.friction.{name}", rng, 0.0, 2.0)
        for name, rng in self.restitution.items():
            _check_range(f"physics.restitution.{name}", rng, 0.0, 1.0)


def _check_windows(key: str, windows: tuple[tuple[float, float], ...]) -> None:
    for i, (start_s, end_s) in enumerate(windows):
        require(
            0.0 <= start_s < end_s <= 86400.0,
            f"{key}[{i}]",
            [start_s, end_s],
            "needs 0 <= start_s < end_s <= 86400",
        )


@dataclass(frozen=True)
class FaultLevel:
    """Injected faults, in simulated seconds.

    ``detection_dropout``: ``[start_s, end_s]`` windows in which the camera delivers no frame.
    ``belt_stall``: windows in which the belt drive receives a setpoint of 0 whatever was commanded.
    ``controller_restart_at_s``: times at which ``cdw-twin run`` kills the controller process and
    starts a new one (the twin itself ignores this list).
    """

    detection_dropout: tuple[tuple[float, float], ...] = ()
    belt_stall: tuple[tuple[float, float], ...] = ()
    controller_restart_at_s: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        _check_windows("faults.detection_dropout", self.detection_dropout)
        _check_windows("faults.belt_stall", self.belt_stall)
        for i, t_s in enumerate(self.controller_restart_at_s):
            require(
                0.0 < t_s <= 86400.0,
                f"faults.controller_restart_at_s[{i}]",
                t_s,
                "must be in (0, 86400] s",
            )

    def stalled(self, time_s: float) -> bool:
        """Whether the belt is stalled at ``time_s`` (windows are ``[start, end)``)."""
        return any(start <= time_s < end for start, end in self.belt_stall)


MAX_NAME_CHARS = 100
"""Longest scenario name (it names a folder, with a time stamp after it)."""

MAX_SEED = 2**64 - 1
"""Largest seed (a 64-bit unsigned integer, as every generator and message takes one)."""


def _is_folder_name(name: str) -> bool:
    """Whether ``name`` is one path part that stays inside its parent folder."""
    return (
        bool(name.strip("."))
        and len(name) <= MAX_NAME_CHARS
        and name.isprintable()
        and not any(c in name for c in ("/", "\\", "\0"))
    )


@dataclass(frozen=True)
class Scenario:
    """One episode's definition. ``dataset`` is a meshgen output folder or ``builtin``.

    ``name`` names the run folder (``runs/<name>-<stamp>``), so it is one plain path part: not
    empty or only dots, without ``/``, ``\\`` or NUL (hence never absolute, never ``..``).

    ``cell`` names the cell file (:func:`scenario_cell`): a shipped cell's name or a path.
    ``controller`` names the controller's ROS 2 parameter file (checked by ``cdw-twin run``
    against the scenario's cell before anything starts): a file name without ``.yaml`` in
    ``control/config/``, or a path. ``bins`` puts classes into the slot of a station's bins it
    names (:class:`interfaces.bins.BinsMap`; the rest take the free slots in the class
    table's order, :func:`episode_cell`).
    """

    name: str = "default"
    dataset: str = "builtin"
    seed: int = 0
    duration_s: float = 60.0
    cell: str = "default"
    controller: str = "default"
    bins: BinsMap = field(default_factory=BinsMap)
    objects: ObjectLevel = field(default_factory=ObjectLevel)
    system: SystemLevel = field(default_factory=SystemLevel)
    physics: PhysicsLevel = field(default_factory=PhysicsLevel)
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    faults: FaultLevel = field(default_factory=FaultLevel)

    def __post_init__(self) -> None:
        require(
            _is_folder_name(self.name),
            "name",
            self.name,
            f"must be a plain folder name (not empty or only dots, at most {MAX_NAME_CHARS} "
            "printable characters, no '/', '\\' or NUL): runs go to runs/<name>-<stamp>",
        )
        for key in ("controller", "cell", "dataset"):
            value: str = getattr(self, key)
            require(
                0 < len(value) <= 4096 and "\0" not in value,
                key,
                value,
                "must be a name or a path (not empty, at most 4096 characters, no NUL)",
            )
        require(0 <= self.seed <= MAX_SEED, "seed", self.seed, "must be in [0, 2**64 - 1]")
        require(
            0.0 < self.duration_s <= 86400.0,
            "duration_s",
            self.duration_s,
            "must be in (0, 86400] s",
        )

    def to_yaml(self) -> str:
        """The scenario as YAML text."""
        return yaml.safe_dump(to_data(self), sort_keys=False)

    @classmethod
    def from_yaml(cls, text: str, where: str = "scenario") -> Scenario:
        """Parse YAML text; errors name ``where`` and the key (and the line of a key given
        twice, which is an error rather than the last one winning)."""
        data = load_yaml_strict(text, where)
        if data is None:
            msg = (
                f"{where}: the scenario is empty; write at least its name (`name: default`) "
                "to run the defaults"
            )
            raise ConfigError(msg)
        if not isinstance(data, dict):
            msg = f"{where}: the top level must be a mapping, got {type(data).__name__}"
            raise ConfigError(msg)
        try:
            return from_data(cls, data, "")
        except ConfigError as exc:
            msg = cut_message(f"{where}: {exc}")
            raise ConfigError(msg) from None

    @classmethod
    def load(cls, path: Path) -> Scenario:
        """Read a scenario file; a relative ``cell`` path is made absolute from the file's
        folder (so the scenario names the same cell wherever it is used from)."""
        text = read_text_capped(path, what="scenario")
        scenario = cls.from_yaml(text, where=str(path))
        cell = scenario.cell
        if _is_cell_path(cell) and not Path(cell).expanduser().is_absolute():
            scenario = replace(scenario, cell=str((path.parent / cell).resolve()))
        return scenario

    def save(self, path: Path) -> None:
        """Write the scenario atomically."""
        write_atomic(path, self.to_yaml())


def scenario_cell(scenario: Scenario, base_dir: Path | None = None, where: str = "") -> Cell:
    """The cell ``scenario.cell`` names: a shipped cell (``default``, ``two_pandas``) or a path,
    relative to ``base_dir`` (the scenario file's folder) when given. Errors name ``where``
    (the scenario) and the cell file."""
    prefix = f"{where}: " if where else ""
    try:
        path = resolve_cell_path(scenario.cell, base_dir)
    except ConfigError as exc:
        raise ConfigError(f"{prefix}{exc}") from None
    try:
        return load_cell(path)
    except ConfigError as exc:
        msg = cut_message(f"{prefix}cell = {cut(scenario.cell)}: {exc}")
        raise ConfigError(msg) from None


def episode_cell(scenario: Scenario, cell: Cell, table: ClassTable, where: str = "") -> Cell:
    """The cell an episode of ``scenario`` runs on: ``cell`` with its bin slots given the
    dataset's classes the scenario lets in (``objects.classes``; every class of ``table``, the
    dataset's class table, when empty), in the table's order or as the scenario's ``bins`` map
    says, and ``table`` as its class table (:func:`interfaces.cell.resolve_cell`). Every place
    that starts an episode resolves its cell here; errors name ``where`` (the scenario)."""
    wanted = scenario.objects.classes
    classes = tuple(c for c in table.names if not wanted or c in wanted)
    check_map(scenario.bins, table.names, [s.name for s in cell.stations], where or "scenario")
    return resolve_cell(cell, table, classes=classes, bins=scenario.bins, where=where)


def scenario_dataset(scenario: Scenario, base_dir: Path | None = None) -> Path:
    """The meshgen output folder ``scenario.dataset`` names: the built-in sample (meshed once,
    :func:`twin.builtin.builtin_dataset`) for ``builtin``, else a path, relative to
    ``base_dir`` (the scenario file's folder) when given."""
    if scenario.dataset == "builtin":
        from twin.builtin import builtin_dataset

        return builtin_dataset()
    dataset = Path(scenario.dataset)
    if not dataset.is_absolute() and base_dir is not None:
        dataset = (base_dir / dataset).resolve()
    return dataset


def _is_cell_path(value: str) -> bool:
    """Whether a scenario's ``cell`` is a path (else the name of a shipped cell)."""
    return "/" in value or value.endswith((".yaml", ".yml"))


class SeedTree(NamedTuple):
    """Independent generators for each random part of an episode, all from one seed."""

    objects: np.random.Generator
    order: np.random.Generator
    physics: np.random.Generator
    perception: np.random.Generator
    fmu_seed: int


def seed_tree(seed: int) -> SeedTree:
    """Split ``seed`` into the episode's independent streams (Gymnasium-style SeedSequence)."""
    root = np.random.SeedSequence(seed)
    objects, order, physics, perception, fmu = root.spawn(5)
    return SeedTree(
        objects=np.random.default_rng(objects),
        order=np.random.default_rng(order),
        physics=np.random.default_rng(physics),
        perception=np.random.default_rng(perception),
        fmu_seed=int(fmu.generate_state(1, dtype=np.uint32)[0]),
    )
