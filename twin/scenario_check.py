"""Check a scenario against its dataset and its cell, completely, before anything starts.

:class:`twin.scenario.Scenario` checks each value on its own when it is built; what needs the
dataset or the cell is checked here, once per run, so that a mistake is one line naming the
scenario file and the key instead of a traceback from a process that already started, or an
episode that runs without objects. Checked:

- ``dataset``: an existing meshgen output folder (``index.csv`` and the ``.cdw-meshgen`` marker,
  or, for outputs written before the marker existed, an ``index.csv`` with meshgen's header);
- ``objects.classes``, ``objects.height_ranges_m``, ``physics.friction`` and
  ``physics.restitution``: every class they name is a class the dataset has. A friction or
  restitution range equal to the shipped class table's for that class is exempt (a scenario a
  run wrote out lists the shipped classes' ranges, and a dataset need not have them all);
- ``bins``: every class the map names is a class of the dataset, every station a station of
  the cell;
- ``objects.images``: every name is an image of the dataset that has objects;
- the object filters (``objects.images``, ``classes``, ``max_width_m``, ``min_height_m``, in the
  order :class:`twin.stream.Stream` applies them) leave at least one object; the error names the
  filter that emptied the selection. An object whose height is re-sampled counts as kept when its
  class's range reaches ``min_height_m``. ``max_objects`` (at least 1) only caps the stream;
- the cell (the scenario's ``cell``, or the one passed), its bin slots given the dataset's
  classes (:func:`twin.scenario.episode_cell`; a station with fewer free slots than classes is
  refused naming the station and the counts): every class that can enter the belt (the
  classes of the objects the filters keep) has a bin at some station (the error names the
  class and the cell file); a scenario that enables the belt perturbation needs a drive
  with a perturbation mapping; a third-party drive's FMU file is an FMU (a zip archive with
  an FMI 2.0 or 3.0 co-simulation model description) that has every variable the drive's
  ``mapping``, ``parameters`` and perturbation mapping name (:func:`twin.belt_drive.plan_fmu`:
  the model description only, nothing is instantiated);
- every station's robot: its URDF can be read and carries the arm joints and the tool's TCP
  link, and the station's pick window, along the belt's centreline, lies within the robot's
  reach (:func:`interfaces.urdf.station_reach`, an upper bound: what lies beyond it can never be
  reached);
- ``system.prefill_m``: at most the belt's run from the infeed to its end, the farthest the
  stream can have been carried while still on the belt;
- fault and schedule times: every ``faults.detection_dropout`` and ``faults.belt_stall`` window,
  ``faults.controller_restart_at_s`` time and ``system.speed_schedule`` time within
  ``[0, duration_s]``.

The dataset is read with :func:`twin.objects.load_dataset` (every ``scene.csv`` once; meshes are
only checked to exist, never loaded), with the class table meshgen recorded in ``classes.yaml``
(:func:`interfaces.materials.dataset_table`).

Example::

    scenario, dataset, cell = build_scenario(args)  # checks them with check_scenario
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from interfaces.cell import Cell
from interfaces.errors import cut
from interfaces.materials import ClassTable, MaterialsError, dataset_table, shipped_table
from interfaces.urdf import station_reach
from meshgen.outdir import MARKER_NAME, is_meshgen_output
from twin.belt_drive import plan_fmu
from twin.errors import ConfigError, FmuError, SceneError
from twin.objects import ImageLayout, ObjectSpec, load_dataset
from twin.scenario import Scenario, episode_cell, scenario_cell

_SHOWN = 8
"""How many names an error message lists before it abbreviates."""


@dataclass(frozen=True)
class Selection:
    """What the scenario's object filters keep of the dataset in one pass over its images.

    ``classes``: the classes the dataset's objects have (sorted). ``images``: the images with at
    least one kept object, in dataset order. ``objects``: how many objects one pass keeps (before
    ``objects.max_objects`` caps the stream). ``entering``: the classes of the kept objects
    (sorted): those that can enter the belt.
    """

    classes: tuple[str, ...]
    images: tuple[str, ...]
    objects: int
    entering: tuple[str, ...] = ()
    cell: Cell | None = field(default=None, compare=False, repr=False)
    """The cell the episode runs on, its bins resolved for the dataset
    (:func:`twin.scenario.episode_cell`)."""


def check_scenario(
    scenario: Scenario,
    dataset_dir: Path,
    *,
    where: str,
    cell: Cell | None = None,
    base_dir: Path | None = None,
) -> Selection:
    """Check ``scenario`` against the meshgen output ``dataset_dir`` and ``cell``.

    ``where`` names the scenario (its file) in the messages; ``cell`` defaults to the one the
    scenario names (relative to ``base_dir``, the scenario file's folder). The cell's bins are
    resolved for the dataset (:func:`twin.scenario.episode_cell`: its slots take the dataset's
    classes) before every class that can enter is checked to have one; the returned
    selection's ``cell`` is the resolved cell. Raises :class:`ConfigError` (one line:
    ``where``, the key, the value and what is wrong) at the first problem; returns what the
    object filters keep.
    """
    cell = cell if cell is not None else scenario_cell(scenario, base_dir, where)
    _check_times(scenario, where)
    _check_prefill(scenario, cell, where)
    _check_drive(scenario, cell, where)
    _check_stations(cell, where)
    layouts = _read_dataset(dataset_dir, where)
    table = _read_table(dataset_dir, where)
    classes = tuple(sorted({spec.class_name for lay in layouts for spec in lay.objects}))
    _check_class_names(scenario, classes, where)
    _check_images(scenario, layouts, where)
    selection = _select(scenario, layouts, classes, table, where)
    cell = episode_cell(scenario, cell, table, where)
    _check_bins(selection, cell, where)
    return replace(selection, cell=cell)


def _read_table(dataset_dir: Path, where: str) -> ClassTable:
    """The dataset's class table (:func:`interfaces.materials.dataset_table`)."""
    try:
        return dataset_table(dataset_dir)
    except MaterialsError as exc:
        msg = f"{where}: dataset = '{dataset_dir}': {exc}"
        raise ConfigError(msg) from None


