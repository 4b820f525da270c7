"""Choose the next object to pick, and say why every other object is not picked.

An object is a candidate when its class has a bin at this station, the tool can grasp an object
of its size (:meth:`~control.tools.ControllerTool.misfit`) and carry its estimated mass
(:func:`holds_estimate`), the line's allocation lets this
station have it (:mod:`control.allocation`), the arm can intercept it inside the station's pick
window and hold it before it leaves the window (:attr:`~control.tools.GraspTiming.held_after_s`:
a grasp outside the window does not count), its grasp point stays within reach (between
``scheduler.min_reach_m`` and ``max_reach_m`` from the base) until the tool has closed, and no
other object lies in the footprints the tool comes down on
(:meth:`~control.tools.ControllerTool.footprints`). The arm can intercept an
object when it can be above it inside the window: the earliest such meeting is searched, not
iterated. Among candidates the highest class priority wins, then the least time left in the
window, then the shortest time to intercept; with ``scheduler.rank: cycle`` (throughput
first) the shortest time to intercept and carry to the bin comes before the time left.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass

from control.config import ControllerConfig
from control.tracking import Track


@dataclass(frozen=True, kw_only=True)
class Untargeted:
    """An object that was not chosen, and why (one of :data:`UNTARGETED_REASONS`)."""

    track_id: int
    reason: str


@dataclass(frozen=True, kw_only=True)
class Schedule:
    """Result of one scheduling decision.

    ``target`` is None when nothing can be picked; ``approach_s`` is the estimated time from now
    until the TCP can be above the target (:func:`approach_time_s`), ``intercept_s`` until it
    reaches the target's grasp point; ``time_left_s`` the time until the target leaves the pick
    window.
    """

    target: Track | None
    approach_s: float
    intercept_s: float
    time_left_s: float
    untargeted: tuple[Untargeted, ...]


def move_time_s(
    distance_m: float, max_velocity: float, max_acceleration: float, max_jerk: float
) -> float:
    """Estimate of a jerk-limited rest-to-rest move time over ``distance_m``.

    Long moves (cruise at ``max_velocity``): ``d / v + v / a + a / j``; medium moves (peak
    acceleration reached): ``2 sqrt(d / a) + a / j``; short moves (jerk only):
    ``(32 d / j) ** (1/3)``. Monotonic in the distance.
    """
    d, v, a, j = abs(distance_m), max_velocity, max_acceleration, max_jerk
    if d == 0.0:
        return 0.0
    if d <= 2.0 * a**3 / j**2:
        return float((32.0 * d / j) ** (1.0 / 3.0))
    cruise_from_m = v * v / a + v * a / j
    if d < cruise_from_m:
        return max(2.0 * math.sqrt(d / a) + a / j, float((32.0 * d / j) ** (1.0 / 3.0)))
    return d / v + v / a + a / j


def grasp_z_m(height_m: float, config: ControllerConfig) -> float:
    """World z of the grasp point of an object ``height_m`` tall lying on the belt: where the
    tool grasps it (:meth:`~control.tools.ControllerTool.grasp_height_m`)."""
    return config.belt.surface_z_m + config.tool.grasp_height_m(height_m, config.pick)


def grasp_xy_at(track: Track, config: ControllerConfig, t_s: float) -> tuple[float, float]:
    """Where the tool grasps the track at ``t_s`` (its constant-velocity prediction), world
    ``(x, y)``: the track's position plus the tool's offset
    (:meth:`~control.tools.ControllerTool.grasp_offset_m`)."""
    x, y = track.position_at(t_s)
    dx_m, dy_m = config.tool.grasp_offset_m(track)
    return x + dx_m, y + dy_m


def base_lift_m(track: Track, config: ControllerConfig) -> float:
    """How far the track's underside is above the belt surface (0 when unknown or below)."""
    if not math.isfinite(track.base_z_m):
        return 0.0
    return max(0.0, track.base_z_m - config.belt.surface_z_m)


