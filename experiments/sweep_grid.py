"""A sweep's grid: the grid file (:class:`Grid`), its expansion into grid cells (one scenario,
cell and seeds each), and the checks made before anything runs (every cell's scenario, cell,
controller parameters and dataset).
"""

from __future__ import annotations

import collections
import dataclasses
import itertools
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from interfaces.dataclass_io import from_data
from interfaces.errors import CdwTwinError, ConfigError, cut, cut_message
from interfaces.metrics import BY_NAME
from interfaces.yamlio import load_yaml_file

if TYPE_CHECKING:
    from experiments.run_types import Transport
    from interfaces.cell import Cell
    from twin.scenario import Scenario

MAX_GRID_EPISODES = 100_000
"""Most seeds (or episodes) of one grid cell."""


MAX_SEED = 2**64 - 1
"""Largest seed (:data:`twin.scenario.MAX_SEED`)."""


@dataclass(frozen=True)
class GridOverrides:
    """Values to sweep; each non-empty list multiplies the cells.

    ``cell``: the cell the scenario runs on (a shipped cell's name or a path relative to the
    grid file) instead of its own. ``stations``: run only the first k stations of the
    scenario's cell (in the cell file's order: a line lists its stations upstream first), so
    one grid gives a figure against the number of stations; the truncated cell is what the grid
    cell's run folder keeps as ``cell.yaml``.
    """

    speed: tuple[float, ...] = ()
    duration_s: tuple[float, ...] = ()
    mode: tuple[Literal["lockstep", "realtime"], ...] = ()
    cell: tuple[str, ...] = ()
    stations: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        for i, k in enumerate(self.stations):
            if k < 1:
                msg = f"overrides.stations[{i}] = {k!r}: must be >= 1 (the first k stations)"
                raise ConfigError(msg)
        for i, name in enumerate(self.cell):
            if not name:
                msg = f"overrides.cell[{i}] = {name!r}: name a shipped cell or a cell file"
                raise ConfigError(msg)
        for i, v in enumerate(self.speed):
            if not 0.0 <= v <= 2.0:
                msg = f"overrides.speed[{i}] = {v!r}: must be in [0, 2] m/s"
                raise ConfigError(msg)
        for i, v in enumerate(self.duration_s):
            if not 0.0 < v <= 86400.0:
                msg = f"overrides.duration_s[{i}] = {v!r}: must be in (0, 86400] s"
                raise ConfigError(msg)


@dataclass(frozen=True)
class Grid:
    """A sweep: scenario files, seeds (or an episode count) and overrides."""

    scenarios: tuple[str, ...] = ()
    seeds: tuple[int, ...] = ()
    episodes: int | None = None
    overrides: GridOverrides = field(default_factory=GridOverrides)
    dataset: str | None = None
    headline: tuple[str, ...] = ()
    """Metrics of the table that ``sweep.json`` lists first, per grid cell (``headline``):
    the figures the grid exists to measure."""

    def __post_init__(self) -> None:
        for i, name in enumerate(self.headline):
            if name not in BY_NAME:
                msg = f"headline[{i}] = {name!r}: not a metric of the table (docs/metrics.md)"
                raise ConfigError(msg)
        if not self.scenarios:
            msg = "scenarios = []: list at least one scenario file"
            raise ConfigError(msg)
        if self.seeds and self.episodes is not None:
            msg = "seeds and episodes: give one of them, not both"
            raise ConfigError(msg)
        if self.episodes is not None and self.episodes < 1:
            msg = f"episodes = {self.episodes}: must be >= 1"
            raise ConfigError(msg)
        if self.episodes is not None and self.episodes > MAX_GRID_EPISODES:
            msg = f"episodes = {self.episodes}: at most {MAX_GRID_EPISODES}"
            raise ConfigError(msg)
        if len(self.seeds) > MAX_GRID_EPISODES:
            msg = f"seeds: {len(self.seeds)} seeds, at most {MAX_GRID_EPISODES}"
            raise ConfigError(msg)
        for i, seed in enumerate(self.seeds):
            if not 0 <= seed <= MAX_SEED:
                msg = f"seeds[{i}] = {cut(seed)}: must be in [0, 2**64 - 1]"
                raise ConfigError(msg)
        counts = collections.Counter(self.seeds)
        repeated = sorted(seed for seed, n in counts.items() if n > 1)
        if repeated:
            shown = ", ".join(map(str, repeated[:8])) + (", ..." if len(repeated) > 8 else "")
            msg = (
                f"seeds = {cut(list(self.seeds))}: seed(s) {shown} repeated; "
                "every seed of a cell must be distinct (a repeat fakes a narrower interval)"
            )
            raise ConfigError(msg)

    @classmethod
    def load(cls, path: Path) -> Grid:
        """Read a grid file (:func:`interfaces.yamlio.load_yaml_file`: size-capped, UTF-8, a key
        given twice refused, alias bombs refused); errors name the file and the key."""
        data = load_yaml_file(path, what="grid")
        if not isinstance(data, dict):
            msg = f"{path}: the top level must be a mapping"
            raise ConfigError(msg)
        try:
            return from_data(cls, data, "")
        except ConfigError as exc:
            msg = cut_message(f"{path}: {exc}")
            raise ConfigError(msg) from None


