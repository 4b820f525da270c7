"""``cdw-twin picture``: a PNG of the cell as the twin renders it (the README's picture).

Examples (the first makes the README's picture: the four-station line with waste on its belt)::

    cdw-twin picture --out docs/images/cell.png --width 1200 --height 600
    cdw-twin picture --cell default --out cell.png

The twin is built as an episode builds it (:class:`twin.sim.Twin` in PyBullet DIRECT, the
built-in dataset or ``--dataset``, no controller: the arms stay at home) with the belt
prefilled (``--prefill``; by default the scenario's, or :data:`PREFILL_SHARE` of the belt's run
from the infeed, so every station has waste in front of it) and run ``--time`` seconds of
simulated time. PyBullet's TinyRenderer (CPU, no display needed) then draws it from a camera
on the stations' side of the belt, above it and turned towards the upstream end, placed to
frame the belt, the robots and the bins (:func:`frame_camera`). Objects are drawn in their
class colours (the class table's, the episode cell's ``materials``:
:func:`interfaces.class_colours.class_colour`), each bin in the colour of the class it takes,
the belt and the floor in :data:`BELT_RGB` and :data:`FLOOR_RGB`; the robots keep their URDF's
colours. The PNG is written through a temporary file and a rename.
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import math
import os
import secrets
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from interfaces.class_colours import RGB, class_colour
from interfaces.errors import CdwTwinError

if TYPE_CHECKING:
    from interfaces.cell import Cell
    from twin.monitor import GroundTruth
    from twin.scenario import Scenario

FloatArray = npt.NDArray[np.float64]
ImageArray = npt.NDArray[np.uint8]

PREFILL_SHARE = 0.9
"""The share of the belt's run (infeed to end) the stream covers at the start by default."""

DEFAULT_CELL = "line"
"""The cell pictured by default: the four-station line (several stations in one picture)."""

BELT_RGB: RGB = (0.24, 0.34, 0.46)
"""The belt's colour: a slate blue that every class colour stands out on (rubber included)."""

FLOOR_RGB: RGB = (0.86, 0.86, 0.84)
"""The floor's colour: a light grey, so the white arms and the bins read against it."""

CAMERA_AZIMUTH_DEG = 30.0
"""How far the camera turns from looking straight across the belt towards its upstream end."""

CAMERA_PITCH_DEG = 45.0
"""The camera's angle below the horizon."""

CAMERA_FOV_DEG = 25.0
"""The camera's vertical field of view."""

FRAME_MARGIN = 0.04
"""The share of the image, on each side, left free around the framed bodies."""

_NEAR_M = 0.05
_FAR_M = 100.0


class PictureError(CdwTwinError):
    """The picture cannot be made or written (the message names the option or file)."""


@dataclass(frozen=True)
class Camera:
    """A pinhole camera in PyBullet's (OpenGL) conventions.

    ``view_matrix`` and ``projection_matrix`` are the 16 floats :func:`pybullet.getCameraImage`
    takes (column-major 4x4); a world point ``p`` lands at normalized device coordinates
    ``(P @ V @ [p, 1])[:3] / w``, x to the right and y up, each in ``[-1, 1]`` on the image.
    """

    width_px: int
    height_px: int
    view_matrix: tuple[float, ...]
    projection_matrix: tuple[float, ...]


def _clip(view: Sequence[float], projection: Sequence[float], points_m: FloatArray) -> FloatArray:
    """Clip coordinates ``(n, 4)`` of world points ``(n, 3)``; ``w`` is the depth before the
    camera (positive in front of it)."""
    v = np.asarray(view, dtype=float).reshape(4, 4).T
    p = np.asarray(projection, dtype=float).reshape(4, 4).T
    homogeneous = np.hstack([points_m, np.ones((len(points_m), 1))])
    clip: FloatArray = (p @ v @ homogeneous.T).T
    return clip


def _ndc(view: Sequence[float], projection: Sequence[float], points_m: FloatArray) -> FloatArray:
    """Normalized device coordinates ``(n, 3)`` of world points ``(n, 3)``."""
    clip = _clip(view, projection, points_m)
    return clip[:, :3] / clip[:, 3:4]


def _fits(
    view: Sequence[float], projection: Sequence[float], points_m: FloatArray, limit: float
) -> bool:
    """Whether every point is in front of the camera and within ``limit`` of the image's
    centre (normalized device coordinates, x and y)."""
    clip = _clip(view, projection, points_m)
    depth = clip[:, 3]
    if np.any(depth <= _NEAR_M):
        return False
    return bool(np.max(np.abs(clip[:, :2] / depth[:, None])) <= limit)


