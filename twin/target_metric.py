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

import numpy as np

from interfaces.metrics import TRACKING_THRESHOLD_M, SettleTimer

PURSUIT_PHASES = frozenset({"approach", "descend", "dwell", "track"})

Pose = tuple[tuple[float, float, float], tuple[float, float, float, float]]


def _rotate(q: tuple[float, float, float, float], v: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    u = np.array([x, y, z])
    return np.asarray(v + 2.0 * np.cross(u, np.cross(u, v) + w * v), dtype=float)


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
        self._offset = np.zeros(3)
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
                height = np.array([0.0, 0.0, grasp_point[2] - pos[2]])
                self._offset = _rotate(inv, height)
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
        point = np.asarray(pos) + _rotate(orn, self._offset)
        self._timer.update(time_s, float(np.linalg.norm(np.asarray(tcp_m) - point)))

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
