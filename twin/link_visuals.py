"""The visual geometry of a robot's links, read from its URDF, for the scene (twin/scene.py).

Viewers of a recording (Foxglove, RViz) draw the arm from triangle markers that travel inside
the recording, so the URDF's visual meshes are read here, decimated to a budget per link and
cached: no file path has to resolve on the machine that replays the episode.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import xml.etree.ElementTree as ET
from functools import cache
from pathlib import Path

import numpy as np

from interfaces.cache import cache_root
from interfaces.fileio import write_atomic
from twin.scene import LINK_MAX_TRIANGLES, LINK_RGBA, RGBA, LinkVisual, box_triangles, decimate


def link_visuals(urdf: Path, max_triangles: int = LINK_MAX_TRIANGLES) -> tuple[LinkVisual, ...]:
    """Every URDF link's visual geometry as triangles in the link's frame, decimated to
    ``max_triangles`` per link, in the file's link order (links without geometry left out).

    Meshes (OBJ, STL, ...) are read with trimesh; a visual mesh trimesh cannot read (a
    COLLADA file without pycollada) is replaced by the link's collision geometry; boxes,
    cylinders and spheres are triangulated. The colour is the visual's material colour (inline
    or named at the top level of the URDF), else a light grey. A link nothing can be read for
    is left out: the scene is a picture, never a reason to refuse a robot.

    Reading and decimating a robot's meshes takes seconds, so the result is kept under
    ``<cache root>/scene/``, keyed by the URDF's text, the budget and every mesh file's size
    and modification time.
    """
    return _link_visuals(Path(urdf), max_triangles)


VISUALS_CACHE_VERSION = 1


@cache
def _link_visuals(urdf: Path, max_triangles: int) -> tuple[LinkVisual, ...]:
    try:
        text = urdf.read_text(encoding="utf-8")
        root = ET.fromstring(text)
    except (OSError, UnicodeDecodeError, ET.ParseError):
        return ()
    key = hashlib.sha256(f"{VISUALS_CACHE_VERSION} {max_triangles}\n{text}".encode())
    for mesh in sorted(m.get("filename", "") for m in root.iter("mesh")):
        try:
            stat = Path(mesh).stat()
        except OSError:
            continue
        key.update(f"{mesh} {stat.st_size} {stat.st_mtime_ns}\n".encode())
    path = cache_root() / "scene" / f"visuals-{key.hexdigest()[:20]}.json"
    cached = _read_visuals(path)
    if cached is not None:
        return cached
    visuals = _read_link_visuals(root, max_triangles)
    data = [
        {"link": v.link, "rgba": list(v.rgba), "triangles": np.round(v.triangles, 6).tolist()}
        for v in visuals
    ]
    with contextlib.suppress(OSError):  # an unwritable cache costs time, nothing else
        write_atomic(path, json.dumps(data))
    return visuals


def _read_visuals(path: Path) -> tuple[LinkVisual, ...] | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return tuple(
            LinkVisual(
                link=str(item["link"]),
                triangles=np.asarray(item["triangles"], dtype=float).reshape(-1, 3, 3),
                rgba=tuple(float(c) for c in item["rgba"]),  # type: ignore[arg-type]
            )
            for item in data
        )
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _read_link_visuals(root: ET.Element, max_triangles: int) -> tuple[LinkVisual, ...]:
    named: dict[str, RGBA] = {}
    for top in root.findall("material"):
        top_colour = _rgba(top)
        if top_colour is not None:
            named[top.get("name", "")] = top_colour
    visuals: list[LinkVisual] = []
    for link in root.findall("link"):
        parts: list[np.ndarray] = []
        colour: RGBA | None = None
        for visual in link.findall("visual"):
            triangles = _element_triangles(visual)
            if triangles is None:
                for collision in link.findall("collision"):
                    triangles = _element_triangles(collision)
                    if triangles is not None:
                        break
            if triangles is None:
                continue
            parts.append(triangles)
            own = visual.find("material")
            if colour is None and own is not None:
                colour = _rgba(own) or named.get(own.get("name", ""))
        if parts:
            visuals.append(
                LinkVisual(
                    link=link.get("name", ""),
                    triangles=decimate(np.concatenate(parts, axis=0), max_triangles),
                    rgba=colour or LINK_RGBA,
                )
            )
    return tuple(visuals)


def _rgba(material: ET.Element) -> RGBA | None:
    color = material.find("color")
    if color is None:
        return None
    try:
        r, g, b, a = (float(v) for v in color.get("rgba", "").split())
    except ValueError:
        return None
    return (r, g, b, a)


def _element_triangles(element: ET.Element) -> np.ndarray | None:
    """A ``<visual>`` or ``<collision>``'s triangles in its link's frame, None if unreadable."""
    geometry = element.find("geometry")
    if geometry is None:
        return None
    triangles = _geometry_triangles(geometry)
    if triangles is None or not len(triangles):
        return None
    origin = element.find("origin")
    xyz = _floats(origin.get("xyz") if origin is not None else None, 3)
    rpy = _floats(origin.get("rpy") if origin is not None else None, 3)
    rotation = _rpy_matrix(rpy)
    return np.asarray(triangles @ rotation.T + np.array(xyz), dtype=float)


def _geometry_triangles(geometry: ET.Element) -> np.ndarray | None:
    mesh = geometry.find("mesh")
    if mesh is not None:
        scale = _floats(mesh.get("scale"), 3, 1.0)
        triangles = _mesh_file_triangles(mesh.get("filename", ""))
        return None if triangles is None else triangles * np.array(scale)
    box = geometry.find("box")
    if box is not None:
        x, y, z = _floats(box.get("size"), 3)
        return box_triangles((0.5 * x, 0.5 * y, 0.5 * z))
    import trimesh

    cylinder = geometry.find("cylinder")
    if cylinder is not None:
        solid = trimesh.creation.cylinder(
            radius=float(cylinder.get("radius", "0")),
            height=float(cylinder.get("length", "0")),
            sections=16,
        )
        return np.asarray(solid.triangles, dtype=float)
    sphere = geometry.find("sphere")
    if sphere is not None:
        solid = trimesh.creation.icosphere(subdivisions=1, radius=float(sphere.get("radius", "0")))
        return np.asarray(solid.triangles, dtype=float)
    return None


@cache
def _mesh_file_triangles(filename: str) -> np.ndarray | None:
    import trimesh

    try:
        mesh = trimesh.load(filename, force="mesh")
        triangles = np.asarray(getattr(mesh, "triangles", ()), dtype=float)
    except Exception:
        return None
    return triangles if triangles.ndim == 3 and len(triangles) else None


def _floats(text: str | None, n: int, default: float = 0.0) -> tuple[float, ...]:
    if not text:
        return (default,) * n
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        return (default,) * n
    return values if len(values) == n else (default,) * n


def _rpy_matrix(rpy: tuple[float, ...]) -> np.ndarray:
    """URDF roll-pitch-yaw (fixed axes x, y, z) as a rotation matrix."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )
