"""Outlines for the built-in sample: irregular footprints with a given size and fill.

:func:`outline` returns a ring whose minimum-area rectangle (as meshgen measures it) is
``length x width`` and whose area is ``fill x length x width``. The ring starts as the
``length x width`` rectangle and loses area in two ways:

- cut corners (convex): each corner is cut by a triangle whose legs are up to 45 % of the
  sides at the planned size (never beyond 49 %), different at every corner, so the outline is
  an irregular polygon between a rectangle (fill 1) and a rhombus (fill 0.5);
- a notch (concave): a rectangular bite out of one long side, in its middle part (a U shape)
  or at one end (an L shape), up to 75 % of the width deep.

The real sample is convex except for rubber (strips and bent profiles): the convex hull adds
more than 10 % to the area of 77 % of the real rubber pieces, 13 % of the bricks, 5 % of the
concrete and 1 % of the wood pieces; each class's chance of a notch follows that
(:data:`STYLES`). A notch takes the larger share of the area to remove; corners take the rest.
The edges are then roughened a little: points every centimetre, moved inwards along a smooth
random profile by up to 1.5 mm (less for fuller shapes). One scale factor on all cuts is
solved for (regula falsi) so that the fill meshgen will measure is the wanted one, and the ring
is finally turned onto its measured rectangle's axes and stretched to exactly
``length x width``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import shapely

from meshgen.annotations import FloatArray
from meshgen.config import MeshgenConfig
from meshgen.footprint import min_area_rectangle

CORNER_LEG_FRACTION = 0.45
"""Longest planned corner-cut leg as a fraction of its side."""
LEG_LIMIT = 0.49
"""No leg grows beyond this fraction of its side, so every side keeps a piece."""
SIDE_PAIRS: tuple[tuple[tuple[int, int], int], ...] = (
    ((0, 1), 0),
    ((1, 2), 1),
    ((2, 3), 0),
    ((3, 0), 1),
)
"""The two corners on each side (bottom, right, top, left) and which leg (0: x, 1: y) lies on
it."""
NOTCH_DEPTH_MAX = 0.75
"""Deepest notch as a fraction of the width."""
NOTCH_LENGTH_MAX = 0.8
"""Longest notch as a fraction of the length."""
EDGE_STEP_M = 0.01
"""Spacing of the points along an edge."""
WAVE_STEP_M = 0.03
"""Spacing of the random depths of the roughness profile (linear in between)."""
ROUGHNESS_MAX_M = 0.0015
"""Deepest inward move of an edge point."""
SIMPLIFY_M = MeshgenConfig().simplify_mm / 1000.0
"""meshgen's default simplification tolerance, applied when measuring an outline."""
SCALE_MAX = 4.0
"""Largest factor on the planned cuts (the plan aims at 1; legs stop at :data:`LEG_LIMIT`)."""
SOLVER_STEPS = 40
FILL_TOLERANCE = 1e-4
FILL_ACCEPTED = 0.005
"""An outline whose fill misses by more is planned again (other corners), up to
:data:`ATTEMPTS` times; the closest is kept."""
ATTEMPTS = 8


@dataclass(frozen=True, slots=True)
class ShapeStyle:
    """How a class's outlines lose area: the chance of a notch whatever the fill, and the
    share of the removed area the notch takes when there is one."""

    notch_probability: float
    notch_share: tuple[float, float]


STYLES: dict[str, ShapeStyle] = {
    "concrete": ShapeStyle(notch_probability=0.05, notch_share=(0.5, 0.8)),
    "brick": ShapeStyle(notch_probability=0.10, notch_share=(0.5, 0.8)),
    "wood": ShapeStyle(notch_probability=0.02, notch_share=(0.5, 0.8)),
    "rubber": ShapeStyle(notch_probability=0.80, notch_share=(0.6, 0.9)),
}
DEFAULT_STYLE = ShapeStyle(notch_probability=0.1, notch_share=(0.5, 0.8))
CORNERS_ALONE_MIN_FILL = 0.62
"""Below this fill every outline gets a notch (four saturated corners leave 0.52)."""