def _fail(where: str, key: str, value: object, what: str) -> ConfigError:
    msg = f"{where}: {key} = {cut(value)}: {what}"
    return ConfigError(msg)


def _names(names: Iterable[str]) -> str:
    items = list(names)
    shown = ", ".join(repr(n) for n in items[:_SHOWN])
    return shown + (f", ... ({len(items)} in all)" if len(items) > _SHOWN else "")


def _cell_file(cell: Cell) -> str:
    return cell.source or f"cell {cell.name!r}"


def _check_bins(selection: Selection, cell: Cell, where: str) -> None:
    sorted_by_cell = set(cell.classes)
    for name in selection.entering:
        if name not in sorted_by_cell:
            msg = (
                f"{where}: class {name!r} can enter the belt but no station of the cell "
                f"{_cell_file(cell)} has a bin for it (its bins sort: {_names(cell.classes)}); "
                "add a bin for it, or leave it out with objects.classes"
            )
            raise ConfigError(msg)


def _check_drive(scenario: Scenario, cell: Cell, where: str) -> None:
    drive = cell.drive
    if scenario.system.perturbation.enabled and drive.perturbation is None:
        what = (
            f"the belt drive of the cell {_cell_file(cell)} ({drive.fmu}) has no perturbation "
            "mapping (drive.perturbation)"
        )
        raise _fail(where, "system.perturbation.enabled", True, what)
    if drive.builtin:
        return
    if not Path(drive.fmu).is_file():
        msg = f"{where}: the cell {_cell_file(cell)}: drive.fmu = {cut(drive.fmu)}: no such file"
        raise ConfigError(msg)
    parameters: dict[str, object] = dict(drive.parameters)
    names = drive.perturbation
    if names is not None:
        parameters.setdefault(names.force_std, 0.0)
        parameters.setdefault(names.correlation_time, 0.5)
        parameters.setdefault(names.seed, 0)
    try:
        plan_fmu(Path(drive.fmu), drive.mapping, parameters)
    except FmuError as exc:
        msg = f"{where}: the cell {_cell_file(cell)}: drive: {exc}"
        raise ConfigError(msg) from None


