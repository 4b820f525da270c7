"""The cell as a 3D scene: transform frames and markers computed from the twin's state.

Pure logic (no ROS, no PyBullet): :class:`twin.ros_node.TwinNode` turns these values into
``tf2_msgs/TFMessage`` and ``visualization_msgs/MarkerArray`` messages, which RViz and Foxglove
render without configuration. Geometry always travels inside the values (triangles, points),
never as a file path.

Frames (every pose is a child of ``world``): ``<prefix><link>`` for every link of a station's
URDF and ``<prefix>tcp`` for its TCP, where the prefix is ``<namespace>/`` (the station's
topic namespace; empty for the empty namespace, as its topics keep the bare names), and
``object/<id>`` for every object in the simulation (the frame of its mesh).

Markers, by namespace (``ns``): ``belt`` (a CUBE), ``bins`` (one TRIANGLE_LIST per bin, its
floor and walls, in its class's colour), ``<prefix>links`` (one TRIANGLE_LIST per link,
locked to the link's frame), ``objects`` (one TRIANGLE_LIST per object, its own mesh in its
class's colour, locked to ``object/<id>``; marker id = object id), ``targets`` (a SPHERE per
station at its controller's announced grasp point) and ``tcp_paths`` (a LINE_STRIP per station
through its TCP's last positions). Large meshes are decimated by vertex clustering
(:func:`decimate`) to a triangle budget.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from interfaces.bins import BinSpec
from interfaces.camera import RgbdCameraSpec, static_frames
from interfaces.cdr import CdrWriter
from interfaces.cell import Cell
from interfaces.class_colours import RGB

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
RGBA = tuple[float, float, float, float]
Pose = tuple[Vec3, Quat]

WORLD_FRAME = "world"
IDENTITY: Quat = (0.0, 0.0, 0.0, 1.0)
BELT_RGBA: RGBA = (0.22, 0.22, 0.24, 1.0)
LINK_RGBA: RGBA = (0.85, 0.85, 0.87, 1.0)
TARGET_RGBA: RGBA = (0.1, 0.8, 0.2, 0.9)
PATH_RGBA: RGBA = (0.1, 0.45, 0.95, 1.0)
TARGET_DIAMETER_M = 0.03
PATH_WIDTH_M = 0.006

OBJECT_MAX_TRIANGLES = 400
"""Triangle budget of one object's mesh (meshgen's extruded objects have far fewer)."""
LINK_MAX_TRIANGLES = 300
"""Triangle budget of one robot link's visual mesh."""


class MarkerKind(IntEnum):
    """A marker's shape: the values of ``visualization_msgs/Marker``'s type constants."""

    CUBE = 1
    SPHERE = 2
    LINE_STRIP = 4
    TRIANGLE_LIST = 11


class MarkerAction(IntEnum):
    """``visualization_msgs/Marker``'s ADD (add or replace) and DELETE actions."""

    ADD = 0
    DELETE = 2


@dataclass(frozen=True)
class Frame:
    """The pose of frame ``child`` in frame ``parent`` (m, xyzw quaternion)."""

    parent: str
    child: str
    position_m: Vec3
    orientation_xyzw: Quat


@dataclass(frozen=True, eq=False)
class SceneMarker:
    """One marker: an ADD (shape, pose in ``frame_id``, size, colour, points) or a DELETE.

    ``points_m`` is ``(n, 3)`` float in ``frame_id`` (three per triangle for a TRIANGLE_LIST,
    the polyline's vertices for a LINE_STRIP); ``scale`` is the box or sphere size, or a line's
    width in its first component.
    """

    ns: str
    id: int
    frame_id: str
    kind: MarkerKind
    action: MarkerAction = MarkerAction.ADD
    position_m: Vec3 = (0.0, 0.0, 0.0)
    orientation_xyzw: Quat = IDENTITY
    scale: Vec3 = (1.0, 1.0, 1.0)
    rgba: RGBA = (1.0, 1.0, 1.0, 1.0)
    points_m: np.ndarray | None = None
    frame_locked: bool = False


def delete_marker(ns: str, marker_id: int, frame_id: str = WORLD_FRAME) -> SceneMarker:
    """The DELETE of marker ``(ns, marker_id)``."""
    return SceneMarker(
        ns=ns,
        id=marker_id,
        frame_id=frame_id,
        kind=MarkerKind.TRIANGLE_LIST,
        action=MarkerAction.DELETE,
    )


# -- frames ------------------------------------------------------------------------------------
def frame_prefix(namespace: str) -> str:
    """``s1/`` for the namespace ``s1``; empty for the empty namespace (bare names, as its
    topics)."""
    return f"{namespace}/" if namespace else ""


def link_frame(namespace: str, link: str) -> str:
    """The frame of a station's URDF link: ``s1/panda_link3``."""
    return frame_prefix(namespace) + link


