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

from interfaces.fileio import write_atomic
from twin.errors import SceneError
from twin.objects import read_mesh


def read_pieces(path: Path) -> list[np.ndarray]:
    """Vertices of each ``o`` block of a convex-pieces OBJ, ``[(n, 3) float, ...]``."""
    arrays = [v for v in read_mesh(path).group_vertices() if len(v) >= 4]
    if not arrays:
        msg = f"{path}: no convex piece with at least 4 vertices"
        raise SceneError(msg)
    return arrays


def _hulls(rings: list[np.ndarray]) -> list[np.ndarray]:
    """Convex hull of each ``(n, 2)`` point set, counter-clockwise ``(m, 2)``; ``m < 3`` if flat."""
    import shapely

    sizes = np.array([len(r) for r in rings])
    points = shapely.multipoints(
        np.concatenate(rings), indices=np.repeat(np.arange(len(rings)), sizes)
    )
    out: list[np.ndarray] = []
    for hull in shapely.convex_hull(points):
        if not isinstance(hull, shapely.Polygon):
            out.append(np.empty((0, 2)))
            continue
        ring = np.asarray(hull.exterior.coords)[:-1]
        out.append(ring if shapely.is_ccw(hull.exterior) else ring[::-1].copy())
    return out


def _area(ring: np.ndarray) -> float:
    if len(ring) < 3:
        return 0.0
    x, y = ring[:, 0], ring[:, 1]
    twice = x[:-1] @ y[1:] - y[:-1] @ x[1:] + x[-1] * y[0] - y[-1] * x[0]
    return 0.5 * abs(float(twice))


def merge_pieces(pieces: list[np.ndarray], tolerance: float, max_pieces: int) -> list[np.ndarray]:
    """Greedily merge prism pieces ``(n, 3)`` whose joint hull adds little area (see module).

    Each round merges the pair whose joint hull adds the least area relative to the pair's
    (the first such pair in index order on ties); pair hulls are computed once and only the
    merged piece's pairs are recomputed. Pieces whose footprint has no area are dropped.
    """
    footprints = [f for f in _hulls([p[:, :2] for p in pieces]) if len(f) >= 3] if pieces else []
    if not footprints:
        msg = "no convex piece with a footprint of positive area"
        raise SceneError(msg)
    areas = [_area(f) for f in footprints]
    z_lo = min(float(p[:, 2].min()) for p in pieces)
    z_hi = max(float(p[:, 2].max()) for p in pieces)
    k = len(footprints)
    cost = np.full((k, k), np.inf)
    joint: dict[tuple[int, int], np.ndarray] = {}
    ids = list(range(k))  # stable identity of each current footprint

    def fill(pairs: list[tuple[int, int]]) -> None:
        if not pairs:
            return
        hulls = _hulls([np.vstack((footprints[i], footprints[j])) for i, j in pairs])
        for (i, j), hull in zip(pairs, hulls, strict=True):
            joint[ids[i], ids[j]] = hull
            pair_area = areas[i] + areas[j]
            cost[ids[i], ids[j]] = (_area(hull) - pair_area) / pair_area

    fill([(i, j) for i in range(k) for j in range(i + 1, k)])
    while len(footprints) > 1:
        live = np.array(ids)
        sub = cost[np.ix_(live, live)]
        flat = int(np.argmin(sub))
        i, j = divmod(flat, len(live))
        excess = float(sub[i, j])
        if not np.isfinite(excess):
            break
        if excess > tolerance and len(footprints) <= max_pieces:
            break
        hull = joint[ids[i], ids[j]]
        footprints[i], areas[i] = hull, _area(hull)
        cost[ids[j], :] = np.inf
        cost[:, ids[j]] = np.inf
        del footprints[j], areas[j], ids[j]
        row = ids[i]
        cost[row, :] = np.inf
        cost[:, row] = np.inf
        fill([(a, i) if a < i else (i, a) for a in range(len(footprints)) if a != i])
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


MERGE_VERSION = 1
"""Bumped whenever :func:`read_pieces`, :func:`merge_pieces` or :func:`pieces_obj_text` would
give a different file for the same source."""


def merged_collision_file(source: Path, cache_dir: Path, tolerance: float, max_pieces: int) -> Path:
    """The merged-pieces OBJ for ``source``, from ``cache_dir`` or written there first.

    The file name is keyed by the source's *content*, the merge parameters and
    :data:`MERGE_VERSION`, so a persistent ``cache_dir`` is shared safely by every episode, run
    and process (the same dataset is merged once per machine, not once per episode) and a changed
    mesh or algorithm never reads a stale file. Files are written atomically: one that exists is
    complete.
    """
    try:
        content = source.read_bytes()
    except OSError as exc:
        msg = f"{source}: cannot read the convex pieces: {exc.strerror or exc}"
        raise SceneError(msg) from None
    digest = hashlib.sha1(content)
    digest.update(f"|{tolerance!r}|{max_pieces}|v{MERGE_VERSION}".encode())
    target = cache_dir / f"{source.stem}-{digest.hexdigest()[:20]}.obj"
    if not target.is_file():
        pieces = merge_pieces(read_pieces(source), tolerance, max_pieces)
        try:
            write_atomic(target, pieces_obj_text(pieces, source.name))
        except OSError as exc:
            msg = (
                f"{target}: cannot write the merged collision shape of {source}: "
                f"{exc.strerror or exc} (CDW_TWIN_CACHE chooses the cache folder)"
            )
            raise SceneError(msg) from None
    return target
