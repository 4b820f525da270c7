"""Load meshgen output (``index.csv`` and one ``scene.csv`` per image) into object specs.

Everything is checked before a simulation starts: a missing file, a malformed row, a missing mesh
or an unknown class raises :class:`twin.errors.SceneError` naming the file, line and field.
Inertia comes from the mesh itself (trimesh mass properties scaled to the recorded mass), expressed
as principal moments plus the rotation of the principal frame, which is what PyBullet takes.

The twin trusts no path a dataset names. Every file ``index.csv`` and the ``scene.csv`` files
name (``scene_csv``, ``mesh_path``, ``convex_path``, ``texture_path``) must resolve, symbolic
links followed, to a file inside the dataset folder: a ``..`` that climbs out of it, an absolute
path elsewhere or a link out of it is refused, naming the CSV file, its line and the column.
Every mesh is bounded (:class:`MeshLimits`, by default :data:`MAX_MESH_VERTICES` vertices,
:data:`MAX_MESH_FACES` faces and :data:`MAX_MESH_BYTES` bytes): its size is checked before it
is opened and its ``v`` and ``f`` lines are counted before anything (PyBullet included) reads
it, so a huge mesh is refused with its file's name instead of stalling the twin.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

from interfaces.materials import MaterialsError, dataset_table
from interfaces.scene_csv import (
    INDEX_REQUIRED_COLUMNS,
    SCENE_FLOAT_COLUMNS,
    SCENE_REQUIRED_COLUMNS,
)
from meshgen.errors import ObjFileError
from meshgen.objfile import ObjMesh, read_obj
from twin.errors import SceneError

MAX_MESH_VERTICES = 100_000
"""Default bound on the vertices of one mesh file (meshgen writes at most a few thousand: two
per outline point, and the real sample's longest outline has 370 points)."""
MAX_MESH_FACES = 200_000
"""Default bound on the faces (triangles) of one mesh file."""
MAX_MESH_BYTES = 32 * 1024 * 1024
"""Default bound on the size of one mesh file, checked before it is opened."""
QUOTE_CHARS = 80
"""An error quotes at most this many characters of a value read from a file."""
MAX_MEAN_LINE_BYTES = 256
"""A mesh file larger than :data:`LONG_LINES_FROM_BYTES` whose lines are longer than this on
average is refused (meshgen's lines are under 100 bytes): the line counts bound the faces only
when a face line cannot hold thousands of corners."""
LONG_LINES_FROM_BYTES = 1024 * 1024
"""Files from this size on are held to :data:`MAX_MEAN_LINE_BYTES`."""


@dataclass(frozen=True, slots=True, kw_only=True)
class MeshLimits:
    """How large a mesh file the twin accepts (see the module doc); pass your own to
    :func:`load_dataset` and :func:`read_mesh` for larger meshes."""

    max_vertices: int = MAX_MESH_VERTICES
    max_faces: int = MAX_MESH_FACES
    max_bytes: int = MAX_MESH_BYTES


DEFAULT_MESH_LIMITS = MeshLimits()
"""The bounds every mesh is held to unless told otherwise."""

_VERTEX_LINE = re.compile(rb"^[ \t]*v[ \t]", re.MULTILINE)
_FACE_LINE = re.compile(rb"^[ \t]*f[ \t]", re.MULTILINE)


def _cut(value: str) -> str:
    """``repr`` of ``value`` cut to :data:`QUOTE_CHARS` characters (``...`` marks a cut)."""
    if len(value) <= QUOTE_CHARS:
        return repr(value)
    return repr(value[:QUOTE_CHARS]) + "..."


def check_mesh_size(path: Path, limits: MeshLimits = DEFAULT_MESH_LIMITS) -> None:
    """Refuse the mesh file at ``path`` when it exceeds ``limits`` (:class:`SceneError` naming
    the file): its size first, without opening it, then its ``v`` and ``f`` lines counted."""
    try:
        size = path.stat().st_size
    except OSError as exc:
        msg = f"{path}: cannot read: {exc.strerror}"
        raise SceneError(msg) from None
    if size > limits.max_bytes:
        msg = (
            f"{path}: {size} bytes, more than the {limits.max_bytes} a mesh file may have "
            "(twin.objects.MeshLimits.max_bytes): refused unread"
        )
        raise SceneError(msg)
    try:
        data = path.read_bytes()
    except OSError as exc:
        msg = f"{path}: cannot read: {exc.strerror}"
        raise SceneError(msg) from None
    lines = data.count(b"\n") + 1
    if len(data) > LONG_LINES_FROM_BYTES and len(data) > MAX_MEAN_LINE_BYTES * lines:
        msg = (
            f"{path}: {len(data)} bytes in {lines} lines, more than {MAX_MEAN_LINE_BYTES} bytes "
            "per line: not a mesh the twin reads (a face of that many corners would be as "
            "costly as that many faces)"
        )
        raise SceneError(msg)
    if lines <= min(limits.max_vertices, limits.max_faces):
        return  # fewer lines than either bound: no need to tell them apart
    for pattern, bound, what in (
        (_VERTEX_LINE, limits.max_vertices, "vertices"),
        (_FACE_LINE, limits.max_faces, "faces"),
    ):
        count = sum(1 for _ in pattern.finditer(data))
        if count > bound:
            msg = (
                f"{path}: {count} {what}, more than the {bound} a mesh may have "
                f"(twin.objects.MeshLimits.max_{what}): refused unparsed"
            )
            raise SceneError(msg)


@dataclass(frozen=True)
class ObjectSpec:
    """One meshed object as recorded by meshgen (image belt frame, metres, kg)."""

    object_id: str
    source_image: str
    class_name: str
    centroid_x_m: float
    centroid_y_m: float
    yaw_rad: float
    length_m: float
    width_m: float
    area_m2: float
    height_m: float
    volume_m3: float
    mass_kg: float
    mesh_path: Path
    convex_path: Path | None
    texture_path: Path | None = None
    """The image the piece's texture coordinates point into (None: a dataset without
    textures, or written before meshgen wrote them)."""

    @property
    def collision_path(self) -> Path:
        """The file PyBullet builds the collision shape from (convex pieces when concave)."""
        return self.convex_path if self.convex_path is not None else self.mesh_path


@dataclass(frozen=True)
class ImageLayout:
    """The objects of one source image in their recorded layout."""

    image: str
    length_m: float
    width_m: float
    objects: tuple[ObjectSpec, ...]


@dataclass(frozen=True)
class Inertia:
    """Principal moments (kg m^2) and the principal frame's orientation (xyzw quaternion)."""

    principal_kgm2: tuple[float, float, float]
    frame_quat_xyzw: tuple[float, float, float, float]


def _read_csv(path: Path) -> list[tuple[int, dict[str, str]]]:
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            reader = csv.DictReader(handle)
            rows = [(i + 2, row) for i, row in enumerate(reader)]
            fields = reader.fieldnames or []
    except FileNotFoundError:
        msg = f"{path}: no such file"
        raise SceneError(msg) from None
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        msg = f"{path}: cannot read: {exc}"
        raise SceneError(msg) from None
    if not fields:
        msg = f"{path}: empty file (no header line)"
        raise SceneError(msg)
    return rows


def _float(path: Path, line: int, row: dict[str, str], key: str) -> float:
    raw = row.get(key)
    try:
        value = float(raw) if raw is not None else math.nan
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        msg = f"{path}:{line}: field {key!r} = {raw!r} is not a finite number"
        raise SceneError(msg)
    return value


def _inside(root: Path, path: Path, line: int, key: str, value: str, kind: str = "mesh") -> Path:
    """The file ``value`` (column ``key`` of line ``line`` of CSV file ``path``) names,
    relative to the CSV file's folder, resolved; :class:`SceneError` unless it is a file
    inside ``root`` (the resolved dataset folder). ``kind`` names the file in the message."""
    where = f"{path}:{line}: field {key!r} = {_cut(value)}"
    try:
        target = (path.parent / value).resolve()
    except (OSError, ValueError) as exc:
        msg = f"{where}: not a usable path ({exc})"
        raise SceneError(msg) from None
    if not target.is_relative_to(root):
        msg = (
            f"{where}: resolves to {target}, outside the dataset folder {root} "
            "(a dataset may name only its own files: no '..', absolute path or link out of it)"
        )
        raise SceneError(msg)
    if not target.is_file():
        msg = f"{path}:{line}: field {key!r}: {kind} {target} does not exist"
        raise SceneError(msg)
    return target


def _parse_object(
    path: Path,
    line: int,
    row: dict[str, str],
    classes: Iterable[str],
    *,
    root: Path,
    limits: MeshLimits,
) -> ObjectSpec:
    for key in SCENE_REQUIRED_COLUMNS:
        if key not in row or row[key] is None:
            msg = f"{path}:{line}: missing field {key!r}"
            raise SceneError(msg)
    values = {key: _float(path, line, row, key) for key in SCENE_FLOAT_COLUMNS}
    for key in ("length_m", "width_m", "area_m2", "height_m", "volume_m3", "mass_kg"):
        if values[key] <= 0.0:
            msg = f"{path}:{line}: field {key!r} = {values[key]!r} must be positive"
            raise SceneError(msg)
    class_name = row["class_name"]
    known = tuple(classes)
    if class_name not in known:
        msg = f"{path}:{line}: field 'class_name' = {class_name!r} is not a known class {known}"
        raise SceneError(msg)
    mesh_path = _inside(root, path, line, "mesh_path", row["mesh_path"])
    check_mesh_size(mesh_path, limits)
    convex_path: Path | None = None
    if row["convex_path"]:
        convex_path = _inside(root, path, line, "convex_path", row["convex_path"])
        check_mesh_size(convex_path, limits)
    texture_path: Path | None = None
    if row.get("texture_path"):
        texture_path = _inside(root, path, line, "texture_path", row["texture_path"], "texture")
    return ObjectSpec(
        object_id=row["object_id"],
        source_image=row["source_image"],
        class_name=class_name,
        mesh_path=mesh_path,
        convex_path=convex_path,
        texture_path=texture_path,
        **values,
    )


def dataset_class_table(dataset_dir: Path) -> tuple[str, ...]:
    """The classes of the class table meshgen recorded for ``dataset_dir``, in its order
    (:func:`interfaces.materials.dataset_table`: its ``classes.yaml``, or an older output's
    ``summary.json``).

    Every object of the output has one of these classes. Raises :class:`SceneError` naming
    the file when neither can be read.
    """
    try:
        return dataset_table(dataset_dir).names
    except MaterialsError as exc:
        raise SceneError(str(exc)) from None


def load_dataset(
    out_dir: Path,
    classes: Iterable[str] | None = None,
    *,
    mesh_limits: MeshLimits = DEFAULT_MESH_LIMITS,
) -> tuple[ImageLayout, ...]:
    """Read a meshgen output folder: every image's layout, in ``index.csv`` order.

    Every object's class must be one of ``classes`` (default: the dataset's own class table,
    :func:`dataset_class_table`); every file named must lie inside ``out_dir`` and every mesh
    within ``mesh_limits`` (module doc).
    """
    index_path = out_dir / "index.csv"
    rows = _read_csv(index_path)
    known = tuple(dataset_class_table(out_dir) if classes is None else classes)
    try:
        root = out_dir.resolve()
    except (OSError, ValueError) as exc:
        msg = f"{out_dir}: cannot resolve the dataset folder: {exc}"
        raise SceneError(msg) from None
    layouts = []
    for line, row in rows:
        for key in INDEX_REQUIRED_COLUMNS:
            if not row.get(key):
                msg = f"{index_path}:{line}: missing field {key!r}"
                raise SceneError(msg)
        m_per_px = _float(index_path, line, row, "m_per_px")
        width_px = _float(index_path, line, row, "width_px")
        height_px = _float(index_path, line, row, "height_px")
        scene_path = _inside(root, index_path, line, "scene_csv", row["scene_csv"], "scene file")
        objects = tuple(
            _parse_object(scene_path, obj_line, obj_row, known, root=root, limits=mesh_limits)
            for obj_line, obj_row in _read_csv(scene_path)
        )
        if objects:
            layouts.append(
                ImageLayout(
                    image=row["image"],
                    length_m=height_px * m_per_px,
                    width_m=width_px * m_per_px,
                    objects=objects,
                )
            )
    if not layouts:
        msg = f"{index_path}: no image with objects to simulate"
        raise SceneError(msg)
    return tuple(layouts)


def read_mesh(path: Path, limits: MeshLimits = DEFAULT_MESH_LIMITS) -> ObjMesh:
    """An OBJ file meshgen wrote (:func:`meshgen.objfile.read_obj`); :class:`SceneError`
    naming the file (and line) when it cannot be read, is malformed or exceeds ``limits``
    (checked before it is parsed, :func:`check_mesh_size`, and on the triangles parsed)."""
    check_mesh_size(path, limits)
    try:
        mesh = read_obj(path)
    except ObjFileError as exc:
        raise SceneError(str(exc)) from None
    if len(mesh.faces) > limits.max_faces:
        msg = (
            f"{path}: {len(mesh.faces)} triangles, more than the {limits.max_faces} a mesh may "
            "have (twin.objects.MeshLimits.max_faces)"
        )
        raise SceneError(msg)
    return mesh


def read_obj_triangles(path: Path) -> np.ndarray:
    """Triangles of an OBJ file, ``(t, 3, 3)`` float; polygons are fan-triangulated."""
    mesh = read_mesh(path)
    if not len(mesh.faces):
        msg = f"{path}: no faces"
        raise SceneError(msg)
    return mesh.triangles()


def unit_mass_inertia(triangles: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume, centre of mass ``(3,)`` and inertia tensor ``(3, 3)`` about it, for unit mass.

    ``triangles`` ``(t, 3, 3)`` bound a closed, outward-wound solid (Eberly's polyhedral mass
    properties: surface integrals by the divergence theorem).
    """
    p0, p1, p2 = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    d = np.cross(p1 - p0, p2 - p0)
    temp0 = p0 + p1
    f1 = temp0 + p2
    temp1 = p0 * p0
    temp2 = temp1 + p1 * temp0
    f2 = temp2 + p2 * f1
    f3 = p0 * temp1 + p1 * temp2 + p2 * f2
    g0 = f2 + p0 * (f1 + p0)
    g1 = f2 + p1 * (f1 + p1)
    g2 = f2 + p2 * (f1 + p2)
    x, y, z = 0, 1, 2
    volume = float(np.sum(d[:, x] * f1[:, x])) / 6.0
    if not volume > 0.0:  # also NaN
        msg = f"volume {volume:g} m^3 is not positive (open or inward-wound mesh)"
        raise SceneError(msg)
    first = np.sum(d * f2, axis=0) / 24.0
    second = np.sum(d * f3, axis=0) / 60.0
    mixed = (
        np.array(
            [
                np.sum(d[:, x] * (p0[:, y] * g0[:, x] + p1[:, y] * g1[:, x] + p2[:, y] * g2[:, x])),
                np.sum(d[:, y] * (p0[:, z] * g0[:, y] + p1[:, z] * g1[:, y] + p2[:, z] * g2[:, y])),
                np.sum(d[:, z] * (p0[:, x] * g0[:, z] + p1[:, x] * g1[:, z] + p2[:, x] * g2[:, z])),
            ]
        )
        / 120.0
    )
    com = first / volume
    sx, sy, sz = second / volume
    mxy, myz, mzx = mixed / volume
    cx, cy, cz = com
    tensor = np.array(
        [
            [sy + sz - (cy * cy + cz * cz), -(mxy - cx * cy), -(mzx - cz * cx)],
            [-(mxy - cx * cy), sx + sz - (cz * cz + cx * cx), -(myz - cy * cz)],
            [-(mzx - cz * cx), -(myz - cy * cz), sx + sy - (cx * cx + cy * cy)],
        ]
    )
    return volume, com, tensor


@cache
def _unit_inertia(mesh_path: Path, z_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Principal moments ``(3,)`` and axes (rows, ``(3, 3)``) of the mesh for unit mass."""
    triangles = read_obj_triangles(mesh_path) * np.array([1.0, 1.0, z_scale])
    try:
        _, _, tensor = unit_mass_inertia(triangles)
    except SceneError as exc:
        msg = f"{mesh_path}: {exc}"
        raise SceneError(msg) from None
    components, vectors = np.linalg.eigh(tensor)
    return components, vectors.T


def inertia_of(spec: ObjectSpec, z_scale: float = 1.0) -> Inertia:
    """The object's inertia about its centre of mass (the mesh origin) for its recorded mass.

    ``z_scale`` stretches the mesh along z (a re-sampled height); mass scales with it.
    """
    components, vectors = _unit_inertia(spec.mesh_path, z_scale)
    rotation = np.array(vectors, dtype=float).T
    if np.linalg.det(rotation) < 0:
        rotation[:, 2] = -rotation[:, 2]
    mass_kg = spec.mass_kg * z_scale
    return Inertia(
        principal_kgm2=(
            float(components[0]) * mass_kg,
            float(components[1]) * mass_kg,
            float(components[2]) * mass_kg,
        ),
        frame_quat_xyzw=_matrix_to_quat(rotation),
    )


def _matrix_to_quat(m: np.ndarray) -> tuple[float, float, float, float]:
    trace = float(m[0, 0] + m[1, 1] + m[2, 2])
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        w, x = 0.25 * s, (m[2, 1] - m[1, 2]) / s
        y, z = (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        w, x = (m[2, 1] - m[1, 2]) / s, 0.25 * s
        y, z = (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        w, x = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s
        y, z = 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        w, x = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s
        y, z = (m[1, 2] + m[2, 1]) / s, 0.25 * s
    return (float(x), float(y), float(z), float(w))