@dataclass(frozen=True, slots=True)
class _Plan:
    """Cuts at scale 1, in metres: corner legs ``(4, 2)`` (x and y leg of each corner,
    counter-clockwise from the origin corner), the notch ``(start_x, length, depth)`` on the
    top side or None, and the roughness depths at :data:`WAVE_STEP_M` intervals."""

    legs: FloatArray
    notch: tuple[float, float, float] | None
    roughness: FloatArray


def _leg_factors(rng: np.random.Generator) -> FloatArray:
    """``(4, 2)`` corner legs as fractions of their sides (x leg of the length, y leg of the
    width), counter-clockwise from the origin corner. Two opposite corners cut deeply (a skew
    hexagon), the two corners of one long side (a trapezoid, down to a triangle), or all four
    alike (an irregular octagon); the other corners a little. Deep cuts at all four corners of
    a squarish piece would make it round enough that a turned rectangle fits it better, and its
    rectangle would no longer be length x width, hence the first two patterns are the common
    ones."""
    factors = rng.uniform(0.02, 0.15, (4, 2))
    pattern = rng.random()
    first = int(rng.integers(0, 4))
    if pattern < 0.4:
        deep = [first, (first + 2) % 4]
        factors[deep] = rng.uniform(0.25, 0.45, (2, 2))
    elif pattern < 0.8:
        deep = [0, 1] if first < 2 else [2, 3]
        factors[deep, 0] = rng.uniform(0.25, 0.45, 2)
        factors[deep, 1] = rng.uniform(0.4, 0.9, 2)
    else:
        factors = rng.uniform(0.1, 0.45, (4, 2))
    return factors


def _plan(
    rng: np.random.Generator, style: ShapeStyle, length: float, width: float, fill: float
) -> _Plan:
    remove = max(0.0, 1.0 - fill) * length * width
    legs = _leg_factors(rng) * np.array([length, width])
    capacity = float(np.sum(legs[:, 0] * legs[:, 1])) / 2.0
    notch = None
    corner_area = remove
    if rng.random() < style.notch_probability or fill < CORNERS_ALONE_MIN_FILL:
        corner_area = (1.0 - rng.uniform(*style.notch_share)) * remove
        depth = rng.uniform(0.5, 1.0) * NOTCH_DEPTH_MAX * width
        notch_length = min((remove - corner_area) / depth, NOTCH_LENGTH_MAX * length)
        clear = 1.5 * (legs[3, 0] + legs[2, 0]) * math.sqrt(corner_area / capacity)
        if rng.random() < 0.5 or notch_length + clear >= length:
            start = length - notch_length
            legs[2] = 0.0  # the notch replaces the top right corner's cut
        else:
            start = rng.uniform(0.0, length - notch_length - clear) + 0.5 * clear
        notch = (start, notch_length, depth)
    legs *= math.sqrt(corner_area / capacity) if capacity > 0.0 else 0.0
    depth_m = min(ROUGHNESS_MAX_M, 0.1 * max(0.0, 1.0 - fill) * width)
    knots = int(2.0 * (length + width) / WAVE_STEP_M) + 2
    return _Plan(legs=legs, notch=notch, roughness=rng.random(knots) * depth_m)


def _corner_points(plan: _Plan, s: float, length: float, width: float) -> list[FloatArray]:
    """Polygon vertices of the cut rectangle at cut scale ``s``, counter-clockwise."""
    legs = plan.legs * s
    for (c0, c1), k in SIDE_PAIRS:  # two cuts on one side leave a piece of it
        limit = 2.0 * LEG_LIMIT * (length, width)[k]
        total = legs[c0, k] + legs[c1, k]
        if total > limit:
            legs[[c0, c1], k] *= limit / total
    depth = 0.0
    if plan.notch is not None:  # the cuts stay clear of the notch: the ring stays simple
        start, notch_length, planned_depth = plan.notch
        depth = min(planned_depth * s, NOTCH_DEPTH_MAX * width)
        legs[3, 0] = min(legs[3, 0], start)
        legs[2, 0] = min(legs[2, 0], length - start - notch_length)
        legs[:2, 1] = np.minimum(legs[:2, 1], (0.95 - depth / width) * width)
    (a0, b0), (a1, b1), (a2, b2), (a3, b3) = legs.tolist()
    pts = [(a0, 0.0), (length - a1, 0.0), (length, b1), (length, width - b2)]
    if plan.notch is not None:
        start, notch_length, _ = plan.notch
        end = start + notch_length
        if end >= length - 1e-12:
            pts[-1] = (length, width - depth)
            pts += [(start, width - depth), (start, width)]
        else:
            pts += [(length - a2, width), (end, width), (end, width - depth)]
            pts += [(start, width - depth), (start, width)]
    else:
        pts += [(length - a2, width)]
    pts += [(a3, width), (0.0, width - b3), (0.0, b0)]
    return [np.array(p) for p in pts]


