"""Multi-object tracking of waste on the belt: one constant-velocity Kalman filter per object.

The state of every filter is ``[x, y, vx, vy]`` in the world frame (metres, m/s). New tracks
start at the detected position with the measured belt velocity as velocity prior. Detections of
one camera frame are assigned to tracks by the Hungarian method on the squared Mahalanobis
distance, with a gate. Class is a confidence-weighted vote; yaw (modulo pi) and the footprint are
smoothed exponentially. :meth:`Tracker.predict_to` extrapolates every track to the time a command
will take effect, which compensates perception and actuation latency.

The filter is written in closed form. The transition ``F``, the white-noise acceleration ``Q``
(variance ``process_accel_std_mps2**2``), the measurement ``H = [I 0]`` and ``R = r I`` act on
x and y alike and never couple them, and both axes start from the same covariance: the 4x4
covariance is two equal 2x2 blocks ``[[p_pp, p_pv], [p_pv, p_vv]]`` (position, velocity) for
all time, so one block per track is kept. The update is the Kalman update of that block, whose
gain is ``K = [p_pp, p_pv] / (p_pp + r)``. This is the standard filter, not an approximation;
it runs in Python floats, which at this size cost far less than numpy's per-call overhead.
``tests/control/test_tracking.py`` checks it against the 4x4 matrix form.

The assignment gates every (track, detection) pair with numpy in one pass. A pair that is the
only candidate of both its track and its detection is matched directly; the Hungarian method
(:func:`min_cost_assignment`, exact, on the few contested pairs) solves the rest, which has the
same optimum as
solving the whole matrix: gated-out pairs cost ``1e12``, so the optimum first maximises the
number of gated pairs and then minimises their summed distance, and an isolated pair belongs to
every such optimum.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from control.config_sections import TrackingConfig

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
    object it lies on); NaN when the camera does not say. ``suction_x_m``, ``suction_y_m``: the
    suction point the camera reports (where a round cup fits best on the top face), ``suction_z_m``
    its height (on a tipped piece lower than the top), ``suction_radius_m`` the largest lip
    radius that fits there and ``suction_tilt_rad`` the tilt of the face there from level; NaN
    when it reports none.
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
    suction_x_m: float = math.nan
    suction_y_m: float = math.nan
    suction_z_m: float = math.nan
    suction_radius_m: float = math.nan
    suction_tilt_rad: float = math.nan

    def is_finite(self) -> bool:
        """True when every numeric field is a finite number (``base_z_m`` and the suction
        point may be NaN)."""
        isfinite = math.isfinite
        return (
            isfinite(self.stamp_s)
            and isfinite(self.confidence)
            and isfinite(self.x_m)
            and isfinite(self.y_m)
            and isfinite(self.yaw_rad)
            and isfinite(self.length_m)
            and isfinite(self.width_m)
            and isfinite(self.height_m)
        )


@dataclass(frozen=True, kw_only=True)
class Track:
    """A snapshot of one tracked object at ``stamp_s``.

    ``position_m`` and ``velocity_mps`` are ``(x, y)``; ``position_std_m`` is the square root of
    the larger eigenvalue of the position covariance. ``length_m >= width_m`` and ``yaw_rad`` is
    the direction of the long side in ``[-pi/2, pi/2)``. ``base_z_m`` is the smoothed world z of
    the object's underside, NaN when no detection gave one (then it lies on the belt).
    ``suction_offset_m`` is the smoothed ``(x, y)`` of the reported suction point less the
    detected position (world frame: the suction point is ``position_m`` plus it),
    ``suction_below_top_m`` the smoothed depth of the suction point below the object's top (the
    underside plus the height; a tipped piece's upturned face slopes down from its top) and
    ``suction_radius_m`` its smoothed radius; NaN when no detection reported one (the depth also
    when none said where the underside is); ``suction_tilt_rad`` the smoothed tilt of the face
    there from level (NaN: none reported).
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
    suction_offset_m: tuple[float, float] = (math.nan, math.nan)
    suction_below_top_m: float = math.nan
    suction_radius_m: float = math.nan
    suction_tilt_rad: float = math.nan

    def position_at(self, t_s: float) -> tuple[float, float]:
        """The constant-velocity prediction of the position at ``t_s``."""
        dt_s = t_s - self.stamp_s
        return (
            self.position_m[0] + self.velocity_mps[0] * dt_s,
            self.position_m[1] + self.velocity_mps[1] * dt_s,
        )


def _fold(smoothed: float, value: float, a: float) -> float:
    """``value`` smoothed into ``smoothed`` with weight ``a``; ``value`` itself while nothing is
    known yet (``smoothed`` NaN)."""
    return (1 - a) * smoothed + a * value if math.isfinite(smoothed) else value


class _TrackState:
    """Mutable per-object state: the filter, the smoothed attributes and the class vote.

    The filter's state is ``x_m, y_m, vx_mps, vy_mps`` and its covariance the 2x2 block
    ``p_pp, p_pv, p_vv`` shared by both axes (see the module docstring), all at the tracker's
    :attr:`~Tracker.last_stamp_s`. ``class_name``, ``class_confidence`` and ``yaw_rad`` are those
    of :class:`Track`, refreshed whenever the vote or the yaw changes.
    """

    __slots__ = (
        "base_z_m",
        "class_confidence",
        "class_name",
        "confirmed",
        "height_m",
        "hits",
        "last_update_s",
        "length_m",
        "p_pp",
        "p_pv",
        "p_vv",
        "suction_below_top_m",
        "suction_dx_m",
        "suction_dy_m",
        "suction_radius_m",
        "suction_tilt_rad",
        "track_id",
        "votes",
        "vx_mps",
        "vy_mps",
        "width_m",
        "x_m",
        "y_m",
        "yaw_rad",
        "yaw_vec",
    )

    def __init__(
        self,
        track_id: int,
        detection: Detection,
        belt_velocity_mps: tuple[float, float],
        config: TrackingConfig,
    ) -> None:
        self.track_id = track_id
        self.x_m = float(detection.x_m)
        self.y_m = float(detection.y_m)
        self.vx_mps = float(belt_velocity_mps[0])
        self.vy_mps = float(belt_velocity_mps[1])
        self.p_pp = config.position_std_m**2
        self.p_pv = 0.0
        self.p_vv = config.initial_velocity_std_mps**2
        self.last_update_s = detection.stamp_s
        self.hits = 1
        self.confirmed = config.confirm_hits <= 1
        self.votes: dict[str, float] = {detection.class_name: max(detection.confidence, 1e-6)}
        self.yaw_vec = (math.cos(2 * detection.yaw_rad), math.sin(2 * detection.yaw_rad))
        self.length_m = detection.length_m
        self.width_m = detection.width_m
        self.height_m = detection.height_m
        self.base_z_m = detection.base_z_m
        self.suction_dx_m = detection.suction_x_m - detection.x_m
        self.suction_dy_m = detection.suction_y_m - detection.y_m
        self.suction_below_top_m = _below_top(detection)
        self.suction_radius_m = detection.suction_radius_m
        self.suction_tilt_rad = detection.suction_tilt_rad
        self._refresh()

    def _refresh(self) -> None:
        """Recompute the class and yaw of :class:`Track` from the vote and the yaw vector."""
        votes = self.votes
        self.class_name = max(votes, key=votes.__getitem__)
        self.class_confidence = votes[self.class_name] / sum(votes.values())
        self.yaw_rad = wrap_half_turn(0.5 * math.atan2(self.yaw_vec[1], self.yaw_vec[0]))

    def predict(self, dt_s: float, q_pp: float, q_pv: float, q_vv: float) -> None:
        """Advance the filter by ``dt_s`` with process noise ``[[q_pp, q_pv], [q_pv, q_vv]]``:
        ``P <- F P F^T + Q`` with ``F = [[1, dt], [0, 1]]`` on each axis."""
        self.x_m += self.vx_mps * dt_s
        self.y_m += self.vy_mps * dt_s
        p_pv = self.p_pv + dt_s * self.p_vv
        self.p_pp = self.p_pp + dt_s * self.p_pv + dt_s * p_pv + q_pp
        self.p_pv = p_pv + q_pv
        self.p_vv = self.p_vv + q_vv

    def update(self, detection: Detection, config: TrackingConfig, r_m2: float) -> None:
        """Correct the filter with the detected position (measurement variance ``r_m2`` per
        axis) and fold the detection's class, yaw and footprint in."""
        s_m2 = self.p_pp + r_m2
        k_p = self.p_pp / s_m2
        k_v = self.p_pv / s_m2
        innovation_x = detection.x_m - self.x_m
        innovation_y = detection.y_m - self.y_m
        self.x_m += k_p * innovation_x
        self.y_m += k_p * innovation_y
        self.vx_mps += k_v * innovation_x
        self.vy_mps += k_v * innovation_y
        # P <- (I - K H) P, written so that the block stays symmetric.
        self.p_vv -= k_v * self.p_pv
        self.p_pp = k_p * r_m2
        self.p_pv = k_v * r_m2
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
            self.base_z_m = _fold(self.base_z_m, detection.base_z_m, a)
        if math.isfinite(detection.suction_radius_m):
            self.suction_dx_m = _fold(self.suction_dx_m, detection.suction_x_m - detection.x_m, a)
            self.suction_dy_m = _fold(self.suction_dy_m, detection.suction_y_m - detection.y_m, a)
            below_m = _below_top(detection)
            if math.isfinite(below_m):
                self.suction_below_top_m = _fold(self.suction_below_top_m, below_m, a)
            self.suction_radius_m = _fold(self.suction_radius_m, detection.suction_radius_m, a)
            if math.isfinite(detection.suction_tilt_rad):
                self.suction_tilt_rad = _fold(self.suction_tilt_rad, detection.suction_tilt_rad, a)
        self._refresh()

    def snapshot(
        self, stamp_s: float, position_m: tuple[float, float], position_var_m2: float
    ) -> Track:
        """The track at ``stamp_s``, at ``position_m`` with position variance
        ``position_var_m2`` per axis.

        Built by filling a new instance's ``__dict__``, what the generated ``__init__`` of the
        frozen dataclass does field by field through ``object.__setattr__`` (it validates
        nothing): every track is snapshot at every control update, and that ``__init__`` was
        most of :meth:`Tracker.predict_to`'s cost."""
        track = object.__new__(Track)
        track.__dict__.update(
            track_id=self.track_id,
            stamp_s=stamp_s,
            class_name=self.class_name,
            class_confidence=self.class_confidence,
            position_m=position_m,
            velocity_mps=(self.vx_mps, self.vy_mps),
            position_std_m=math.sqrt(max(position_var_m2, 0.0)),
            yaw_rad=self.yaw_rad,
            length_m=self.length_m,
            width_m=self.width_m,
            height_m=self.height_m,
            hits=self.hits,
            confirmed=self.confirmed,
            last_update_s=self.last_update_s,
            base_z_m=self.base_z_m,
            suction_offset_m=(self.suction_dx_m, self.suction_dy_m),
            suction_below_top_m=self.suction_below_top_m,
            suction_radius_m=self.suction_radius_m,
            suction_tilt_rad=self.suction_tilt_rad,
        )
        return track


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
        base_z_m=detection.base_z_m,
        suction_x_m=detection.suction_x_m,
        suction_y_m=detection.suction_y_m,
        suction_z_m=detection.suction_z_m,
        suction_radius_m=detection.suction_radius_m,
        suction_tilt_rad=detection.suction_tilt_rad,
    )