def tcp_frame(namespace: str) -> str:
    """The frame of a station's TCP: ``s1/tcp``."""
    return frame_prefix(namespace) + "tcp"


def object_frame(object_id: int) -> str:
    """The frame of an object's mesh: ``object/7``."""
    return f"object/{object_id}"


def world_frames(poses: Iterable[tuple[str, Pose]]) -> list[Frame]:
    """A child of ``world`` for every ``(frame name, (position, xyzw))``."""
    return [
        Frame(WORLD_FRAME, name, _vec3(position), _quat(orientation))
        for name, (position, orientation) in poses
    ]


def camera_frames(cameras: Iterable[RgbdCameraSpec]) -> list[Frame]:
    """Every camera's two static frames (REP 103 / 105, :func:`interfaces.camera.static_frames`):
    ``NAME_link`` in ``world`` as the cell file places it, ``NAME_optical_frame`` in
    ``NAME_link`` (z forward, x right, y down)."""
    return [
        Frame(f.parent, f.child, f.translation_m, f.rotation_xyzw)
        for spec in cameras
        for f in static_frames(spec, WORLD_FRAME)
    ]


def station_frames(namespace: str, links: Mapping[str, Pose], tcp: Pose) -> list[Frame]:
    """A station's link frames (in the mapping's order) and its TCP frame, children of
    ``world``."""
    named = [(link_frame(namespace, name), pose) for name, pose in links.items()]
    return world_frames([*named, (tcp_frame(namespace), tcp)])


def tf_message_cdr(frames: Sequence[Frame], sec: int, nanosec: int) -> bytes:
    """The serialized ``tf2_msgs/msg/TFMessage`` (CDR, as rclpy serializes it) of ``frames``,
    every transform stamped ``(sec, nanosec)``.

    Written directly (:mod:`interfaces.cdr`) rather than through rclpy's message objects: the
    scene sends some forty transforms 30 times a second, and building them as Python messages
    costs far more than the rest of a step's publishing.
    """
    w = CdrWriter()
    w.u32(len(frames))
    for frame in frames:
        w.header(sec, nanosec, frame.parent)
        w.string(frame.child)
        w.f64s((*frame.position_m, *frame.orientation_xyzw))
    return w.bytes()


def _vec3(v: Sequence[float]) -> Vec3:
    return (float(v[0]), float(v[1]), float(v[2]))


def _quat(q: Sequence[float]) -> Quat:
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


# -- meshes ------------------------------------------------------------------------------------
def box_triangles(half_extents_m: Vec3, centre_m: Vec3 = (0.0, 0.0, 0.0)) -> np.ndarray:
    """The 12 outward-wound triangles ``(12, 3, 3)`` of an axis-aligned box."""
    hx, hy, hz = half_extents_m
    corners = np.array(
        [[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    ) + np.asarray(centre_m, dtype=float)
    faces = [
        (0, 1, 3),
        (0, 3, 2),  # -x
        (4, 6, 7),
        (4, 7, 5),  # +x
        (0, 4, 5),
        (0, 5, 1),  # -y
        (2, 3, 7),
        (2, 7, 6),  # +y
        (0, 2, 6),
        (0, 6, 4),  # -z
        (1, 5, 7),
        (1, 7, 3),  # +z
    ]
    return np.asarray(corners[np.array(faces)], dtype=float)


def decimate(triangles: np.ndarray, max_triangles: int) -> np.ndarray:
    """``triangles`` ``(t, 3, 3)`` with at most ``max_triangles`` triangles.

    Vertex clustering: vertices are snapped to the centroid of their cell of a cubic grid,
    triangles that collapse (two corners in one cell) or repeat are dropped. The first cell
    size gives the surface about ``max_triangles`` / 2 cells; it grows by a factor 1.25 until
    the budget holds. A mesh within budget comes back unchanged.
    """
    tris = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    if max_triangles < 1:
        msg = f"max_triangles = {max_triangles} must be at least 1"
        raise ValueError(msg)
    if len(tris) <= max_triangles:
        return tris
    vertices = tris.reshape(-1, 3)
    lo = vertices.min(axis=0)
    extent = max(float((vertices.max(axis=0) - lo).max()), 1e-9)
    area = 0.5 * float(
        np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1).sum()
    )
    cell = max(0.8 * math.sqrt(area / (0.5 * max_triangles)), extent / 1000.0)
    while True:
        grid = np.floor((vertices - lo) / cell).astype(np.int64)
        keys = (grid[:, 0] * 4096 + grid[:, 1]) * 4096 + grid[:, 2]
        _, cluster, counts = np.unique(keys, return_inverse=True, return_counts=True)
        cluster = cluster.reshape(-1)
        sums = np.zeros((len(counts), 3))
        np.add.at(sums, cluster, vertices)
        centres = sums / counts[:, None]
        corners = cluster.reshape(-1, 3)
        kept = (
            (corners[:, 0] != corners[:, 1])
            & (corners[:, 1] != corners[:, 2])
            & (corners[:, 0] != corners[:, 2])
        )
        corners = corners[kept]
        if len(corners):
            canonical = np.sort(corners, axis=1)
            _, first = np.unique(canonical, axis=0, return_index=True)
            corners = corners[np.sort(first)]
        if len(corners) <= max_triangles:
            return np.asarray(centres[corners], dtype=float)
        cell *= 1.25


def mesh_marker(
    ns: str, marker_id: int, frame_id: str, triangles: np.ndarray, rgba: RGBA
) -> SceneMarker:
    """A TRIANGLE_LIST of ``triangles`` ``(t, 3, 3)`` in ``frame_id``, locked to that frame."""
    return SceneMarker(
        ns=ns,
        id=marker_id,
        frame_id=frame_id,
        kind=MarkerKind.TRIANGLE_LIST,
        rgba=rgba,
        points_m=np.asarray(triangles, dtype=float).reshape(-1, 3),
        frame_locked=True,
    )


def rgba(rgb: RGB, alpha: float = 1.0) -> RGBA:
    """An RGB colour with opacity ``alpha``."""
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]), float(alpha))


