"""Footprints of the player's objects: the outline each mesh casts on the belt seen from above
(its convex hull, or the boundary of its bottom face when that is one closed chain), a box for
an object without its mesh, and where each object's mesh lies in the dataset.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from interfaces.errors import CdwTwinError


class PlayerError(CdwTwinError):
    """An episode folder cannot be turned into a player page (the message says why)."""


def _convex_hull(points: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    """Counter-clockwise convex hull (Andrew's monotone chain)."""
    pts = sorted(set(points))
    if len(pts) < 3:
        return pts

    def cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, float]] = []
    upper: list[tuple[float, float]] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


@dataclass(frozen=True)
class Footprint:
    """An object's outline ``ring`` ``(n, 2)`` in its own xy plane and the z span of its
    prism (object frame, m): the top view is the union of the ring at both heights and the
    side faces between them, turned and moved by the object's pose."""

    ring: tuple[tuple[float, float], ...]
    z_low_m: float
    z_high_m: float

    def scaled_z(self, height_m: float) -> Footprint:
        """The same footprint for the prism stretched along z to ``height_m`` (as the twin
        stretches a mesh about its origin to a sampled height)."""
        span = self.z_high_m - self.z_low_m
        if span <= 0 or height_m <= 0:
            return self
        k = height_m / span
        return Footprint(self.ring, self.z_low_m * k, self.z_high_m * k)


def footprint_outline(mesh_path: Path) -> Footprint:
    """The outline of a mesh seen along its own z axis, in its own frame (m), and its z span.

    The ring is the boundary of the mesh's bottom faces (those whose corners all lie at the
    lowest z), chained into one ring: the exact, possibly concave, footprint of a meshgen
    prism. A mesh whose bottom is not one flat ring gets the convex hull of its vertices' xy.
    """
    from meshgen.errors import ObjFileError
    from meshgen.objfile import read_obj

    try:
        mesh = read_obj(mesh_path)
    except ObjFileError as exc:
        raise PlayerError(str(exc)) from None
    vertices = mesh.vertices
    if len(vertices) < 3:
        msg = f"{mesh_path}: {len(vertices)} vertices, no footprint"
        raise PlayerError(msg)
    z = vertices[:, 2]
    z_low, z_high = float(z.min()), float(z.max())
    tol = 1e-6 * max(1.0, z_high - z_low)
    low = z < z_low + tol
    edges: dict[tuple[int, int], int] = {}
    for face in mesh.faces:
        corners = [int(i) for i in face]
        if not all(low[i] for i in corners):
            continue
        for a, b in zip(corners, corners[1:] + corners[:1], strict=True):
            key = (min(a, b), max(a, b))
            edges[key] = edges.get(key, 0) + 1
    ring = _chain([e for e, n in edges.items() if n == 1])
    if ring is None or len(ring) < 3:
        points = _convex_hull([(float(v[0]), float(v[1])) for v in vertices])
    else:
        points = [(float(vertices[i][0]), float(vertices[i][1])) for i in ring]
    return Footprint(tuple(points), z_low, z_high)


def _chain(edges: list[tuple[int, int]]) -> list[int] | None:
    """The single closed ring the undirected ``edges`` form, None when they form anything else."""
    if not edges:
        return None
    links: dict[int, list[int]] = {}
    for a, b in edges:
        links.setdefault(a, []).append(b)
        links.setdefault(b, []).append(a)
    if any(len(v) != 2 for v in links.values()):
        return None
    start = edges[0][0]
    ring, prev, here = [start], -1, start
    while True:
        a, b = links[here]
        nxt = a if a != prev else b
        if nxt == start:
            break
        ring.append(nxt)
        prev, here = here, nxt
    return ring if len(ring) == len(links) else None


def box_outline(length_m: float, width_m: float, height_m: float) -> Footprint:
    """A ``length_m`` x ``width_m`` x ``height_m`` box about the origin, along x, y and z."""
    hx, hy = 0.5 * length_m, 0.5 * width_m
    return Footprint(((-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)), -0.5 * height_m, 0.5 * height_m)


class MeshFinder:
    """Finds ``<dataset>/<image>/<source_id>.obj``: first in the folder the id's prefix names
    (meshgen's ids are ``<image>_<k>``), else through the dataset's ``index.csv`` and each
    image's ``scene.csv`` (read once, only when needed)."""

    def __init__(self, dataset: Path | None) -> None:
        self.dataset = dataset
        self._index: dict[str, Path] | None = None

    def find(self, source_id: str) -> Path | None:
        """The mesh of ``source_id``, None when the dataset does not have it."""
        if self.dataset is None or not source_id:
            return None
        guess = self.dataset / source_id.rsplit("_", 1)[0] / f"{source_id}.obj"
        if guess.is_file():
            return guess
        if self._index is None:
            self._index = self._read_index()
        return self._index.get(source_id)

    def _read_index(self) -> dict[str, Path]:
        found: dict[str, Path] = {}
        assert self.dataset is not None
        index = self.dataset / "index.csv"
        if not index.is_file():
            return found
        try:
            with index.open(encoding="utf-8", newline="") as handle:
                scenes = [self.dataset / r["scene_csv"] for r in csv.DictReader(handle)]
            for scene in scenes:
                with scene.open(encoding="utf-8", newline="") as handle:
                    for row in csv.DictReader(handle):
                        found[row["object_id"]] = scene.parent / row["mesh_path"]
        except (OSError, KeyError, csv.Error, UnicodeDecodeError):
            return found
        return found
