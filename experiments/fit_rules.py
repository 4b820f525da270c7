"""The stations ``cdw-twin fit`` judges, and the pieces of a dataset as the camera reports them.

Whether a station could take a piece at all is the controllers' own rule
(:mod:`control.fit`: :class:`~control.fit.Piece`, :func:`~control.fit.takeable`,
:func:`~control.fit.line_refusal`, re-exported here), the one the twin marks every spawned
piece with. :func:`flat_pieces` computes what the camera reports of a meshgen output's pieces
lying flat on the belt, as the stream spawns them (the mesh as meshgen wrote it, turned about z
only, which changes neither the face turned up nor its disc), by the twin's own geometry
(:class:`twin.spawn_fit.SeenShapes`).

The stations judged are those of a cell, resolved for the dataset as an episode resolves it
(:func:`cell_setups`), or one per catalogue tool (:func:`catalogue_setups`: each tool on its
robot in a one-station cell built in memory from a shipped cell, with that cell's controller
parameter file), every one with the dataset's class table (densities for the too-heavy check).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from control.config import (
    DEFAULT_PARAMS,
    PARAMS_DIR,
    ControllerConfig,
    load_config,
    station_configs,
)
from control.config import params_path as controller_params_path
from control.fit import REFUSALS, Piece, line_refusal, takeable
from interfaces.bins import BinSpec
from interfaces.catalog import CATALOG, catalog_names
from interfaces.cell import Cell, load_cell, resolve_cell
from interfaces.errors import CdwTwinError
from interfaces.materials import ClassTable
from interfaces.robots import robot_from_data
from interfaces.tools import tool_from_data

if TYPE_CHECKING:
    from twin.objects import ObjectSpec

FLANGE_ROBOT = "ur10"
"""The robot a flange-mounted catalogue tool is judged on (the line's)."""

FLANGE_TEMPLATE = "line"
"""The shipped cell (and parameter file of that name) a flange tool's station is built from."""

BUILTIN_TOOL_ROBOTS: dict[str, str] = {"panda_hand": "panda", "xarm_gripper": "xarm6"}
"""The catalogue robot whose URDF carries each built-in (not flange-mounted) catalogue tool."""

BUILTIN_TEMPLATE = "default"
"""The shipped cell (and parameter file of that name) a built-in tool's station is built from."""

_EXTRA_BIN_GAP_M = 0.3

FloatArray = npt.NDArray[np.float64]


class FitError(CdwTwinError):
    """The fit of a dataset cannot be judged (the message names the folder, file or name)."""


UP_TOLERANCE = 0.01
"""Triangles whose unit normal's z is within this of the highest one's may belong to the face
turned up (:func:`facing_up`); the finder's faces group normals to 1e-3."""


def facing_up(triangles: FloatArray) -> FloatArray:
    """Those of a mesh's ``(t, 3, 3)`` triangles whose unit normal's z lies within
    :data:`UP_TOLERANCE` of the highest: all of the face turned up when the mesh lies as it is
    (the face whose normal points most nearly up, :mod:`twin.suction_point`) and no face that
    could win over it, so the suction point's finder gives the same disc from them alone."""
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    norms = np.linalg.norm(cross, axis=1)
    up = np.divide(cross[:, 2], norms, out=np.full(len(norms), -np.inf), where=norms > 1e-12)
    kept: FloatArray = triangles[up >= up.max() - UP_TOLERANCE]
    return kept


def flat_pieces(objects: Sequence[ObjectSpec]) -> tuple[Piece, ...]:
    """Each object of a meshgen output as the camera reports it lying flat on the belt.

    The seen box and the suction point's radius and tilt come from its mesh as the twin
    computes them for a spawned piece (:class:`twin.spawn_fit.SeenShapes`), in the pose the
    stream spawns it in: the mesh as written (its top cap turned up, tilt 0). Reads every mesh
    once, and hands the finder only its triangles :func:`facing_up` (the same answer, ten
    times sooner).
    """
    from twin.objects import read_obj_triangles
    from twin.spawn_fit import SeenShapes

    seen = SeenShapes(lambda spec, _: facing_up(read_obj_triangles(spec.mesh_path)))
    pieces = []
    for spec in objects:
        length_m, width_m, height_m, radius_m, tilt_rad = seen(
            spec, spec.height_m, (0.0, 0.0, 0.0, 1.0)
        )
        pieces.append(
            Piece(
                class_name=spec.class_name,
                length_m=length_m,
                width_m=width_m,
                height_m=height_m,
                face_radius_m=radius_m,
                face_tilt_rad=tilt_rad,
            )
        )
    return tuple(pieces)


def check_meshgen_folder(folder: Path) -> None:
    """:class:`FitError` naming ``folder`` unless it is a meshgen output (meshgen's marker
    file, or an older output's ``index.csv`` header)."""
    from meshgen.export import INDEX_COLUMNS
    from meshgen.outdir import MARKER_NAME, is_meshgen_output

    if not folder.is_dir():
        msg = f"{folder}: no such folder" if not folder.exists() else f"{folder}: not a folder"
        raise FitError(msg)
    if is_meshgen_output(folder):
        return
    index = folder / "index.csv"
    try:
        with index.open(encoding="utf-8", newline="") as handle:
            header = tuple(handle.readline().rstrip("\r\n").split(","))
    except (OSError, UnicodeDecodeError):
        header = ()
    if header != INDEX_COLUMNS:
        msg = (
            f"{folder}: not a meshgen output folder (no {MARKER_NAME} marker, no meshgen "
            "index.csv); make one with `cdw-twin meshgen`"
        )
        raise FitError(msg)


@dataclass(frozen=True, kw_only=True)
class StationSetup:
    """One station whose fit is judged: ``name`` (the cell's station, or the catalogue tool's
    name), its ``tool`` and ``robot`` (catalogue names), the controller parameter file
    ``params`` and the configuration loaded from it for that station."""

    name: str
    tool: str
    robot: str
    params: Path
    config: ControllerConfig


def params_path(value: str) -> Path:
    """The controller parameter file ``value`` names (:func:`control.config.params_path`: a
    bare name is one shipped in ``control/config/``, such as ``line``, anything else a path).
    :class:`FitError` naming the value when there is no such file."""
    try:
        path = controller_params_path(value).resolve()
    except CdwTwinError as exc:
        msg = f"--controller {value!r}: {exc}"
        raise FitError(msg) from None
    if not path.is_file():
        msg = f"--controller {value!r}: no such file ({path})"
        raise FitError(msg)
    return path


def default_params(cell_path: Path) -> Path:
    """The parameter file a cell's controllers use by default: the shipped file of the cell
    file's name (``line`` for ``interfaces/cells/line.yaml``), else ``default``."""
    shipped = PARAMS_DIR / f"{cell_path.stem}.yaml"
    return shipped if shipped.is_file() else DEFAULT_PARAMS


def cell_setups(cell: Cell, params: Path) -> tuple[StationSetup, ...]:
    """Every station of ``cell`` (resolved for the dataset), upstream first as listed, with its
    configuration from the parameter file ``params``."""
    configs = station_configs(params, cell)
    return tuple(
        StationSetup(
            name=station.name,
            tool=station.tool.name,
            robot=station.robot.name,
            params=params,
            config=config,
        )
        for station, config in zip(cell.stations, configs, strict=True)
    )


@cache
def _template(name: str) -> Cell:
    return load_cell(name)


def _with_bins(cell: Cell, classes: Sequence[str]) -> tuple[BinSpec, ...]:
    """The first station's bins plus one for each of ``classes`` it lacks, placed beside the
    belt well away from it (where does not matter to the fit; a bin must exist)."""
    station = cell.stations[0]
    missing = [c for c in classes if station.bin_for(c) is None]
    edge_y_m = cell.belt.centre_y_m - 0.5 * cell.belt.width_m - 1.0
    extra = tuple(
        BinSpec(
            class_name=name,
            centre_x_m=station.base_position_m[0],
            centre_y_m=edge_y_m - _EXTRA_BIN_GAP_M * k,
        )
        for k, name in enumerate(missing)
    )
    return station.bins + extra


def catalogue_setups(table: ClassTable) -> tuple[StationSetup, ...]:
    """One station per catalogue tool (``interfaces/catalog.yaml``, in its order), with a bin
    for each class of ``table`` (the dataset's class table, the cells' too): a flange tool on a
    :data:`FLANGE_ROBOT` in the first station of the shipped cell :data:`FLANGE_TEMPLATE` with
    its parameter file; a built-in tool on its robot (:data:`BUILTIN_TOOL_ROBOTS`) in the first
    station of :data:`BUILTIN_TEMPLATE` with its parameter file. The template station's bin
    slots take the first classes, a bin beside the belt each class left over."""
    classes = table.names
    setups = []
    for name in catalog_names()["tools"]:
        spec = tool_from_data(name, f"{CATALOG}: tools.{name}")
        if spec.mount == "flange":
            template_name, robot_name = FLANGE_TEMPLATE, FLANGE_ROBOT
        else:
            template_name = BUILTIN_TEMPLATE
            robot_name = BUILTIN_TOOL_ROBOTS.get(name, "")
            if not robot_name:
                known = ", ".join(f"{t} ({r})" for t, r in BUILTIN_TOOL_ROBOTS.items())
                msg = (
                    f"{CATALOG}: tools.{name}: a built-in tool, on no robot fit knows "
                    f"(experiments.fit_rules.BUILTIN_TOOL_ROBOTS: {known})"
                )
                raise FitError(msg)
        shipped = _template(template_name)
        slots = len(shipped.stations[0].bin_layout or shipped.stations[0].bins)
        template = resolve_cell(shipped, table, classes=classes[:slots])
        station = replace(
            template.stations[0],
            robot=robot_from_data(robot_name, f"{CATALOG}: robots.{robot_name}"),
            tool=spec,
            bins=_with_bins(template, classes),
        )
        cell = replace(template, name=f"fit_{name}", stations=(station,))
        params = PARAMS_DIR / f"{template_name}.yaml"
        setups.append(
            StationSetup(
                name=name,
                tool=name,
                robot=robot_name,
                params=params,
                config=load_config(params, cell=cell, station=station.name),
            )
        )
    return tuple(setups)


__all__ = [
    "REFUSALS",
    "FitError",
    "Piece",
    "StationSetup",
    "catalogue_setups",
    "cell_setups",
    "check_meshgen_folder",
    "default_params",
    "facing_up",
    "flat_pieces",
    "line_refusal",
    "params_path",
    "takeable",
]