def grasp_height_m(track: Track, config: ControllerConfig) -> float:
    """World z of the grasp point of ``track``: :func:`grasp_z_m`, raised by what it lies on and
    lowered by where on its top the tool grasps (:meth:`~control.tools.ControllerTool.grasp_drop_m`:
    a tipped piece's suction point lies below its top)."""
    drop_m = config.tool.grasp_drop_m(track)
    return grasp_z_m(track.height_m, config) + base_lift_m(track, config) - drop_m


def approach_rise_m(track: Track, config: ControllerConfig, clear_rise_m: float = 0.0) -> float:
    """How far above the grasp point the approach ends: ``pick.approach_height_m`` above the
    object's top, not above a suction point lower than the top (a tipped piece's), which would
    bring the tool in sideways into the piece's raised part; ``clear_rise_m`` higher still to
    pass over the neighbours (:func:`clearance_rise_m`)."""
    return config.pick.approach_height_m + config.tool.grasp_drop_m(track) + clear_rise_m


def approach_z_m(track: Track, config: ControllerConfig, clear_rise_m: float = 0.0) -> float:
    """World z of the TCP where the approach to ``track`` ends (:func:`approach_rise_m`)."""
    return grasp_height_m(track, config) + approach_rise_m(track, config, clear_rise_m)


def clearance_rise_m(track: Track, others: Sequence[Track], config: ControllerConfig) -> float:
    """How much higher than :func:`approach_rise_m` the approach to ``track`` must end for the
    tool to pass over every other object whose footprint comes within
    ``pick.approach_clear_radius_m`` of the grasp point: the TCP ``pick.approach_clear_m``
    above the tallest such top (a joint-space move comes down on its end point along no
    straight line, and a hand ending beside a taller neighbour sweeps its fingers through it).
    0 when off (a radius of 0) or when no neighbour is that tall. The tracks move together
    with the belt, so their relative positions hold until the meeting."""
    pick = config.pick
    radius = pick.approach_clear_radius_m
    if radius <= 0.0:
        return 0.0
    gx, gy = grasp_xy_at(track, config, track.stamp_s)
    top_z = -math.inf
    for other in others:
        if other.track_id == track.track_id:
            continue
        reach = radius + math.hypot(other.length_m, other.width_m) / 2
        if math.hypot(other.position_m[0] - gx, other.position_m[1] - gy) > reach:
            continue
        top_z = max(top_z, config.belt.surface_z_m + base_lift_m(other, config) + other.height_m)
    if not math.isfinite(top_z):
        return 0.0
    return max(0.0, top_z + pick.approach_clear_m - approach_z_m(track, config))


INTERCEPT_HORIZON_S = 5.0
"""Latest intercept searched for (s); an object the arm cannot meet sooner is not targeted."""

_SCAN_STEP_S = 0.1
_BISECTIONS = 7


def nearest_grasp_yaw(yaw_rad: float, reference_rad: float, period_rad: float) -> float:
    """``yaw_rad + k * period_rad`` closest to ``reference_rad``: of the grasp yaws a tool
    symmetric under turns of ``period_rad`` (pi for a parallel gripper) allows, the nearest.
    A period of 0 (a tool whose grasp does not depend on the object's yaw): ``reference_rad``."""
    if period_rad == 0.0:
        return reference_rad
    return yaw_rad + period_rad * round((reference_rad - yaw_rad) / period_rad)


def yaw_turn_s(track: Track, tcp_yaw_rad: float, config: ControllerConfig) -> float:
    """Time the tool needs to turn from ``tcp_yaw_rad`` to the nearest of the track's grasp
    yaws (:func:`nearest_grasp_yaw`), less the part of the turn the descent may overlap
    (``pick.descend_yaw_lead_s``)."""
    motion = config.motion
    period_rad = config.tool.grasp_yaw_period_rad
    turn_rad = abs(nearest_grasp_yaw(track.yaw_rad, tcp_yaw_rad, period_rad) - tcp_yaw_rad)
    turn_s = move_time_s(
        turn_rad, motion.max_velocity[3], motion.max_acceleration[3], motion.max_jerk[3]
    )
    return max(0.0, turn_s - config.pick.descend_yaw_lead_s)