def look_at(eye_m: FloatArray, target_m: FloatArray) -> tuple[float, ...]:
    """The view matrix (column-major, 16 floats) of a camera at ``eye_m`` looking at
    ``target_m`` with world z up (as :func:`pybullet.computeViewMatrix` builds it)."""
    forward = target_m - eye_m
    forward /= np.linalg.norm(forward)
    side = np.cross(forward, np.array([0.0, 0.0, 1.0]))
    side /= np.linalg.norm(side)
    up = np.cross(side, forward)
    matrix = np.eye(4)
    matrix[0, :3], matrix[1, :3], matrix[2, :3] = side, up, -forward
    matrix[:3, 3] = -matrix[:3, :3] @ eye_m
    return tuple(float(x) for x in matrix.T.reshape(-1))


def perspective(fov_deg: float, aspect: float) -> tuple[float, ...]:
    """The projection matrix (column-major, 16 floats) of a vertical field of view ``fov_deg``
    and width/height ``aspect`` (as :func:`pybullet.computeProjectionMatrixFOV` builds it)."""
    f = 1.0 / math.tan(math.radians(fov_deg) / 2.0)
    near, far = _NEAR_M, _FAR_M
    matrix = np.zeros((4, 4))
    matrix[0, 0] = f / aspect
    matrix[1, 1] = f
    matrix[2, 2] = (far + near) / (near - far)
    matrix[2, 3] = 2.0 * far * near / (near - far)
    matrix[3, 2] = -1.0
    return tuple(float(x) for x in matrix.T.reshape(-1))


def frame_camera(
    points_m: FloatArray,
    width_px: int,
    height_px: int,
    *,
    side: float = -1.0,
    azimuth_deg: float = CAMERA_AZIMUTH_DEG,
    pitch_deg: float = CAMERA_PITCH_DEG,
    fov_deg: float = CAMERA_FOV_DEG,
    margin: float = FRAME_MARGIN,
) -> Camera:
    """A camera looking at the points ``(n, 3)`` across the belt from its ``side`` (the sign
    of y the eye is at), turned ``azimuth_deg`` towards the upstream end (-x), ``pitch_deg``
    below the horizon, as close as it can be with every point inside the image less ``margin``
    of it on each side, the points' extent centred in the image."""
    points = np.asarray(points_m, dtype=float)
    lo, hi = points.min(axis=0), points.max(axis=0)
    azimuth, pitch = math.radians(azimuth_deg), math.radians(pitch_deg)
    towards_eye = np.array(
        [
            -math.sin(azimuth) * math.cos(pitch),
            math.copysign(1.0, side) * math.cos(azimuth) * math.cos(pitch),
            math.sin(pitch),
        ]
    )
    projection = perspective(fov_deg, width_px / height_px)
    limit = 1.0 - 2.0 * margin
    size_m = float(np.linalg.norm(hi - lo)) + 1.0

    def fit(target: FloatArray) -> float:
        """The smallest distance from ``target`` at which every point fits (bisection)."""
        near, far = 0.0, 100.0 * size_m
        for _ in range(60):
            mid = 0.5 * (near + far)
            if _fits(look_at(target + mid * towards_eye, target), projection, points, limit):
                far = mid
            else:
                near = mid
        return far

    target = 0.5 * (lo + hi)
    for _ in range(8):  # aim at the world point drawn at the centre of the points' extent
        distance = fit(target)
        view = look_at(target + distance * towards_eye, target)
        ndc = _ndc(view, projection, points)
        centre = 0.5 * (ndc[:, :2].min(axis=0) + ndc[:, :2].max(axis=0))
        if np.max(np.abs(centre)) < 1e-3:
            break
        inverse = np.linalg.inv(
            np.asarray(projection).reshape(4, 4).T @ np.asarray(view).reshape(4, 4).T
        )
        depth = _ndc(view, projection, target[None, :])[0, 2]
        moved = inverse @ np.array([centre[0], centre[1], depth, 1.0])
        target = moved[:3] / moved[3]
    else:
        distance = fit(target)
    return Camera(
        width_px=width_px,
        height_px=height_px,
        view_matrix=look_at(target + distance * towards_eye, target),
        projection_matrix=projection,
    )


@dataclass(frozen=True)
class SceneBodies:
    """The PyBullet bodies of a twin's scene, by role; bins and objects with their class."""

    floor: int | None
    belt: int | None
    robots: tuple[int, ...]
    bins: dict[int, str]
    objects: dict[int, str]