def _check_stations(cell: Cell, where: str) -> None:
    """Every station's URDF reads and its pick window lies within its robot's reach."""
    belt = cell.belt
    for i, station in enumerate(cell.stations):
        key = f"stations[{i}] ({station.name})"
        try:
            reach = station_reach(station.robot, station.tool)
        except ConfigError as exc:
            msg = f"{where}: the cell {_cell_file(cell)}: {key}: {exc}"
            raise ConfigError(msg) from None
        origin = station.to_world(reach.origin_m)
        for x_m in station.pick_window_x_m:
            point = (x_m, belt.centre_y_m, belt.surface_z_m)
            distance = math.dist(origin, point)
            if distance > reach.reach_m:
                msg = (
                    f"{where}: the cell {_cell_file(cell)}: stations[{i}].pick_window_x_m = "
                    f"{list(station.pick_window_x_m)}: the belt's centreline at x = {x_m:g} m "
                    f"is {distance:.3f} m from the robot's first joint, beyond the reach of "
                    f"{station.robot.name} with {station.tool.name} "
                    f"(at most {reach.reach_m:.3f} m); move the base or the window"
                )
                raise ConfigError(msg)


def _check_times(scenario: Scenario, where: str) -> None:
    duration = scenario.duration_s
    within = f"must lie within the episode, [0, {duration:g}] s (duration_s)"
    faults = scenario.faults
    for key, windows in (
        ("faults.detection_dropout", faults.detection_dropout),
        ("faults.belt_stall", faults.belt_stall),
    ):
        for i, (start_s, end_s) in enumerate(windows):
            if not 0.0 <= start_s <= end_s <= duration:
                raise _fail(where, f"{key}[{i}]", [start_s, end_s], within)
    for i, t_s in enumerate(faults.controller_restart_at_s):
        if not 0.0 <= t_s <= duration:
            raise _fail(where, f"faults.controller_restart_at_s[{i}]", t_s, within)
    for i, (t_s, speed) in enumerate(scenario.system.speed_schedule):
        if not 0.0 <= t_s <= duration:
            raise _fail(where, f"system.speed_schedule[{i}]", [t_s, speed], within)


def _check_prefill(scenario: Scenario, cell: Cell, where: str) -> None:
    belt = cell.belt
    run_m = round(belt.end_x_m - belt.infeed_x_m, 9)
    if scenario.system.prefill_m > run_m:
        what = (
            f"must be at most {run_m:g} m, the belt's run from the infeed to its end "
            "(belt.end_x_m - belt.infeed_x_m): farther, the stream is carried off the belt"
        )
        raise _fail(where, "system.prefill_m", scenario.system.prefill_m, what)


def _check_meshgen_folder(dataset_dir: Path, where: str) -> Path:
    def refuse(what: str) -> ConfigError:
        return ConfigError(f"{where}: dataset = '{dataset_dir}': {what}")

    if not dataset_dir.exists():
        raise refuse("no such folder")
    if not dataset_dir.is_dir():
        raise refuse("not a folder")
    index = dataset_dir / "index.csv"
    if not index.is_file():
        raise refuse("no index.csv: not a meshgen output folder (make one with `cdw-twin meshgen`)")
    if is_meshgen_output(dataset_dir):
        return index
    from interfaces.scene_csv import INDEX_COLUMNS

    try:
        with index.open(encoding="utf-8", newline="") as handle:
            header = tuple(handle.readline().rstrip("\r\n").split(","))
    except (OSError, UnicodeDecodeError) as exc:
        raise refuse(f"cannot read index.csv: {exc}") from None
    if header != INDEX_COLUMNS:
        raise refuse(
            f"neither a {MARKER_NAME} marker nor meshgen's index.csv header "
            f"({','.join(INDEX_COLUMNS)}): not a meshgen output folder"
        )
    return index


def _read_dataset(dataset_dir: Path, where: str) -> tuple[ImageLayout, ...]:
    _check_meshgen_folder(dataset_dir, where)
    try:
        return load_dataset(dataset_dir)
    except SceneError as exc:
        msg = f"{where}: dataset = '{dataset_dir}': {exc}"
        raise ConfigError(msg) from None