def approach_time_s(
    track: Track,
    now_s: float,
    tcp_position_m: tuple[float, float, float],
    config: ControllerConfig,
    *,
    tcp_yaw_rad: float | None = None,
) -> float:
    """Earliest time from ``now_s`` at which the TCP can be above the moving track's grasp point,
    moving with it.

    The first ``t >= 0`` with ``move_time(|tcp - p(now + t)|) + reverse_s <= t``, ``p`` the
    track's constant-velocity prediction at approach height, ``reverse_s`` the time to match
    the track's speed along x when the TCP meets it moving against it (the meeting point is on
    the track's upstream side of the TCP: the TCP has to turn round), ``|vx| / a``; moving with
    the track, the speed matching overlaps the move. A scan in 0.1 s steps, then bisection to
    about 1 ms. (A fixed-point iteration on ``t`` oscillates for fast objects far upstream.)
    With ``tcp_yaw_rad`` the tool's turn to the grasp yaw bounds ``t`` from below as well
    (:func:`yaw_turn_s`). ``math.inf`` when there is no such time within
    :data:`INTERCEPT_HORIZON_S`.
    """
    motion = config.motion
    v, a, j = motion.max_velocity[0], motion.max_acceleration[0], motion.max_jerk[0]
    z = approach_z_m(track, config)
    turn_s = 0.0 if tcp_yaw_rad is None else yaw_turn_s(track, tcp_yaw_rad, config)

    vx = track.velocity_mps[0]

    def late(t_s: float) -> bool:
        x, y = track.position_at(now_s + t_s)
        reverse_s = abs(vx) / a if (x - tcp_position_m[0]) * vx < 0.0 else 0.0
        return move_time_s(math.dist(tcp_position_m, (x, y, z)), v, a, j) + reverse_s <= t_s

    lo = turn_s  # no meeting before the turn is done
    if lo > INTERCEPT_HORIZON_S:
        return math.inf
    if late(lo):
        return lo
    hi = lo + _SCAN_STEP_S
    while not late(hi):
        lo = hi
        hi += _SCAN_STEP_S
        if hi > INTERCEPT_HORIZON_S:
            return math.inf
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if late(mid):
            hi = mid
        else:
            lo = mid
    return hi


def descend_after_s(config: ControllerConfig) -> float:
    """Time from above the object to its grasp point: the descent plus the time margin."""
    return descend_time_s(config) + config.scheduler.time_margin_s


def descend_time_s(config: ControllerConfig) -> float:
    """Estimated time to descend ``pick.approach_height_m`` from the approach point."""
    motion = config.motion
    return move_time_s(
        config.pick.approach_height_m,
        motion.max_velocity[2],
        motion.max_acceleration[2],
        motion.max_jerk[2],
    )


def _corners(
    centre: tuple[float, float], yaw_rad: float, half_long_m: float, half_across_m: float
) -> list[tuple[float, float]]:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return [
        (
            centre[0] + a * half_long_m * c - b * half_across_m * s,
            centre[1] + a * half_long_m * s + b * half_across_m * c,
        )
        for a, b in ((1, 1), (-1, 1), (-1, -1), (1, -1))
    ]


def _disc_overlap(
    centre: tuple[float, float], radius_m: float, corners: list[tuple[float, float]]
) -> bool:
    """Whether a disc overlaps a rectangle (its corners in order): the rectangle's point
    nearest the centre, in the rectangle's own axes, lies within the radius."""
    (x0, y0), (x1, y1), _, (x3, y3) = corners
    ox, oy = 0.5 * (x0 + corners[2][0]), 0.5 * (y0 + corners[2][1])
    dx, dy = centre[0] - ox, centre[1] - oy
    distance_sq = 0.0
    for ex, ey in ((x0 - x1, y0 - y1), (x0 - x3, y0 - y3)):  # the two side directions
        half = 0.5 * math.hypot(ex, ey)
        along = abs(dx * ex + dy * ey) / (2.0 * half) if half > 0.0 else 0.0
        distance_sq += max(0.0, along - half) ** 2
    return distance_sq <= radius_m * radius_m


