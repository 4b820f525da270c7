"""Collision shapes for the physics: meshgen's exact convex pieces, merged within a tolerance.

meshgen writes an *exact* convex decomposition of every concave footprint (Hertel-Mehlhorn on the
triangulation). Jagged real outlines decompose into many thin pieces, and collision cost grows
with the piece count. For the physics the twin merges neighbouring pieces greedily while the
convex hull of a merged pair adds at most ``tolerance`` of the pair's area, then keeps merging the
cheapest pairs until at most ``max_pieces`` remain. Concave objects stay concave (an L or a C
keeps its notch: merging across it costs far more than the tolerance); only slivers and
staircase notches are absorbed. ``tolerance = 0`` and a large ``max_pieces`` keep the exact
decomposition.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from twin.errors import SceneError
from twin.fileio import write_atomic


def read_pieces(path: Path) -> list[np.ndarray]:
    """Vertices of each ``o`` block of a convex-pieces OBJ, ``[(n, 3) float, ...]``."""
    pieces: list[list[list[float]]] = []
    current: list[list[float]] | None = None
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        msg = f"{path}: cannot read: {exc.strerror}"
        raise SceneError(msg) from None
    for number, line in enumerate(lines, start=1):
        if line.startswith("o "):
            current = []
            pieces.append(current)
        elif line.startswith("v "):
            if current is None:
                current = []
                pieces.append(current)
            try:
                current.append([float(v) for v in line.split()[1:4]])
            except ValueError:
                msg = f"{path}:{number}: malformed vertex line {line!r}"
                raise SceneError(msg) from None
    arrays = [np.asarray(p, dtype=float) for p in pieces if len(p) >= 4]
    if not arrays:
        msg = f"{path}: no convex piece with at least 4 vertices"
        raise SceneError(msg)
    return arrays


def _hull_2d(points: np.ndarray) -> np.ndarray:
    """Convex hull of ``(n, 2)`` points, counter-clockwise, ``(m, 2)`` (monotone chain)."""
    pts = np.unique(np.round(points, 9), axis=0)
    if len(pts) < 3:
        return pts

    def half(seq: np.ndarray) -> list[np.ndarray]:
        out: list[np.ndarray] = []
        for p in seq:
            while len(out) >= 2:
                a, b = out[-2], out[-1]
                if (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) <= 0:
                    out.pop()
                else:
                    break
            out.append(p)
        return out

    lower = half(pts)
    upper = half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _area(ring: np.ndarray) -> float:
    if len(ring) < 3:
        return 0.0
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def merge_pieces(pieces: list[np.ndarray], tolerance: float, max_pieces: int) -> list[np.ndarray]:
    """Greedily merge prism pieces ``(n, 3)`` whose joint hull adds little area (see module)."""
    footprints = [_hull_2d(p[:, :2]) for p in pieces]
    areas = [_area(f) for f in footprints]
    z_lo = min(float(p[:, 2].min()) for p in pieces)
    z_hi = max(float(p[:, 2].max()) for p in pieces)
    while len(footprints) > 1:
        best: tuple[float, int, int, np.ndarray] | None = None
        for i in range(len(footprints)):
            for j in range(i + 1, len(footprints)):
                hull = _hull_2d(np.vstack([footprints[i], footprints[j]]))
                joint = areas[i] + areas[j]
                excess = (_area(hull) - joint) / joint if joint > 0 else 0.0
                if best is None or excess < best[0]:
                    best = (excess, i, j, hull)
        if best is None:
            break
        excess, i, j, hull = best
        if excess > tolerance and len(footprints) <= max_pieces:
            break
        footprints[i], areas[i] = hull, _area(hull)
        del footprints[j], areas[j]
    return [
        np.vstack(
            [
                np.column_stack([f, np.full(len(f), z_lo)]),
                np.column_stack([f, np.full(len(f), z_hi)]),
            ]
        )
        for f in footprints
    ]


def pieces_obj_text(pieces: list[np.ndarray], name: str) -> str:
    """OBJ text with one closed prism (``o`` block) per piece ``(2m, 3)``: bottom ring, top ring."""
    lines = [f"# cdw-twin collision pieces of {name}"]
    base = 1
    for k, piece in enumerate(pieces):
        m = len(piece) // 2
        lines.append(f"o piece_{k}")
        lines.extend(f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in piece)
        bottom = [base + i for i in range(m)]
        top = [base + m + i for i in range(m)]
        lines.extend(f"f {bottom[0]} {bottom[i + 1]} {bottom[i]}" for i in range(1, m - 1))
        lines.extend(f"f {top[0]} {top[i]} {top[i + 1]}" for i in range(1, m - 1))
        for i in range(m):
            j = (i + 1) % m
            lines.append(f"f {bottom[i]} {bottom[j]} {top[j]}")
            lines.append(f"f {bottom[i]} {top[j]} {top[i]}")
        base += 2 * m
    return "\n".join(lines) + "\n"


def merged_collision_file(
    source: Path, cache_dir: Path, tolerance: float, max_pieces: int
) -> tuple[Path, int]:
    """Write (once) and return the merged-pieces OBJ for ``source`` and its piece count."""
    key = hashlib.sha1(f"{source}|{tolerance}|{max_pieces}".encode()).hexdigest()[:16]
    target = cache_dir / f"{source.stem}-{key}.obj"
    pieces = merge_pieces(read_pieces(source), tolerance, max_pieces)
    if not target.is_file():
        write_atomic(target, pieces_obj_text(pieces, source.name))
    return target, len(pieces)