def scene_bodies(client: int, cell: Cell, objects: Sequence[GroundTruth]) -> SceneBodies:
    """Which body is the floor (the plane), the belt (the one box of the belt's width and
    thickness), a robot (a body with joints), a bin (at a bin's centre) and an object (at an
    object's ground-truth position, which is its body's position)."""
    import pybullet as pb

    belt_spec = cell.belt
    bin_at = {(b.centre_x_m, b.centre_y_m): b.class_name for s in cell.stations for b in s.bins}
    object_at = {o.position_m: o.class_name for o in objects}
    floor = belt = None
    robots: list[int] = []
    bins: dict[int, str] = {}
    found: dict[int, str] = {}
    for i in range(pb.getNumBodies(physicsClientId=client)):
        body = pb.getBodyUniqueId(i, physicsClientId=client)
        shapes = pb.getVisualShapeData(body, physicsClientId=client)
        position, _ = pb.getBasePositionAndOrientation(body, physicsClientId=client)
        geometry = [(shape[2], shape[3]) for shape in shapes if shape[1] == -1]
        if pb.getNumJoints(body, physicsClientId=client) > 0:
            robots.append(body)
        elif geometry and geometry[0][0] == pb.GEOM_PLANE:
            floor = body
        elif (
            len(geometry) == 1
            and geometry[0][0] == pb.GEOM_BOX
            and math.isclose(geometry[0][1][1], belt_spec.width_m)
            and math.isclose(geometry[0][1][2], belt_spec.thickness_m)
        ):
            belt = body
        elif (position[0], position[1]) in bin_at:
            bins[body] = bin_at[position[0], position[1]]
        elif tuple(position) in object_at:
            found[body] = object_at[tuple(position)]
    return SceneBodies(floor=floor, belt=belt, robots=tuple(robots), bins=bins, objects=found)


def bounding_points(client: int, bodies: Sequence[int]) -> FloatArray:
    """The corners ``(n, 3)`` of the bounding boxes of every link of ``bodies``."""
    import pybullet as pb

    corners: list[tuple[float, float, float]] = []
    for body in bodies:
        for link in range(-1, pb.getNumJoints(body, physicsClientId=client)):
            lo, hi = pb.getAABB(body, link, physicsClientId=client)
            corners.extend(
                (x, y, z) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])
            )
    return np.asarray(corners, dtype=float)


def paint(client: int, bodies: SceneBodies, colours: Callable[[str], RGB]) -> None:
    """Colour the floor, the belt, the bins and the objects (the robots keep their own); a
    bin or an object in its class's colour (``colours``: the class table's,
    :func:`interfaces.class_colours.class_colour`)."""
    import pybullet as pb

    def colour(body: int, rgb: RGB) -> None:
        for shape in pb.getVisualShapeData(body, physicsClientId=client):
            pb.changeVisualShape(
                body,
                shape[1],
                shapeIndex=-1,
                rgbaColor=[*rgb, 1.0],
                textureUniqueId=-1,
                physicsClientId=client,
            )

    if bodies.floor is not None:
        colour(bodies.floor, FLOOR_RGB)
    if bodies.belt is not None:
        colour(bodies.belt, BELT_RGB)
    for body, name in (*bodies.bins.items(), *bodies.objects.items()):
        colour(body, colours(name))


def render(client: int, camera: Camera) -> ImageArray:
    """The scene through ``camera`` with PyBullet's TinyRenderer: ``(height, width, 3)`` RGB."""
    import pybullet as pb

    width, height, rgba, _, _ = pb.getCameraImage(
        camera.width_px,
        camera.height_px,
        viewMatrix=list(camera.view_matrix),
        projectionMatrix=list(camera.projection_matrix),
        renderer=pb.ER_TINY_RENDERER,
        shadow=0,
        lightDirection=[-0.4, 0.6, 1.0],
        lightAmbientCoeff=0.55,
        lightDiffuseCoeff=0.5,
        lightSpecularCoeff=0.05,
        physicsClientId=client,
    )
    pixels = np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)
    return np.ascontiguousarray(pixels[:, :, :3])


@dataclass(frozen=True)
class Picture:
    """A rendered picture and the camera it was taken with."""

    rgb: ImageArray
    camera: Camera


def take_picture(
    cell: Cell,
    scenario: Scenario,
    dataset_dir: Path,
    *,
    time_s: float,
    width_px: int,
    height_px: int,
) -> Picture:
    """Run the twin (no controller) ``time_s`` of simulated time and render the cell from a
    camera that frames its belt, robots and bins (not the objects: one falling off the belt's
    end does not move the camera), on the stations' side of the belt."""
    from twin.sim import Twin

    with Twin(scenario, dataset_dir=dataset_dir, cell=cell, perception_enabled=False) as twin:
        twin.reset(seed=scenario.seed)
        for _ in range(round(time_s / twin.dt_s)):
            twin.advance()
        bodies = scene_bodies(twin.client, cell, twin.observe_objects())
        paint(twin.client, bodies, class_colour(twin.cell.materials))
        framed = [b for b in (bodies.belt, *bodies.robots, *bodies.bins) if b is not None]
        stations_y = sum(s.base_position_m[1] for s in cell.stations) / len(cell.stations)
        camera = frame_camera(
            bounding_points(twin.client, framed),
            width_px,
            height_px,
            side=-1.0 if stations_y <= cell.belt.centre_y_m else 1.0,
        )
        return Picture(rgb=render(twin.client, camera), camera=camera)