def _overlap(a: list[tuple[float, float]], b: list[tuple[float, float]]) -> bool:
    """Separating-axis test of two convex quadrilaterals (corner lists in order)."""
    for poly in (a, b):
        for i in range(4):
            (x0, y0), (x1, y1) = poly[i], poly[(i + 1) % 4]
            nx, ny = y0 - y1, x1 - x0
            pa = [nx * x + ny * y for x, y in a]
            pb = [nx * x + ny * y for x, y in b]
            if max(pa) < min(pb) or max(pb) < min(pa):
                return False
    return True


def blocked_by(track: Track, others: Sequence[Track], config: ControllerConfig) -> int | None:
    """The id of a track in the way of the tool coming down on ``track``, or None.

    In the way: a footprint overlapping one of the tool's footprints about the grasp point
    (:meth:`~control.tools.ControllerTool.footprints`, grown by ``scheduler.clearance_m`` and
    turned with the track), if it reaches as high as that footprint cares about.
    """
    clearance = config.scheduler.clearance_m
    footprints = config.tool.footprints(clearance)
    grasp_z = grasp_height_m(track, config)
    areas = [
        (
            f,
            _corners(track.position_m, track.yaw_rad, f.half_along_m, f.half_across_m),
            None if f.clear_above_tcp_m is None else grasp_z + f.clear_above_tcp_m - clearance,
        )
        for f in footprints
    ]
    radius = max(math.hypot(f.half_along_m, f.half_across_m) for f in footprints)
    x, y = track.position_m
    grasp_xy = grasp_xy_at(track, config, track.stamp_s)
    radius += math.dist(grasp_xy, (x, y))  # the disc about the grasp point, off the centre
    for other in others:
        if other.track_id == track.track_id:
            continue
        reach = radius + math.hypot(other.length_m, other.width_m) / 2
        if math.hypot(other.position_m[0] - x, other.position_m[1] - y) > reach:
            continue  # bounding circles apart: the rectangles cannot overlap
        footprint = _corners(other.position_m, other.yaw_rad, other.length_m / 2, other.width_m / 2)
        top_z = config.belt.surface_z_m + base_lift_m(other, config) + other.height_m
        for area, corners, min_top_z in areas:
            if min_top_z is not None and not top_z >= min_top_z:
                continue  # too low to reach this part of the tool
            hit = (
                _disc_overlap(grasp_xy, area.half_along_m, footprint)
                if area.disc
                else _overlap(corners, footprint)
            )
            if hit:
                return other.track_id
    return None


def carry_time_s(track: Track, meet_s: float, config: ControllerConfig) -> float:
    """Estimated time to carry ``track``, met at ``meet_s``, to its bin: the turn of the base
    joint between the two bearings, at the robot's datasheet limits of that joint (0 without a
    datasheet velocity, or a bin)."""
    robot = config.robot
    drop = config.bins.get(track.class_name)
    if drop is None or not robot.joint_max_velocity_rps:
        return 0.0
    base = config.base_position_m
    x, y = track.position_at(meet_s)
    turn = math.atan2(drop[1] - base[1], drop[0] - base[0]) - math.atan2(y - base[1], x - base[0])
    turn = abs(math.remainder(turn, 2.0 * math.pi))
    return move_time_s(
        turn,
        robot.joint_max_velocity_rps[0] * config.motion.transfer_speed_scale,
        robot.joint_max_acceleration_rps2[0],
        robot.joint_max_jerk_rps3[0],
    )