def _below_top(detection: Detection) -> float:
    """How far the detection's suction point lies below its top (underside plus height); NaN
    when it reports no suction point or no underside."""
    return detection.base_z_m + detection.height_m - detection.suction_z_m


def min_cost_assignment(cost: list[list[float]]) -> list[tuple[int, int]]:
    """The assignment of minimum total cost of an ``(n, m)`` cost matrix: ``min(n, m)`` pairs
    ``(row, column)``, each row and column at most once, in row order.

    The Hungarian method with potentials and shortest augmenting paths (``O(n^2 m)``), the
    optimum ``scipy.optimize.linear_sum_assignment`` gives; written out because the tracker's
    contested blocks are a few rows wide, where importing scipy.optimize (half a second per
    controller process) costs more than every assignment of an episode.
    """
    if not cost or not cost[0]:
        return []
    transposed = len(cost) > len(cost[0])
    if transposed:
        cost = [list(column) for column in zip(*cost, strict=True)]
    n, m = len(cost), len(cost[0])
    u = [0.0] * (n + 1)  # row potentials, 1-based
    v = [0.0] * (m + 1)  # column potentials, 1-based; column 0 is the augmenting path's root
    owner = [0] * (m + 1)  # column j -> its row (1-based), 0: free
    for row in range(1, n + 1):
        _augment(cost, row, u, v, owner)
    pairs = [(owner[j] - 1, j - 1) for j in range(1, m + 1) if owner[j]]
    if transposed:
        pairs = [(j, i) for i, j in pairs]
    return sorted(pairs)