def _check_class_names(scenario: Scenario, classes: tuple[str, ...], where: str) -> None:
    known = set(classes)
    lacks = f"names a class the dataset lacks (its classes: {_names(classes)})"
    objects = scenario.objects
    for i, name in enumerate(objects.classes):
        if name not in known:
            raise _fail(where, f"objects.classes[{i}]", name, lacks)
    for name in objects.height_ranges_m:
        if name not in known:
            raise _fail(where, "objects.height_ranges_m", name, f"key {lacks}")
    shipped = shipped_table()
    for key, table, field_name in (
        ("physics.friction", scenario.physics.friction, "friction"),
        ("physics.restitution", scenario.physics.restitution, "restitution"),
    ):
        for name in _changed_keys(table, shipped, field_name):
            if name not in known:
                raise _fail(where, key, name, f"key {lacks}")


def _changed_keys(
    table: Mapping[str, tuple[float, float]], shipped: ClassTable, field_name: str
) -> list[str]:
    """The classes of ``table`` whose range is not the shipped class table's own (a scenario
    written out by a run, or before the class table existed, lists those for the shipped
    classes, which a dataset need not all have)."""
    return [
        name
        for name, rng in table.items()
        if not shipped.names_class(name)
        or getattr(shipped.material(name), field_name) != tuple(rng)
    ]


def _check_images(scenario: Scenario, layouts: tuple[ImageLayout, ...], where: str) -> None:
    present = {lay.image for lay in layouts}
    unmatched = [name for name in scenario.objects.images if name not in present]
    if unmatched:
        what = (
            f"{_names(unmatched)} match no image with objects in the dataset "
            f"({len(layouts)} images: {_names(lay.image for lay in layouts)})"
        )
        raise _fail(where, "objects.images", list(scenario.objects.images), what)


def _tallest_m(scenario: Scenario, spec: ObjectSpec, table: ClassTable) -> float:
    """The tallest the object can enter: the top of its class's range when re-sampled (the
    scenario's, else the class table's)."""
    objects = scenario.objects
    if objects.resample_heights:
        if spec.class_name in objects.height_ranges_m:
            return objects.height_ranges_m[spec.class_name][1]
        return table.material(spec.class_name).height_max_m
    return spec.height_m


def _select(
    scenario: Scenario,
    layouts: tuple[ImageLayout, ...],
    classes: tuple[str, ...],
    table: ClassTable,
    where: str,
) -> Selection:
    objects = scenario.objects
    wanted = set(objects.images)
    kept = [
        (lay.image, spec)
        for lay in layouts
        if not wanted or lay.image in wanted
        for spec in lay.objects
    ]
    before = kept
    kept = [
        (image, spec)
        for image, spec in before
        if not objects.classes or spec.class_name in objects.classes
    ]
    if not kept:
        present = sorted({spec.class_name for _, spec in before})
        what = f"leaves no object: the {len(before)} objects it filters have classes {present}"
        raise _fail(where, "objects.classes", list(objects.classes), what)
    if objects.max_width_m is not None:
        limit_m = objects.max_width_m
        before = kept
        kept = [(i, s) for i, s in before if min(s.width_m, s.length_m) <= limit_m]
        if not kept:
            narrowest = min(min(s.width_m, s.length_m) for _, s in before)
            what = (
                f"leaves no object: the narrowest of the {len(before)} objects the filters "
                f"before it keep is {narrowest:.3g} m across"
            )
            raise _fail(where, "objects.max_width_m", limit_m, what)
    if objects.min_height_m is not None:
        floor_m = objects.min_height_m
        before = kept
        kept = [(i, s) for i, s in before if _tallest_m(scenario, s, table) >= floor_m]
        if not kept:
            tallest = max(_tallest_m(scenario, s, table) for _, s in before)
            what = (
                f"leaves no object: the tallest of the {len(before)} objects the filters "
                f"before it keep is {tallest:.3g} m tall"
            )
            raise _fail(where, "objects.min_height_m", floor_m, what)
    images = tuple(dict.fromkeys(image for image, _ in kept))
    entering = tuple(sorted({spec.class_name for _, spec in kept}))
    return Selection(classes=classes, images=images, objects=len(kept), entering=entering)