def _roughened(corners: list[FloatArray], roughness: FloatArray) -> FloatArray:
    """Points every :data:`EDGE_STEP_M` along the polygon's edges, moved inwards by the smooth
    roughness profile (zero at the vertices)."""
    out = []
    arc = 0.0
    knots = WAVE_STEP_M * np.arange(len(roughness))
    for a, b in zip(corners, corners[1:] + corners[:1], strict=True):
        edge = b - a
        size = float(np.hypot(*edge))
        if size <= 1e-12:
            continue
        inward = np.array([-edge[1], edge[0]]) / size
        steps = max(1, round(size / EDGE_STEP_M))
        for j in range(steps):
            t = j / steps
            depth = float(np.interp(arc + t * size, knots, roughness)) * math.sin(math.pi * t)
            out.append(a + t * edge + depth * inward)
        arc += size
    return np.array(out)


def _measure(ring: FloatArray) -> tuple[float, float, float, float]:
    """(yaw, length, width, fill) as meshgen measures the ring with its default configuration
    (after simplifying it: the roughness it smooths away would otherwise add area)."""
    simple = shapely.simplify(shapely.Polygon(ring), SIMPLIFY_M, preserve_topology=True)
    pts = np.asarray(simple.exterior.coords)[:-1]
    yaw, length, width = min_area_rectangle(pts, simple)
    return yaw, length, width, float(simple.area) / (length * width)


def _solve_scale(excess: Callable[[float], float]) -> float:
    """The cut scale in [0, SCALE_MAX] where the decreasing ``excess`` (measured fill minus wanted)
    crosses zero: regula falsi with the Illinois step, or the end nearest to it."""
    a, b = 0.0, SCALE_MAX
    fa, fb = excess(a), excess(b)
    if fa <= 0.0 or fb >= 0.0:
        return a if fa <= 0.0 else b
    side = 0
    for _ in range(SOLVER_STEPS):
        c = b - fb * (b - a) / (fb - fa)
        fc = excess(c)
        if abs(fc) < FILL_TOLERANCE:
            return c
        if fc > 0.0:
            a, fa = c, fc
            fb = fb / 2.0 if side == -1 else fb
            side = -1
        else:
            b, fb = c, fc
            fa = fa / 2.0 if side == 1 else fa
            side = 1
    return c


def outline(
    rng: np.random.Generator, class_name: str, length_m: float, width_m: float, fill: float
) -> FloatArray:
    """A closed ring ``(n, 2)`` in metres, centred on its rectangle, long side along x, with the
    wanted minimum-area rectangle ``length_m x width_m`` and area ``fill`` times its area."""
    style = STYLES.get(class_name, DEFAULT_STYLE)
    best: tuple[float, FloatArray, tuple[float, float, float, float]] | None = None
    for _ in range(ATTEMPTS):
        plan = _plan(rng, style, length_m, width_m, fill)

        def ring_at(s: float, plan: _Plan = plan) -> FloatArray:
            return _roughened(_corner_points(plan, s, length_m, width_m), plan.roughness)

        def excess(s: float, ring_at: Callable[[float], FloatArray] = ring_at) -> float:
            return _measure(ring_at(s))[3] - fill

        ring = ring_at(_solve_scale(excess))
        measured = _measure(ring)
        miss = abs(measured[3] - fill)
        if best is None or miss < best[0]:
            best = (miss, ring, measured)
        if miss <= FILL_ACCEPTED:
            break
    assert best is not None
    _, ring, (yaw, length, width, _) = best
    c, s = math.cos(yaw), math.sin(yaw)
    local = (ring - ring.mean(axis=0)) @ np.array([[c, -s], [s, c]])
    local -= 0.5 * (local.max(axis=0) + local.min(axis=0))
    result: FloatArray = local * np.array([length_m / length, width_m / width])
    return result
