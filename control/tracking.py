"""Multi-object tracking of waste on the belt: one constant-velocity Kalman filter per object.

The state of every filter is ``[x, y, vx, vy]`` in the world frame (metres, m/s). New tracks
start at the detected position with the measured belt velocity as velocity prior. Detections of
one camera frame are assigned to tracks by the Hungarian method on the squared Mahalanobis
distance, with a gate. Class is a confidence-weighted vote; yaw (modulo pi) and the footprint are
smoothed exponentially. :meth:`Tracker.predict_to` extrapolates every track to the time a command
will take effect, which compensates perception and actuation latency.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from control.config import TrackingConfig

REJECT_REASONS: tuple[str, ...] = (
    "non_finite",
    "unknown_class",
    "out_of_order",
    "low_confidence",
    "bad_size",
)
"""Reasons a detection is rejected before assignment; :attr:`Tracker.rejected` counts each."""

_GATE_INF = 1e12


def wrap_half_turn(yaw_rad: float) -> float:
    """Wrap an angle modulo pi into ``[-pi/2, pi/2)`` (a rectangle's yaw is symmetric)."""
    return (yaw_rad + math.pi / 2) % math.pi - math.pi / 2


@dataclass(frozen=True, kw_only=True)
class Detection:
    """One detected object in the world frame.

    ``stamp_s`` is the capture time (not the arrival time). ``length_m >= width_m`` is not
    required; the tracker normalises the footprint so that ``yaw_rad`` is along the long side.
    ``base_z_m`` is the world z of the object's underside (the belt surface, or the top of the
    object it lies on); NaN when the camera does not say.
    """

    stamp_s: float
    class_name: str
    confidence: float
    x_m: float
    y_m: float
    yaw_rad: float
    length_m: float
    width_m: float
    height_m: float
    base_z_m: float = math.nan

    def is_finite(self) -> bool:
        """True when every numeric field is a finite number (``base_z_m`` may be NaN)."""
        values = (
            self.stamp_s,
            self.confidence,
            self.x_m,
            self.y_m,
            self.yaw_rad,
            self.length_m,
            self.width_m,
            self.height_m,
        )
        return all(math.isfinite(v) for v in values)


@dataclass(frozen=True, kw_only=True)
class Track:
    """A snapshot of one tracked object at ``stamp_s``.

    ``position_m`` and ``velocity_mps`` are ``(x, y)``; ``position_std_m`` is the square root of
    the larger eigenvalue of the position covariance. ``length_m >= width_m`` and ``yaw_rad`` is
    the direction of the long side in ``[-pi/2, pi/2)``. ``base_z_m`` is the smoothed world z of
    the object's underside, NaN when no detection gave one (then it lies on the belt).
    """

    track_id: int
    stamp_s: float
    class_name: str
    class_confidence: float
    position_m: tuple[float, float]
    velocity_mps: tuple[float, float]
    position_std_m: float
    yaw_rad: float
    length_m: float
    width_m: float
    height_m: float
    hits: int
    confirmed: bool
    last_update_s: float
    base_z_m: float = math.nan

    def position_at(self, t_s: float) -> tuple[float, float]:
        """The constant-velocity prediction of the position at ``t_s``."""
        dt_s = t_s - self.stamp_s
        return (
            self.position_m[0] + self.velocity_mps[0] * dt_s,
            self.position_m[1] + self.velocity_mps[1] * dt_s,
        )


class _TrackState:
    """Mutable per-object state: the filter plus smoothed attributes and the class vote."""

    def __init__(
        self,
        track_id: int,
        detection: Detection,
        belt_velocity_mps: tuple[float, float],
        config: TrackingConfig,
    ) -> None:
        self.track_id = track_id
        self.kf = KalmanFilter(dim_x=4, dim_z=2)
        self.kf.x = np.array([detection.x_m, detection.y_m, *belt_velocity_mps], dtype=float)
        r = config.position_std_m**2
        v = config.initial_velocity_std_mps**2
        self.kf.P = np.diag([r, r, v, v])
        self.kf.H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
        self.kf.R = np.eye(2) * r
        self.stamp_s = detection.stamp_s
        self.last_update_s = detection.stamp_s
        self.hits = 1
        self.confirmed = config.confirm_hits <= 1
        self.votes: dict[str, float] = {}
        self.votes[detection.class_name] = self.votes.get(detection.class_name, 0.0) + max(
            detection.confidence, 1e-6
        )
        self.yaw_vec = (math.cos(2 * detection.yaw_rad), math.sin(2 * detection.yaw_rad))
        self.length_m = detection.length_m
        self.width_m = detection.width_m
        self.height_m = detection.height_m
        self.base_z_m = detection.base_z_m

    def predict(self, t_s: float, accel_var: float) -> None:
        dt_s = t_s - self.stamp_s
        if dt_s <= 0.0:
            return
        self.kf.F = np.array(
            [
                [1.0, 0.0, dt_s, 0.0],
                [0.0, 1.0, 0.0, dt_s],
                [0.0, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
        self.kf.Q = Q_discrete_white_noise(
            dim=2, dt=dt_s, var=accel_var, block_size=2, order_by_dim=False
        )
        self.kf.predict()
        self.stamp_s = t_s

    def update(self, detection: Detection, config: TrackingConfig) -> None:
        self.kf.update(np.array([detection.x_m, detection.y_m]))
        self.last_update_s = detection.stamp_s
        self.hits += 1
        if self.hits >= config.confirm_hits:
            self.confirmed = True
        self.votes[detection.class_name] = self.votes.get(detection.class_name, 0.0) + max(
            detection.confidence, 1e-6
        )
        a = config.smoothing
        c, s = math.cos(2 * detection.yaw_rad), math.sin(2 * detection.yaw_rad)
        self.yaw_vec = ((1 - a) * self.yaw_vec[0] + a * c, (1 - a) * self.yaw_vec[1] + a * s)
        self.length_m = (1 - a) * self.length_m + a * detection.length_m
        self.width_m = (1 - a) * self.width_m + a * detection.width_m
        self.height_m = (1 - a) * self.height_m + a * detection.height_m
        if math.isfinite(detection.base_z_m):
            known = math.isfinite(self.base_z_m)
            base = detection.base_z_m
            self.base_z_m = (1 - a) * self.base_z_m + a * base if known else base

    def snapshot(self, x: NDArray[np.float64], p: NDArray[np.float64], t_s: float) -> Track:
        class_name, weight = max(self.votes.items(), key=lambda item: item[1])
        total = sum(self.votes.values())
        position_std = math.sqrt(max(float(np.linalg.eigvalsh(p[:2, :2])[-1]), 0.0))
        return Track(
            track_id=self.track_id,
            stamp_s=t_s,
            class_name=class_name,
            class_confidence=weight / total,
            position_m=(float(x[0]), float(x[1])),
            velocity_mps=(float(x[2]), float(x[3])),
            position_std_m=position_std,
            yaw_rad=wrap_half_turn(0.5 * math.atan2(self.yaw_vec[1], self.yaw_vec[0])),
            length_m=self.length_m,
            width_m=self.width_m,
            height_m=self.height_m,
            hits=self.hits,
            confirmed=self.confirmed,
            last_update_s=self.last_update_s,
            base_z_m=self.base_z_m,
        )


def _normalised(detection: Detection) -> Detection:
    """Swap length and width (turning yaw by pi/2) so that length is the long side."""
    if detection.width_m <= detection.length_m:
        yaw = wrap_half_turn(detection.yaw_rad)
        length, width = detection.length_m, detection.width_m
    else:
        yaw = wrap_half_turn(detection.yaw_rad + math.pi / 2)
        length, width = detection.width_m, detection.length_m
    return Detection(
        stamp_s=detection.stamp_s,
        class_name=detection.class_name,
        confidence=detection.confidence,
        x_m=detection.x_m,
        y_m=detection.y_m,
        yaw_rad=yaw,
        length_m=length,
        width_m=width,
        height_m=detection.height_m,
    )


class Tracker:
    """Kalman multi-object tracker with Mahalanobis gating and Hungarian assignment.

    Call :meth:`update` once per camera frame (frames in stamp order) and :meth:`predict_to`
    whenever a planner needs the tracks at a given time. Rejected detections are counted per
    reason in :attr:`rejected`.
    """

    def __init__(self, config: TrackingConfig, *, classes: Iterable[str]) -> None:
        """Create an empty tracker of objects of ``classes`` (detections of others are
        rejected as ``unknown_class``)."""
        self._config = config
        self._classes = frozenset(classes)
        self._tracks: dict[int, _TrackState] = {}
        self._next_id = 1
        self._last_stamp_s = -math.inf
        self._rejected: Counter[str] = Counter()
        self._accel_var = config.process_accel_std_mps2**2

    @property
    def rejected(self) -> Mapping[str, int]:
        """Number of rejected detections per reason (keys from :data:`REJECT_REASONS`)."""
        return {reason: self._rejected[reason] for reason in REJECT_REASONS}

    @property
    def last_stamp_s(self) -> float:
        """Stamp of the last accepted frame (``-inf`` before the first)."""
        return self._last_stamp_s

    def _accept(self, detections: Iterable[Detection], stamp_s: float) -> list[Detection]:
        accepted: list[Detection] = []
        for det in detections:
            if not det.is_finite():
                self._rejected["non_finite"] += 1
            elif det.class_name not in self._classes:
                self._rejected["unknown_class"] += 1
            elif det.stamp_s != stamp_s or det.stamp_s <= self._last_stamp_s:
                self._rejected["out_of_order"] += 1
            elif det.confidence < self._config.min_confidence:
                self._rejected["low_confidence"] += 1
            elif min(det.length_m, det.width_m, det.height_m) <= 0.0:
                self._rejected["bad_size"] += 1
            else:
                accepted.append(_normalised(det))
        return accepted

    def update(
        self,
        stamp_s: float,
        detections: Sequence[Detection],
        belt_velocity_mps: tuple[float, float],
    ) -> None:
        """Process one camera frame captured at ``stamp_s``.

        Detections whose own stamp differs from ``stamp_s``, or frames not newer than the last
        one, are rejected as ``out_of_order``. ``belt_velocity_mps`` is ``(vx, vy)`` and seeds the
        velocity of tracks born in this frame.
        """
        accepted = self._accept(detections, stamp_s)
        if not math.isfinite(stamp_s) or stamp_s <= self._last_stamp_s:
            if math.isfinite(stamp_s):
                self._rejected["out_of_order"] += len(accepted)
            else:
                self._rejected["non_finite"] += len(accepted)
            return
        self._last_stamp_s = stamp_s
        if not all(math.isfinite(v) for v in belt_velocity_mps):
            belt_velocity_mps = (0.0, 0.0)
        for state in self._tracks.values():
            state.predict(stamp_s, self._accel_var)
        unmatched = self._assign(accepted)
        for det in unmatched:
            self._tracks[self._next_id] = _TrackState(
                self._next_id, det, belt_velocity_mps, self._config
            )
            self._next_id += 1
        dead = [
            tid
            for tid, state in self._tracks.items()
            if stamp_s - state.last_update_s > self._config.max_coast_s
        ]
        for tid in dead:
            del self._tracks[tid]

    def _assign(self, detections: list[Detection]) -> list[Detection]:
        """Update matched tracks in place; return the detections that matched no track."""
        states = list(self._tracks.values())
        if not states or not detections:
            return detections
        cost = np.full((len(states), len(detections)), _GATE_INF)
        gate_sq = self._config.gate_mahalanobis_sq
        for i, state in enumerate(states):
            kf = state.kf
            s = kf.H @ kf.P @ kf.H.T + kf.R
            s_inv = np.linalg.inv(s)
            predicted = kf.x[:2]
            for j, det in enumerate(detections):
                innovation = np.array([det.x_m, det.y_m]) - predicted
                d_sq = float(innovation @ s_inv @ innovation)
                near = float(np.hypot(*innovation)) <= self._config.gate_min_m
                if d_sq <= gate_sq or near:
                    cost[i, j] = d_sq
        rows, cols = linear_sum_assignment(cost)
        matched: set[int] = set()
        for i, j in zip(rows, cols, strict=True):
            if cost[i, j] >= _GATE_INF:
                continue
            states[i].update(detections[j], self._config)
            matched.add(int(j))
        return [det for j, det in enumerate(detections) if j not in matched]

    def predict_to(self, t_s: float, *, confirmed_only: bool = True) -> tuple[Track, ...]:
        """Every (confirmed) track extrapolated to ``t_s`` without changing the filters.

        Tracks are returned in increasing ``track_id`` order.
        """
        result: list[Track] = []
        for tid in sorted(self._tracks):
            state = self._tracks[tid]
            if confirmed_only and not state.confirmed:
                continue
            dt_s = t_s - state.stamp_s
            kf = state.kf
            x = np.asarray(kf.x, dtype=float)
            p = np.asarray(kf.P, dtype=float)
            if dt_s > 0.0:
                f = np.array(
                    [
                        [1.0, 0.0, dt_s, 0.0],
                        [0.0, 1.0, 0.0, dt_s],
                        [0.0, 0.0, 1.0, 0.0],
                        [0.0, 0.0, 0.0, 1.0],
                    ]
                )
                q = Q_discrete_white_noise(
                    dim=2, dt=dt_s, var=self._accel_var, block_size=2, order_by_dim=False
                )
                x = f @ x
                p = f @ p @ f.T + q
            result.append(state.snapshot(x, p, max(t_s, state.stamp_s)))
        return tuple(result)

    def __len__(self) -> int:
        """Number of live tracks (tentative and confirmed)."""
        return len(self._tracks)