# -- the static scene ---------------------------------------------------------------------------
def belt_marker(cell: Cell) -> SceneMarker:
    """The belt: a CUBE from its start to its end, its width and thickness, top at its
    surface."""
    belt = cell.belt
    return SceneMarker(
        ns="belt",
        id=0,
        frame_id=WORLD_FRAME,
        kind=MarkerKind.CUBE,
        position_m=(
            0.5 * (belt.start_x_m + belt.end_x_m),
            belt.centre_y_m,
            belt.surface_z_m - 0.5 * belt.thickness_m,
        ),
        scale=(belt.end_x_m - belt.start_x_m, belt.width_m, belt.thickness_m),
        rgba=BELT_RGBA,
    )


def bin_triangles(spec: BinSpec) -> np.ndarray:
    """A bin's floor and four walls, ``(60, 3, 3)`` in the world frame (the boxes the twin
    builds it from)."""
    half = 0.5 * spec.size_m
    wall_h = 0.5 * (spec.top_z_m - spec.floor_z_m)
    t = 0.5 * spec.wall_m
    cx, cy, cz = spec.centre_x_m, spec.centre_y_m, spec.floor_z_m + wall_h
    boxes = [
        ((half, half, t), (0.0, 0.0, -wall_h + t)),
        ((t, half, wall_h), (half - t, 0.0, 0.0)),
        ((t, half, wall_h), (-half + t, 0.0, 0.0)),
        ((half, t, wall_h), (0.0, half - t, 0.0)),
        ((half, t, wall_h), (0.0, -half + t, 0.0)),
    ]
    return np.concatenate(
        [box_triangles(h, (cx + c[0], cy + c[1], cz + c[2])) for h, c in boxes], axis=0
    )


def bin_markers(cell: Cell, colour: Callable[[str], RGB]) -> list[SceneMarker]:
    """One TRIANGLE_LIST per bin of every station (in the cell's order), in its class's
    colour."""
    return [
        mesh_marker("bins", i, WORLD_FRAME, bin_triangles(spec), rgba(colour(spec.class_name)))
        for i, spec in enumerate(cell.bins)
    ]


@dataclass(frozen=True, eq=False)
class LinkVisual:
    """A link's visual geometry: triangles ``(t, 3, 3)`` in the link's frame, and a colour."""

    link: str
    triangles: np.ndarray
    rgba: RGBA = LINK_RGBA


def link_markers(
    namespace: str, visuals: Sequence[LinkVisual], max_triangles: int = LINK_MAX_TRIANGLES
) -> list[SceneMarker]:
    """A station's links: one decimated TRIANGLE_LIST per link with geometry, locked to the
    link's frame (``ns`` ``<prefix>links``, ids in the given order)."""
    ns = frame_prefix(namespace) + "links"
    return [
        mesh_marker(
            ns,
            i,
            link_frame(namespace, visual.link),
            decimate(visual.triangles, max_triangles),
            visual.rgba,
        )
        for i, visual in enumerate(visuals)
        if len(visual.triangles)
    ]


# -- objects -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class ObjectsUpdate:
    """What changed in the set of objects: the ids added and removed, and the markers to send:
    an ADD for every live object (in id order; an ADD replaces a marker of the same id, so
    every message holds the whole set) then a DELETE for every removed one."""

    added: tuple[int, ...]
    removed: tuple[int, ...]
    markers: tuple[SceneMarker, ...]


@dataclass
class ObjectMarkers:
    """The objects' markers over an episode: a mesh marker from the first update an object is
    live in, a DELETE at the first update it is not.

    ``mesh(object_id)`` gives an object's triangles ``(t, 3, 3)`` in its frame and its class
    (called once per object); ``colour(class_name)`` the class's colour.
    """

    mesh: Callable[[int], tuple[np.ndarray, str]]
    colour: Callable[[str], RGB]
    max_triangles: int = OBJECT_MAX_TRIANGLES
    _live: dict[int, SceneMarker] = field(default_factory=dict)

    def update(self, live_ids: Iterable[int]) -> ObjectsUpdate | None:
        """The markers for the objects now live; None when the set did not change."""
        ids = set(live_ids)
        added = tuple(sorted(ids - self._live.keys()))
        removed = tuple(sorted(self._live.keys() - ids))
        if not added and not removed:
            return None
        for object_id in added:
            triangles, class_name = self.mesh(object_id)
            self._live[object_id] = mesh_marker(
                "objects",
                object_id,
                object_frame(object_id),
                decimate(triangles, self.max_triangles),
                rgba(self.colour(class_name)),
            )
        for object_id in removed:
            del self._live[object_id]
        markers = [self._live[i] for i in sorted(self._live)]
        markers += [delete_marker("objects", i, object_frame(i)) for i in removed]
        return ObjectsUpdate(added=added, removed=removed, markers=tuple(markers))


# -- targets and paths ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Target:
    """A controller's announced grasp point at ``stamp_s`` and its velocity (world)."""

    point_m: Vec3
    velocity_mps: Vec3
    stamp_s: float


def target_marker(index: int, target: Target | None, now_s: float) -> SceneMarker:
    """Station ``index``'s target: a SPHERE where the announced grasp point is at ``now_s``
    (moved on with its velocity), or the DELETE of that marker when there is none."""
    if target is None:
        return delete_marker("targets", index)
    dt = max(0.0, now_s - target.stamp_s)
    p, v = target.point_m, target.velocity_mps
    return SceneMarker(
        ns="targets",
        id=index,
        frame_id=WORLD_FRAME,
        kind=MarkerKind.SPHERE,
        position_m=(p[0] + v[0] * dt, p[1] + v[1] * dt, p[2] + v[2] * dt),
        scale=(TARGET_DIAMETER_M,) * 3,
        rgba=TARGET_RGBA,
    )


@dataclass
class TcpPath:
    """A TCP's positions over the last ``window_s`` (one sample per :meth:`add`)."""

    window_s: float = 3.0
    _samples: deque[tuple[float, Vec3]] = field(default_factory=deque)

    def add(self, time_s: float, position_m: Sequence[float]) -> None:
        """Append a sample and forget those older than the window."""
        self._samples.append((time_s, _vec3(position_m)))
        while self._samples and self._samples[0][0] < time_s - self.window_s - 1e-9:
            self._samples.popleft()

    @property
    def points_m(self) -> np.ndarray:
        """The samples' positions, oldest first, ``(n, 3)``."""
        return np.array([p for _, p in self._samples], dtype=float).reshape(-1, 3)

    def marker(self, index: int) -> SceneMarker:
        """Station ``index``'s path: a LINE_STRIP in ``world`` (a DELETE with fewer than two
        samples)."""
        points = self.points_m
        if len(points) < 2:
            return delete_marker("tcp_paths", index)
        return SceneMarker(
            ns="tcp_paths",
            id=index,
            frame_id=WORLD_FRAME,
            kind=MarkerKind.LINE_STRIP,
            scale=(PATH_WIDTH_M, 0.0, 0.0),
            rgba=PATH_RGBA,
            points_m=points,
        )


def quat_angle_rad(a: Quat, b: Quat) -> float:
    """The angle of the rotation between two unit quaternions (xyzw), rad."""
    dot = abs(sum(x * y for x, y in zip(a, b, strict=True)))
    return 2.0 * math.acos(min(1.0, dot))


__all__ = [
    "IDENTITY",
    "WORLD_FRAME",
    "Frame",
    "LinkVisual",
    "MarkerAction",
    "MarkerKind",
    "ObjectMarkers",
    "ObjectsUpdate",
    "SceneMarker",
    "Target",
    "TcpPath",
    "belt_marker",
    "bin_markers",
    "bin_triangles",
    "box_triangles",
    "decimate",
    "delete_marker",
    "frame_prefix",
    "link_frame",
    "link_markers",
    "mesh_marker",
    "object_frame",
    "quat_angle_rad",
    "rgba",
    "station_frames",
    "target_marker",
    "tcp_frame",
    "tf_message_cdr",
    "world_frames",
]