def _augment(
    cost: list[list[float]], row: int, u: list[float], v: list[float], owner: list[int]
) -> None:
    """Assign ``row`` (1-based) along the shortest augmenting path in the reduced costs,
    updating the potentials ``u``, ``v`` and the assignment ``owner`` in place."""
    m = len(v) - 1
    least = [math.inf] * (m + 1)
    used = [False] * (m + 1)
    way = [0] * (m + 1)
    owner[0] = row
    j0 = 0
    while True:
        used[j0] = True
        i0, delta, j1 = owner[j0], math.inf, 0
        for j in range(1, m + 1):
            if not used[j]:
                reduced = cost[i0 - 1][j - 1] - u[i0] - v[j]
                if reduced < least[j]:
                    least[j], way[j] = reduced, j0
                if least[j] < delta:
                    delta, j1 = least[j], j
        for j in range(m + 1):
            if used[j]:
                u[owner[j]] += delta
                v[j] -= delta
            else:
                least[j] -= delta
        j0 = j1
        if owner[j0] == 0:
            break
    while j0:
        j1 = way[j0]
        owner[j0] = owner[j1]
        j0 = j1


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
        # Insertion order is increasing track id: new ids only grow.
        self._tracks: dict[int, _TrackState] = {}
        self._next_id = 1
        self._last_stamp_s = -math.inf
        self._rejected: Counter[str] = Counter()
        self._last_rejected: tuple[str, Detection] | None = None
        self._accel_var = config.process_accel_std_mps2**2
        self._r_m2 = config.position_std_m**2

    @property
    def rejected(self) -> Mapping[str, int]:
        """Number of rejected detections per reason (keys from :data:`REJECT_REASONS`)."""
        return {reason: self._rejected[reason] for reason in REJECT_REASONS}

    @property
    def last_stamp_s(self) -> float:
        """Stamp of the last accepted frame (``-inf`` before the first); every track's filter
        is at this time."""
        return self._last_stamp_s

    @property
    def last_rejection(self) -> str:
        """The latest rejected detection and why, for a log line ("" before any)."""
        if self._last_rejected is None:
            return ""
        reason, det = self._last_rejected
        return (
            f"{reason}: {det.class_name} ({det.confidence:.2f}) at ({det.x_m:.3f}, "
            f"{det.y_m:.3f}) m, {det.length_m * 1e3:.0f} x {det.width_m * 1e3:.0f} x "
            f"{det.height_m * 1e3:.0f} mm, stamp {det.stamp_s:.3f} s"
        )

    def _accept(self, detections: Iterable[Detection], stamp_s: float) -> list[Detection]:
        accepted: list[Detection] = []
        for det in detections:
            reason = self._rejection(det, stamp_s)
            if reason is None:
                accepted.append(_normalised(det))
            else:
                self._rejected[reason] += 1
                self._last_rejected = (reason, det)
        return accepted

    def _rejection(self, det: Detection, stamp_s: float) -> str | None:
        """Why ``det`` is rejected (one of :data:`REJECT_REASONS`), None when it is not."""
        if not det.is_finite():
            return "non_finite"
        if det.class_name not in self._classes:
            return "unknown_class"
        if det.stamp_s != stamp_s or det.stamp_s <= self._last_stamp_s:
            return "out_of_order"
        if det.confidence < self._config.min_confidence:
            return "low_confidence"
        if min(det.length_m, det.width_m, det.height_m) <= 0.0:
            return "bad_size"
        return None

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
        if self._tracks:
            dt_s = stamp_s - self._last_stamp_s
            var = self._accel_var
            q_pp, q_pv, q_vv = 0.25 * dt_s**4 * var, 0.5 * dt_s**3 * var, dt_s**2 * var
            for state in self._tracks.values():
                state.predict(dt_s, q_pp, q_pv, q_vv)
        self._last_stamp_s = stamp_s
        if not all(math.isfinite(v) for v in belt_velocity_mps):
            belt_velocity_mps = (0.0, 0.0)
        unmatched = self._assign(accepted)
        for det in unmatched:
            self._tracks[self._next_id] = _TrackState(
                self._next_id, det, belt_velocity_mps, self._config
            )
            self._next_id += 1
        max_coast_s = self._config.max_coast_s
        dead = [
            tid
            for tid, state in self._tracks.items()
            if stamp_s - state.last_update_s > max_coast_s
        ]
        for tid in dead:
            del self._tracks[tid]

    def _assign(self, detections: list[Detection]) -> list[Detection]:
        """Update matched tracks in place; return the detections that matched no track.

        A pair is a candidate when its squared Mahalanobis distance is within the gate or its
        distance within ``gate_min_m``; the matching minimises the summed squared Mahalanobis
        distance of the candidates among those with the most pairs.
        """
        states = list(self._tracks.values())
        if not states or not detections:
            return detections
        config = self._config
        innovation_x = (
            np.array([d.x_m for d in detections]) - np.array([s.x_m for s in states])[:, None]
        )
        innovation_y = (
            np.array([d.y_m for d in detections]) - np.array([s.y_m for s in states])[:, None]
        )
        s_m2 = np.array([s.p_pp for s in states]) + self._r_m2
        d_sq = (innovation_x * innovation_x + innovation_y * innovation_y) / s_m2[:, None]
        gated = (d_sq <= config.gate_mahalanobis_sq) | (
            np.hypot(innovation_x, innovation_y) <= config.gate_min_m
        )
        gated &= d_sq < _GATE_INF
        rows, cols = np.nonzero(gated)
        if rows.size == 0:
            return detections
        # A candidate pair that is the only one of its track and of its detection is in every
        # optimal matching; the Hungarian method solves the rest.
        alone = (np.bincount(rows)[rows] == 1) & (np.bincount(cols)[cols] == 1)
        pairs = list(zip(rows[alone].tolist(), cols[alone].tolist(), strict=True))
        if not alone.all():
            rest_rows = np.unique(rows[~alone])
            rest_cols = np.unique(cols[~alone])
            block = np.ix_(rest_rows, rest_cols)
            cost = np.where(gated[block], d_sq[block], _GATE_INF)
            for i, j in min_cost_assignment(cost.tolist()):
                if cost[i, j] < _GATE_INF:
                    pairs.append((int(rest_rows[i]), int(rest_cols[j])))
        matched: set[int] = set()
        for i, j in pairs:
            states[i].update(detections[j], config, self._r_m2)
            matched.add(j)
        return [det for j, det in enumerate(detections) if j not in matched]

    def predict_to(self, t_s: float, *, confirmed_only: bool = True) -> tuple[Track, ...]:
        """Every (confirmed) track extrapolated to ``t_s`` without changing the filters.

        Tracks are returned in increasing ``track_id`` order, stamped ``t_s`` (the time of the
        last frame, unextrapolated, when ``t_s`` is earlier).
        """
        dt_s = t_s - self._last_stamp_s
        stamp_s = max(t_s, self._last_stamp_s)
        result: list[Track] = []
        if dt_s > 0.0:
            # The position variance of F P F^T + Q (see _TrackState.predict).
            q_pp = 0.25 * dt_s**4 * self._accel_var
            for state in self._tracks.values():
                if confirmed_only and not state.confirmed:
                    continue
                position_m = (state.x_m + state.vx_mps * dt_s, state.y_m + state.vy_mps * dt_s)
                p_pv = state.p_pv + dt_s * state.p_vv
                var_m2 = state.p_pp + dt_s * state.p_pv + dt_s * p_pv + q_pp
                result.append(state.snapshot(stamp_s, position_m, var_m2))
        else:
            for state in self._tracks.values():
                if confirmed_only and not state.confirmed:
                    continue
                result.append(state.snapshot(stamp_s, (state.x_m, state.y_m), state.p_pp))
        return tuple(result)

    def __len__(self) -> int:
        """Number of live tracks (tentative and confirmed)."""
        return len(self._tracks)
