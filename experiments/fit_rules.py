"""Whether a station could take a piece at all, by the rules its controller applies.

A controller leaves a piece untargeted for reasons of two kinds: static ones, that no timing or
clutter changes (no bin for its class, the tool does not fit it, it is too heavy for the tool),
and the rest (too late, out of reach, blocked, claimed...). This module answers the static
question without a simulator, for one piece and one station's
:class:`~control.config.ControllerConfig`: :func:`takeable` asks the station's tool
(:meth:`~control.tools.ControllerTool.misfit`) and the scheduler's mass check
(:func:`~control.scheduler.holds_estimate`) exactly as the scheduler does for a track, so a
piece it refuses is one the station's controller would never target. It is cheap (no mesh, no
PyBullet): the twin can ask it for every spawned piece.

A :class:`Piece` is what the camera reports of a piece: its class, seen box and the suction
point's disc radius and face tilt (:mod:`twin.suction_point`). :func:`flat_pieces` computes them
for a meshgen output's pieces lying flat on the belt, as the stream spawns them (the mesh as
meshgen wrote it, turned about z only, which changes neither the face turned up nor its disc).

The stations judged are those of a cell (:func:`cell_setups`) or one per catalogue tool
(:func:`catalogue_setups`: each tool on its robot in a one-station cell built in memory from a
shipped cell, with that cell's controller parameter file).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from control.cmd_controller import DEFAULT_PARAMS
from control.config import ControllerConfig, load_config
from control.scheduler import UNTARGETED_REASONS, holds_estimate
from control.tracking import Track
from interfaces.catalog import CATALOG, catalog_names
from interfaces.cell import BinSpec, Cell, load_cell
from interfaces.errors import CdwTwinError
from interfaces.robots import robot_from_data
from interfaces.tools import tool_from_data

if TYPE_CHECKING:
    from twin.objects import ObjectSpec

REFUSALS: tuple[str, ...] = tuple(
    r
    for r in UNTARGETED_REASONS
    if r in {"no_bin", "too_wide", "too_flat", "too_small", "too_tilted", "too_heavy"}
)
"""The static reasons a station refuses a piece, in the order the scheduler checks them."""

PARAMS_DIR = DEFAULT_PARAMS.parent
"""The shipped controller parameter files (``control/config/``)."""

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


@dataclass(frozen=True, kw_only=True)
class Piece:
    """What the camera reports of one piece on the belt, all a station's static rules need.

    ``length_m`` and ``width_m`` are its footprint as seen from above, ``height_m`` its height;
    ``face_radius_m`` the radius of the largest disc on its upturned face and ``face_tilt_rad``
    that face's tilt from level (the detection's ``suction_radius_m``, ``suction_tilt_rad``;
    NaN: none reported, as a camera without a suction-point finder).
    """

    class_name: str
    length_m: float
    width_m: float
    height_m: float
    face_radius_m: float = math.nan
    face_tilt_rad: float = math.nan

    @property
    def narrow_m(self) -> float:
        """The narrow side of the footprint, what a gripper's opening must take."""
        return min(self.length_m, self.width_m)


def _track(piece: Piece) -> Track:
    """A confirmed, certain track at rest standing for ``piece`` (what the scheduler judges)."""
    return Track(
        track_id=0,
        stamp_s=0.0,
        class_name=piece.class_name,
        class_confidence=1.0,
        position_m=(0.0, 0.0),
        velocity_mps=(0.0, 0.0),
        position_std_m=0.0,
        yaw_rad=0.0,
        length_m=max(piece.length_m, piece.width_m),
        width_m=piece.narrow_m,
        height_m=piece.height_m,
        hits=1,
        confirmed=True,
        last_update_s=0.0,
        suction_radius_m=piece.face_radius_m,
        suction_tilt_rad=piece.face_tilt_rad,
    )


def takeable(piece: Piece, config: ControllerConfig) -> str | None:
    """Why the station ``config`` drives would never target ``piece`` (one of
    :data:`REFUSALS`), or None when it could take it.

    The scheduler's static checks in its order: ``no_bin`` (the station sorts no such class),
    the tool's :meth:`~control.tools.ControllerTool.misfit` with the scheduler's width margin
    (``too_wide``, ``too_flat``, ``too_small``, ``too_tilted``), then ``too_heavy``
    (:func:`~control.scheduler.holds_estimate`: the mass estimated from the seen box and the
    parameter file's class density). A certain detection: confidence is not judged.
    """
    if piece.class_name not in config.bins:
        return "no_bin"
    misfit = config.tool.misfit(
        length_m=piece.length_m,
        width_m=piece.width_m,
        height_m=piece.height_m,
        width_margin_m=config.scheduler.grasp_width_margin_m,
        face_radius_m=piece.face_radius_m,
        face_tilt_rad=piece.face_tilt_rad,
    )
    if misfit is not None:
        return misfit
    if not holds_estimate(_track(piece), config):
        return "too_heavy"
    return None