@dataclass(frozen=True, kw_only=True)
class GridCell:
    """One grid cell: a resolved scenario, its run mode, seeds and folder name."""

    name: str
    scenario: Scenario
    scenario_path: Path
    mode: Literal["lockstep", "realtime"]
    seeds: tuple[int, ...]
    overrides: dict[str, Any]
    stations: int | None = None
    """Run only the first ``stations`` stations of the scenario's cell (None: all of them)."""


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "cell"


def _override_cell(value: str, base: Path) -> str:
    """A grid's ``cell`` override as a scenario's ``cell``: a shipped name as it is, a path
    made absolute from the grid file's folder."""
    if "/" in value or value.endswith((".yaml", ".yml")):
        path = Path(value).expanduser()
        return str(path if path.is_absolute() else (base / path).resolve())
    return value


def _apply(scenario: Scenario, chosen: dict[str, Any], base: Path) -> Scenario:
    """``scenario`` with the overrides of one grid cell applied (validated by the dataclass)."""
    resolved = scenario
    if "speed" in chosen:
        system = dataclasses.replace(resolved.system, belt_speed_mps=chosen["speed"])
        resolved = dataclasses.replace(resolved, system=system)
    if "duration_s" in chosen:
        resolved = dataclasses.replace(resolved, duration_s=chosen["duration_s"])
    if "cell" in chosen:
        resolved = dataclasses.replace(resolved, cell=_override_cell(chosen["cell"], base))
    return resolved


def expand(grid: Grid, base: Path) -> list[GridCell]:
    """The grid's cells in a fixed order (scenarios, then overrides as a product).

    Every scenario is loaded and every override applied (and validated) here, before anything
    runs. ``base`` is the grid file's folder.
    """
    from twin.scenario import Scenario

    axes = [(k, v) for k, v in dataclasses.asdict(grid.overrides).items() if v]
    names = [k for k, _ in axes]
    cells: list[GridCell] = []
    for entry in grid.scenarios:
        path = (base / entry).resolve()
        scenario = Scenario.load(path)
        for values in itertools.product(*(v for _, v in axes)):
            chosen = dict(zip(names, values, strict=True))
            resolved = _apply(scenario, chosen, base)
            seeds = grid.seeds or tuple(
                resolved.seed + i for i in range(grid.episodes if grid.episodes else 1)
            )
            suffix = "".join(f"-{k}{Path(v).stem if k == 'cell' else v}" for k, v in chosen.items())
            cells.append(
                GridCell(
                    name=_slug(f"{scenario.name}{suffix}"),
                    scenario=resolved,
                    scenario_path=path,
                    mode=chosen.get("mode", "lockstep"),
                    seeds=seeds,
                    overrides=chosen,
                    stations=chosen.get("stations"),
                )
            )
    seen: dict[str, int] = {}
    unique = []
    for cell in cells:
        n = seen.get(cell.name, 0)
        seen[cell.name] = n + 1
        unique.append(cell if n == 0 else dataclasses.replace(cell, name=f"{cell.name}-{n}"))
    return unique