def class_density_kg_m3(class_name: str, config: ControllerConfig) -> float | None:
    """The density the controller estimates a piece of ``class_name``'s mass with:
    ``scheduler.class_density_kg_m3``'s, else (``scheduler.check_mass``) the cell's class
    table's (what the cell file the controller reads says: a run's resolved cell carries its
    dataset's); None when it checks no mass of that class."""
    sched = config.scheduler
    density = sched.class_density_kg_m3.get(class_name)
    if density is None and sched.check_mass:
        density = config.cell.materials.material(class_name).density_kg_m3
    return density


def estimated_mass_kg(track: Track, config: ControllerConfig) -> float | None:
    """The track's mass from its seen box, ``scheduler.fill_fraction`` full, and its class's
    density (:func:`class_density_kg_m3`); None for a class with no density."""
    density = class_density_kg_m3(track.class_name, config)
    if density is None:
        return None
    volume_m3 = track.length_m * track.width_m * track.height_m * config.scheduler.fill_fraction
    return volume_m3 * density


def holds_estimate(track: Track, config: ControllerConfig) -> bool:
    """Whether the tool can carry the track's estimated mass (:func:`estimated_mass_kg`) at
    ``scheduler.carry_acceleration_mps2``; True without an estimate."""
    mass_kg = estimated_mass_kg(track, config)
    if mass_kg is None:
        return True
    return config.tool.holds(track.class_name, mass_kg, config.scheduler.carry_acceleration_mps2)


def static_reason(track: Track, config: ControllerConfig) -> str | None:
    """Why the station ``config`` drives would never take the piece ``track`` stands for (one
    of :data:`STATIC_REASONS`), None when it could: its class has no bin at the station
    (``no_bin``), the tool does not fit its seen box and suction point
    (:meth:`~control.tools.ControllerTool.misfit` with ``scheduler.grasp_width_margin_m``:
    ``too_wide``, ``too_flat``, ``too_small``, ``too_tilted``), or the tool could not carry
    its estimated mass (:func:`holds_estimate`: ``too_heavy``). The scheduler's own first
    checks, and the judgement of :mod:`control.fit`."""
    if track.class_name not in config.bins:
        return "no_bin"
    misfit = config.tool.misfit(
        length_m=track.length_m,
        width_m=track.width_m,
        height_m=track.height_m,
        width_margin_m=config.scheduler.grasp_width_margin_m,
        face_radius_m=track.suction_radius_m,
        face_tilt_rad=track.suction_tilt_rad,
    )
    if misfit is not None:
        return misfit
    if not holds_estimate(track, config):
        return "too_heavy"
    return None


def _static_reason(
    track: Track, config: ControllerConfig, excluded_ids: Collection[int]
) -> str | None:
    """The reasons that need no timing: checked first, before any intercept search (a track
    of too low a confidence, :func:`static_reason`, an excluded track)."""
    if track.class_confidence < config.scheduler.min_confidence:
        return "low_confidence"
    reason = static_reason(track, config)
    if reason is not None:
        return reason
    if track.track_id in excluded_ids:
        return "excluded"
    return None


def unsettled(
    track: Track, belt_velocity_mps: tuple[float, float], config: ControllerConfig
) -> bool:
    """The track's velocity differs from the belt's measured ``(vx, vy)`` by more than
    ``scheduler.settle_tolerance_mps``: an object still sliding or tumbling, or a young track
    whose velocity has not converged, whose prediction misses the meeting point by
    centimetres at speed (False when the belt's velocity is not known). Such a track is left
    ``unsettled`` and considered again at the next update."""
    if not all(math.isfinite(v) for v in belt_velocity_mps):
        return False
    dv = math.dist(track.velocity_mps, belt_velocity_mps)
    return dv > config.scheduler.settle_tolerance_mps