def line_refusal(piece: Piece, configs: Sequence[ControllerConfig]) -> str | None:
    """None when some station of ``configs`` could take ``piece``; otherwise every station's
    reason (:func:`takeable`), the distinct ones in :data:`REFUSALS` order joined by ``+``
    (``too_flat+too_small``: the jaws found it too flat, the cups too small)."""
    reasons: set[str] = set()
    for config in configs:
        reason = takeable(piece, config)
        if reason is None:
            return None
        reasons.add(reason)
    return "+".join(r for r in REFUSALS if r in reasons)


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

    The seen box is meshgen's (an upright piece's top view); the suction point's radius and
    tilt come from its mesh, as the twin's camera computes them
    (:class:`twin.suction_point.SuctionPoints`) for the pose the stream spawns it in: the mesh
    as written (its top cap turned up, tilt 0). Reads every mesh once, and hands the finder
    only its triangles :func:`facing_up` (the same answer, ten times sooner).
    """
    from twin.monitor import GroundTruth
    from twin.objects import read_obj_triangles
    from twin.suction_point import SuctionPoints
    from twin.top_view import TopView

    def upward(index: int) -> FloatArray:
        return facing_up(read_obj_triangles(objects[index].mesh_path))

    finder = SuctionPoints(upward)
    pieces = []
    for index, spec in enumerate(objects):
        resting = GroundTruth(
            id=index,
            source_id=spec.object_id,
            class_name=spec.class_name,
            position_m=(0.0, 0.0, 0.0),
            orientation_xyzw=(0.0, 0.0, 0.0, 1.0),
            linear_velocity_mps=(0.0, 0.0, 0.0),
            angular_velocity_radps=(0.0, 0.0, 0.0),
            top_view=TopView(
                yaw_rad=spec.yaw_rad,
                length_m=spec.length_m,
                width_m=spec.width_m,
                height_m=spec.height_m,
                below_m=0.5 * spec.height_m,
            ),
            length_m=spec.length_m,
            width_m=spec.width_m,
            area_m2=spec.area_m2,
            volume_m3=spec.volume_m3,
            height_m=spec.height_m,
            mass_kg=spec.mass_kg,
            on_belt=True,
            in_workspace=False,
            held=False,
            in_bin=False,
        )
        _, radius_m, tilt_rad = finder(resting)
        pieces.append(
            Piece(
                class_name=spec.class_name,
                length_m=spec.length_m,
                width_m=spec.width_m,
                height_m=spec.height_m,
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
    """The controller parameter file ``value`` names: a bare name is one shipped in
    ``control/config/`` (``line``), anything else a path. :class:`FitError` naming the value
    when there is no such file."""
    if "/" not in value and not value.endswith((".yaml", ".yml")):
        path = PARAMS_DIR / f"{value}.yaml"
        if not path.is_file():
            known = ", ".join(sorted(p.stem for p in PARAMS_DIR.glob("*.yaml")))
            msg = f"--controller {value!r}: no parameter file of that name (shipped: {known})"
            raise FitError(msg)
        return path
    path = Path(value).expanduser().resolve()
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
    """Every station of ``cell``, upstream first as listed, with its configuration from the
    parameter file ``params``."""
    return tuple(
        StationSetup(
            name=station.name,
            tool=station.tool.name,
            robot=station.robot.name,
            params=params,
            config=load_config(params, cell=cell, station=station.name),
        )
        for station in cell.stations
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


def catalogue_setups(classes: Sequence[str]) -> tuple[StationSetup, ...]:
    """One station per catalogue tool (``interfaces/catalog.yaml``, in its order), with a bin
    for each of ``classes``: a flange tool on a :data:`FLANGE_ROBOT` in the first station of
    the shipped cell :data:`FLANGE_TEMPLATE` with its parameter file; a built-in tool on its
    robot (:data:`BUILTIN_TOOL_ROBOTS`) in the first station of :data:`BUILTIN_TEMPLATE` with
    its parameter file. The template station keeps its own bins (its parameter file's class
    densities name their classes)."""
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
        template = _template(template_name)
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