def _own_dataset(grid: Grid, grid_path: Path, cell: GridCell) -> Path | None:
    """The dataset a cell names (the grid's, else its scenario's), None for the built-in one."""
    if grid.dataset is not None:
        return (grid_path.parent / grid.dataset).resolve()
    if cell.scenario.dataset != "builtin":
        return (cell.scenario_path.parent / cell.scenario.dataset).resolve()
    return None


@dataclass(frozen=True, kw_only=True)
class CheckedCell:
    """A grid cell validated before anything is written: its cell, parameters and dataset."""

    cell: GridCell
    params: Path
    station_cell: Cell
    dataset: Path
    own_dataset: Path | None


def first_stations(cell: Cell, k: int, where: str) -> Cell:
    """``cell`` with only its first ``k`` stations (named ``<name>_first<k>``); errors name
    ``where`` (the grid file) and the cell file when it has fewer."""
    n = len(cell.stations)
    if k > n:
        msg = (
            f"{where}: overrides.stations = {k}: the cell {cell.source or cell.name} has "
            f"{n} station(s)"
        )
        raise ConfigError(msg)
    if k == n:
        return cell
    return dataclasses.replace(cell, name=f"{cell.name}_first{k}", stations=cell.stations[:k])


def _check_cells(grid: Grid, grid_path: Path) -> list[CheckedCell]:
    """Every grid cell's scenario, cell file, controller parameters and dataset, checked."""
    from experiments.run import controller_params
    from twin.builtin import builtin_dataset
    from twin.scenario import scenario_cell
    from twin.scenario_check import check_scenario

    checked = []
    for cell in expand(grid, grid_path.parent):
        where = str(cell.scenario_path)
        station_cell = scenario_cell(cell.scenario, cell.scenario_path.parent, where)
        if cell.stations is not None:
            station_cell = first_stations(station_cell, cell.stations, str(grid_path))
        own = _own_dataset(grid, grid_path, cell)
        dataset = own or builtin_dataset()
        selection = check_scenario(cell.scenario, dataset, where=where, cell=station_cell)
        station_cell = selection.cell or station_cell
        params = controller_params(
            cell.scenario.controller, cell.scenario_path.parent, station_cell
        )
        checked.append(
            CheckedCell(
                cell=cell,
                params=params,
                station_cell=station_cell,
                dataset=dataset,
                own_dataset=own,
            )
        )
    return checked


def load_grid(grid_path: Path, dataset: Path | None = None) -> Grid:
    """The grid file, its ``dataset`` replaced by ``dataset`` (a path from the command line,
    relative to the working directory) when given."""
    grid = Grid.load(grid_path)
    if dataset is not None:
        grid = dataclasses.replace(grid, dataset=str(dataset.expanduser().resolve()))
    return grid


def check_sweep(
    grid_path: Path, *, dataset: Path | None = None, transport: Transport = "ros"
) -> tuple[Grid, list[CheckedCell]]:
    """Load the grid (its dataset replaced by ``dataset``, :func:`load_grid`) and check every
    grid cell's scenario, cell, controller parameters, dataset and transport; nothing is
    written."""
    from experiments.run import check_transport

    grid = load_grid(grid_path, dataset)
    checked = _check_cells(grid, grid_path)
    for c in checked:
        try:
            check_transport(transport, c.cell.mode, c.cell.scenario.faults.controller_restart_at_s)
        except CdwTwinError as exc:
            msg = f"{grid_path}: grid cell {c.cell.name}: {exc}"
            raise ConfigError(msg) from exc
    return grid, checked