def _past_window(track: Track, now_s: float, config: ControllerConfig) -> bool:
    """Whether :func:`_timing_reason` says ``too_late`` for ``track`` whatever the intercept
    search finds: a track moving downstream (``vx > 0``) already past the window's exit, or
    past it when held even with an approach of no time at all (the intercept comes no sooner,
    and a later one only lies farther downstream; no meeting at all is ``too_late`` too). The
    same arithmetic as :func:`_timing_reason` with an approach of 0 s, so the answer is exact;
    checked before the search, which most of the tracks a station sees downstream of its
    window (the line's neighbours' pieces) would otherwise cost."""
    if not track.velocity_mps[0] > 0.0:
        return False
    x_max = config.pick_window_x_m[1]
    if track.position_m[0] > x_max:
        return True
    return held_x_m(track, now_s, 0.0, config) > x_max


def held_x_m(track: Track, now_s: float, approach_s: float, config: ControllerConfig) -> float:
    """Where along the belt (x, m) ``track`` is when the grasp of a pick whose approach takes
    ``approach_s`` from ``now_s`` holds it (``timing.held_after_s`` after the intercept): past
    the window's exit, the pick is ``too_late``."""
    intercept_s = approach_s + descend_after_s(config)
    return track.position_at(now_s + intercept_s + config.timing.held_after_s)[0]


def _timing_reason(
    track: Track,
    now_s: float,
    approach_s: float,
    config: ControllerConfig,
    *,
    others: Sequence[Track] = (),
) -> str | None:
    """The reasons that depend on when the arm can meet the track (after :func:`_static_reason`)."""
    belt = config.belt
    if not math.isfinite(approach_s):  # cannot be met within the search horizon
        return "too_late" if track.velocity_mps[0] > 0.0 else "out_of_reach"
    intercept_s = approach_s + descend_after_s(config)
    x_min, x_max = config.pick_window_x_m
    x_meet, y_meet = track.position_at(now_s + intercept_s)
    timing = config.timing
    x_done, y_done = track.position_at(
        now_s + intercept_s + timing.dwell_s - timing.close_overlap_s + timing.close_s
    )
    if held_x_m(track, now_s, approach_s, config) > x_max or track.position_m[0] > x_max:
        return "too_late"  # the grasp of an object outside the window does not count
    x_above, _ = track.position_at(now_s + approach_s)
    if x_above < x_min:
        return "upstream"
    z = grasp_height_m(track, config)
    off_belt = abs(track.position_m[1] - belt.centre_y_m) > belt.width_m / 2
    if off_belt or not _followable(track, (x_meet, y_meet), (x_done, y_done), z, config):
        return "out_of_reach"
    if blocked_by(track, others, config) is not None:
        return "blocked"
    return None


def _followable(
    track: Track,
    meet_xy: tuple[float, float],
    done_xy: tuple[float, float],
    z_m: float,
    config: ControllerConfig,
) -> bool:
    """Whether the grasp point stays within reach while the tool follows it from ``meet_xy``
    to ``done_xy`` (at height ``z_m``): between ``scheduler.min_reach_m`` and ``max_reach_m``
    from the base all along that straight path (its farthest point is an end, its nearest may
    lie between them), and, with ``scheduler.base_turn_fraction``, slow enough for the base
    joint: following a point moving at ``v`` past the base's vertical axis turns the base at
    ``|v| d / r**2`` (``d`` the path's distance from the axis, ``r`` the point's), fastest
    where the path comes nearest, and that must stay within the fraction of the first joint's
    datasheet velocity (a Panda following a piece at 0.6 m/s 0.25 m from its base would turn
    it at 2.4 rad/s, beyond its 2.175)."""
    sched = config.scheduler
    bx, by, bz = config.base_position_m
    ax, ay = meet_xy[0] - bx, meet_xy[1] - by
    ex, ey = done_xy[0] - bx, done_xy[1] - by
    dz = z_m - bz
    far_sq = max(ax * ax + ay * ay, ex * ex + ey * ey)
    sx, sy = ex - ax, ey - ay
    length_sq = sx * sx + sy * sy
    along = 0.0 if length_sq == 0.0 else min(1.0, max(0.0, -(ax * sx + ay * sy) / length_sq))
    nx, ny = ax + along * sx, ay + along * sy
    near_sq = nx * nx + ny * ny
    if far_sq + dz * dz > sched.max_reach_m**2 or near_sq + dz * dz < sched.min_reach_m**2:
        return False
    fraction = sched.base_turn_fraction
    velocities = config.robot.joint_max_velocity_rps
    if fraction <= 0.0 or not velocities or near_sq == 0.0:
        return fraction <= 0.0 or not velocities
    vx, vy = track.velocity_mps
    turn_rate = abs(vx * ay - vy * ax) / near_sq  # |v x r| is the same all along the path
    return turn_rate <= fraction * velocities[0]