def png_bytes(rgb: ImageArray) -> bytes:
    """A PNG file's bytes of an ``(height, width, 3)`` RGB image."""
    from matplotlib.image import imsave

    buffer = io.BytesIO()
    imsave(buffer, rgb, format="png")
    return buffer.getvalue()


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in its folder and a rename (the
    file gets the permissions an ordinary ``open`` gives: 0666 minus the umask)."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        with tmp.open("xb") as handle:
            handle.write(data)
        tmp.replace(path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def check_out(out: Path) -> None:
    """Refuse an ``--out`` whose folder does not exist or cannot be written, before the run."""
    folder = out.parent
    if out.is_dir():
        msg = f"--out {out}: is a folder; give the PNG file's path"
        raise PictureError(msg)
    if not folder.is_dir():
        msg = f"--out {out}: folder {folder} does not exist"
        raise PictureError(msg)
    if not os.access(folder, os.W_OK | os.X_OK):
        msg = f"--out {out}: folder {folder} is not writable"
        raise PictureError(msg)


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the picture's options."""
    parser.add_argument(
        "--cell",
        default=None,
        metavar="NAME_OR_PATH",
        help=f"cell file or shipped cell's name (default: the scenario's, else {DEFAULT_CELL})",
    )
    parser.add_argument("--scenario", type=Path, default=None, help="scenario YAML")
    parser.add_argument(
        "--dataset",
        type=Path,
        default=None,
        help="meshgen output folder (default: the scenario's, or built-in)",
    )
    parser.add_argument("--seed", type=int, default=None, help="seed (override)")
    parser.add_argument(
        "--prefill",
        type=float,
        default=None,
        metavar="M",
        help="metres of stream on the belt at the start (default: the scenario's, else 90 %% "
        "of the belt's run)",
    )
    parser.add_argument(
        "--time", type=float, default=6.0, metavar="S", help="simulated seconds before the shot"
    )
    parser.add_argument("--out", type=Path, default=Path("cell.png"), help="PNG file (cell.png)")
    parser.add_argument("--width", type=int, default=1200, help="image width, pixels")
    parser.add_argument("--height", type=int, default=600, help="image height, pixels")


def run(args: argparse.Namespace) -> int:
    """Render the cell and write the PNG; prints its path."""
    from interfaces.cell import load_cell
    from twin.cmd_node import build_scenario

    for name, value, low, high in (
        ("--width", args.width, 16, 8192),
        ("--height", args.height, 16, 8192),
    ):
        if not low <= value <= high:
            msg = f"{name} {value}: must be in [{low}, {high}] pixels"
            raise PictureError(msg)
    if not (math.isfinite(args.time) and 0.0 <= args.time <= 600.0):
        msg = f"--time {args.time}: must be in [0, 600] s"
        raise PictureError(msg)
    check_out(args.out)
    cell_arg = args.cell if args.cell is not None or args.scenario is not None else DEFAULT_CELL
    if cell_arg is not None:
        load_cell(cell_arg)  # a wrong cell is refused before the dataset is built
    scenario, dataset, cell = build_scenario(
        argparse.Namespace(
            scenario=args.scenario,
            cell=cell_arg,
            dataset=args.dataset,
            seed=args.seed,
            prefill=args.prefill,
            speed=None,
            duration=None,
            objects=None,
        )
    )
    if args.prefill is None and scenario.system.prefill_m == 0.0:
        prefill_m = PREFILL_SHARE * (cell.belt.end_x_m - cell.belt.infeed_x_m)
        scenario = dataclasses.replace(
            scenario, system=dataclasses.replace(scenario.system, prefill_m=prefill_m)
        )
    picture = take_picture(
        cell, scenario, dataset, time_s=args.time, width_px=args.width, height_px=args.height
    )
    try:
        write_bytes_atomic(args.out, png_bytes(picture.rgb))
    except OSError as exc:
        msg = f"--out {args.out}: cannot write: {exc.strerror}"
        raise PictureError(msg) from None
    print(args.out)
    return 0


__all__ = [
    "BELT_RGB",
    "DEFAULT_CELL",
    "FLOOR_RGB",
    "PREFILL_SHARE",
    "Camera",
    "Picture",
    "PictureError",
    "bounding_points",
    "frame_camera",
    "look_at",
    "paint",
    "perspective",
    "render",
    "scene_bodies",
    "take_picture",
]
