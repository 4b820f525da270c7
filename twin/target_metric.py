"""Tracking time to 4 mm, measured by the twin against ground truth.

The controller announces the object it pursues (``PickTarget``: a track id, its estimate of the
grasp point, a phase). When a new target starts, the twin matches the announced grasp point to
the nearest object. The true grasp point is on that object's vertical axis through its centre
of mass (the footprint's centroid for the extruded proxies, the point a controller aims at),
at the announced grasp height; it is fixed in the object's frame. The controller's estimate
only chooses the object and the height: its horizontal error is part of what is measured, not
part of the reference. From then on, each step, the twin measures the distance from the TCP to
that point *as the object really is*. The tracking time is
from the start of the target to the moment after which the distance stays below the threshold
(4 mm) until the pursuit ends (the gripper starts closing, another target starts, or the object
is picked). A pursuit that never settles has no tracking time and is counted as unsettled.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from interfaces.metrics import TRACKING_THRESHOLD_M, SettleTimer
from interfaces.phases import TRACKED_PHASES

PURSUIT_PHASES = TRACKED_PHASES  # the announced phases the twin measures (interfaces.phases)

Pose = tuple[tuple[float, float, float], tuple[float, float, float, float]]


Vec3 = tuple[float, float, float]


def _cross(a: Vec3, b: Vec3) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _rotate(q: tuple[float, float, float, float], v: Vec3) -> Vec3:
    """``v`` turned by the unit quaternion ``q`` (xyzw): ``v + 2 u x (u x v + w v)``, in floats
    (numpy's per-call cost is most of it at this size, every physics step of a pursuit)."""
    x, y, z, w = q
    u = (x, y, z)
    c = _cross(u, v)
    t = _cross(u, (c[0] + w * v[0], c[1] + w * v[1], c[2] + w * v[2]))
    return (v[0] + 2.0 * t[0], v[1] + 2.0 * t[1], v[2] + 2.0 * t[2])


@dataclass(frozen=True)
class TrackingResult:
    """One pursuit: ``time_to_threshold_s`` is None when it never settled."""

    track_id: int
    object_id: int
    start_s: float
    end_s: float
    time_to_threshold_s: float | None


class TargetTracker:
    """Follows one controller's announced targets and measures how fast its TCP settles (the
    settling rule is :class:`interfaces.metrics.SettleTimer`'s, shared with the controller)."""

    def __init__(
        self, threshold_m: float = TRACKING_THRESHOLD_M, match_radius_m: float = 0.1
    ) -> None:
        self.threshold_m = threshold_m
        self.match_radius_m = match_radius_m
        self.results: list[TrackingResult] = []
        self._track_id: int | None = None
        self._object_id = 0
        self._offset: Vec3 = (0.0, 0.0, 0.0)
        self._timer = SettleTimer(0.0, threshold_m)

    @property
    def active(self) -> bool:
        """Whether a pursuit is being measured."""
        return self._track_id is not None

    def announce(
        self,
        time_s: float,
        track_id: int,
        grasp_point: tuple[float, float, float],
        phase: str,
        poses: dict[int, Pose],
    ) -> None:
        """A ``PickTarget`` arrived; ``poses`` maps object ids to their true poses now."""
        if self._track_id is not None and (
            track_id != self._track_id or phase not in PURSUIT_PHASES
        ):
            self.finish(time_s)
        if self._track_id is None and phase in PURSUIT_PHASES:
            best, best_d = 0, math.inf
            for oid, (pos, _) in poses.items():
                d = math.hypot(pos[0] - grasp_point[0], pos[1] - grasp_point[1])
                if d < best_d:
                    best, best_d = oid, d
            if best and best_d <= self.match_radius_m:
                pos, orn = poses[best]
                inv = (-orn[0], -orn[1], -orn[2], orn[3])
                self._offset = _rotate(inv, (0.0, 0.0, grasp_point[2] - pos[2]))
                self._track_id, self._object_id = track_id, best
                self._timer = SettleTimer(time_s, self.threshold_m)

    def update(
        self,
        time_s: float,
        tcp_m: tuple[float, float, float],
        pose_of: Callable[[int], Pose | None],
    ) -> None:
        """Measure one step; ``pose_of`` gives an object's true pose (None once it is gone)."""
        if self._track_id is None:
            return
        pose = pose_of(self._object_id)
        if pose is None:
            self.finish(time_s)
            return
        pos, orn = pose
        d = _rotate(orn, self._offset)
        point = (pos[0] + d[0], pos[1] + d[1], pos[2] + d[2])
        self._timer.update(time_s, math.dist(tcp_m, point))

    def finish(self, time_s: float) -> None:
        """End the current pursuit (e.g. the object was picked)."""
        if self._track_id is None:
            return
        timer = self._timer
        self.results.append(
            TrackingResult(
                self._track_id, self._object_id, timer.start_s, time_s, timer.settled_after_s
            )
        )
        self._track_id = None