def schedule(
    tracks: Sequence[Track],
    *,
    now_s: float,
    tcp_position_m: tuple[float, float, float],
    config: ControllerConfig,
    excluded_ids: Collection[int] = (),
    tcp_yaw_rad: float | None = None,
    approach_estimate: Callable[[Track], float] | None = None,
    allow: Callable[[Track], str | None] | None = None,
) -> Schedule:
    """Choose the next target among confirmed ``tracks`` (already predicted to ``now_s``).

    ``excluded_ids`` are tracks that must not be chosen again (e.g. a failed pick);
    ``tcp_yaw_rad``, the tool's yaw now, adds the turn to each grasp yaw to its meeting time.
    ``approach_estimate(track)``, when given, replaces :func:`approach_time_s` as the time (s)
    until the arm can be above the track (``inf`` when it cannot): the joint-space approach
    estimates its own move. ``allow(track)``, when given, is the line's allocation: the reason
    this station must leave the track to another (:mod:`control.allocation`), or None (it may
    also say ``unsettled``, :func:`unsettled`).
    """
    x_max = config.pick_window_x_m[1]
    ranked: list[tuple[tuple[float, float, float, int], Track, float, float]] = []
    untargeted: list[Untargeted] = []
    after_s = descend_after_s(config)
    for track in tracks:
        if not track.confirmed:
            continue
        reason = _static_reason(track, config, excluded_ids)
        if reason is None and allow is not None:
            reason = allow(track)
        approach_s = math.inf
        if reason is None and _past_window(track, now_s, config):
            reason = "too_late"
        if reason is None:  # the intercept search only for tracks that could be picked
            approach_s = (
                approach_time_s(track, now_s, tcp_position_m, config, tcp_yaw_rad=tcp_yaw_rad)
                if approach_estimate is None
                else approach_estimate(track)
            )
            reason = _timing_reason(track, now_s, approach_s, config, others=tracks)
        if reason is not None:
            untargeted.append(Untargeted(track_id=track.track_id, reason=reason))
            continue
        vx = track.velocity_mps[0]
        time_left_s = (x_max - track.position_m[0]) / vx if vx > 1e-6 else math.inf
        priority = config.class_priorities.get(track.class_name, 0.0)
        if config.scheduler.rank == "cycle":
            cycle_s = approach_s + after_s + carry_time_s(track, now_s + approach_s, config)
            key = (-priority, cycle_s, time_left_s, track.track_id)
        else:
            key = (-priority, time_left_s, approach_s + after_s, track.track_id)
        ranked.append((key, track, approach_s, time_left_s))
    if not ranked:
        return Schedule(
            target=None,
            approach_s=math.nan,
            intercept_s=math.nan,
            time_left_s=math.nan,
            untargeted=tuple(untargeted),
        )
    ranked.sort(key=lambda item: item[0])
    _, target, approach_s, time_left_s = ranked[0]
    untargeted.extend(
        Untargeted(track_id=item[1].track_id, reason="lower_priority") for item in ranked[1:]
    )
    return Schedule(
        target=target,
        approach_s=approach_s,
        intercept_s=approach_s + after_s,
        time_left_s=time_left_s,
        untargeted=tuple(untargeted),
    )
