"""Kalman tracking: convergence on noisy trajectories, identities through crossings, rejects,
and the same tracks as a plain 4x4 Kalman filter with whole-matrix Hungarian assignment."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from control import tracking
from control.bench import CameraFrame, TrackerLoad, tracker_stream
from control.config import TrackingConfig
from control.tracking import REJECT_REASONS, Detection, Track, Tracker, wrap_half_turn

RATE_HZ = 30.0
CLASSES = ("concrete", "brick", "wood", "rubber")


def _detection(t_s: float, x: float, y: float, rng: np.random.Generator, **kw: object) -> Detection:
    fields: dict[str, object] = {
        "stamp_s": t_s,
        "class_name": "wood",
        "confidence": 0.9,
        "x_m": x + rng.normal(0.0, 0.002),
        "y_m": y + rng.normal(0.0, 0.002),
        "yaw_rad": 0.4 + rng.normal(0.0, 0.02),
        "length_m": 0.15,
        "width_m": 0.05,
        "height_m": 0.03,
    }
    fields.update(kw)
    return Detection(**fields)  # type: ignore[arg-type]


@pytest.mark.parametrize("speed_mps", [0.2, 0.4, 0.6])
def test_converges_on_noisy_constant_velocity(speed_mps: float) -> None:
    rng = np.random.default_rng(7)
    tracker = Tracker(TrackingConfig(), classes=CLASSES)
    # Belt velocity prior 10 % off: the filter must still converge to the true velocity.
    for k in range(60):
        t_s = k / RATE_HZ
        tracker.update(
            t_s, [_detection(t_s, -0.5 + speed_mps * t_s, 0.45, rng)], (0.9 * speed_mps, 0)
        )
    (track,) = tracker.predict_to(2.0)
    # Stated bounds after 2 s of 2 mm noise: position 3 mm (within 4 sigma of the filter),
    # velocity 10 mm/s, yaw 0.02 rad.
    error_m = math.dist(track.position_m, (-0.5 + speed_mps * 2.0, 0.45))
    assert error_m < 0.003
    assert error_m < 4 * track.position_std_m
    assert math.dist(track.velocity_mps, (speed_mps, 0.0)) < 0.01
    assert abs(wrap_half_turn(track.yaw_rad - 0.4)) < 0.02
    assert track.class_name == "wood"
    assert track.width_m == pytest.approx(0.05)
    assert track.length_m == pytest.approx(0.15)
    assert track.position_std_m < 0.0015


@pytest.mark.parametrize("swapped", [False, True])
def test_the_underside_the_camera_reports_reaches_the_track(swapped: bool) -> None:
    """An object lying on another one: the camera's underside height (``base_z_m``) reaches
    the track, whichever side it reports as length, so the grasp is planned on its top."""
    rng = np.random.default_rng(3)
    tracker = Tracker(TrackingConfig(), classes=CLASSES)
    size = {"length_m": 0.05, "width_m": 0.15} if swapped else {}
    for k in range(10):
        t_s = k / RATE_HZ
        detection = _detection(t_s, -0.5 + 0.4 * t_s, 0.45, rng, base_z_m=0.04, **size)
        tracker.update(t_s, [detection], (0.4, 0.0))
    (track,) = tracker.predict_to(10 / RATE_HZ)
    assert track.base_z_m == pytest.approx(0.04)


@pytest.mark.parametrize("swapped", [False, True])
def test_the_suction_point_reaches_the_track_as_an_offset_from_its_position(swapped: bool) -> None:
    """The camera's suction point, 3 cm behind and 1 cm beside the detected centre, reaches the
    track as that offset (so it moves with the track's prediction), with its radius, whichever
    side the camera reports as length; a camera that reports none leaves both NaN."""
    rng = np.random.default_rng(5)
    tracker = Tracker(TrackingConfig(), classes=CLASSES)
    plain = Tracker(TrackingConfig(), classes=CLASSES)
    size = {"length_m": 0.05, "width_m": 0.15} if swapped else {}
    for k in range(20):
        t_s = k / RATE_HZ
        detection = _detection(t_s, -0.5 + 0.4 * t_s, 0.45, rng, **size)
        point = {
            "suction_x_m": detection.x_m - 0.03,
            "suction_y_m": detection.y_m + 0.01,
            "suction_radius_m": 0.024,
            "suction_tilt_rad": 0.4 + rng.normal(0.0, 0.02),
        }
        tracker.update(t_s, [dataclasses.replace(detection, **point)], (0.4, 0.0))
        plain.update(t_s, [detection], (0.4, 0.0))
    (track,) = tracker.predict_to(1.0)
    assert track.suction_offset_m == pytest.approx((-0.03, 0.01), abs=1e-9)
    assert track.suction_radius_m == pytest.approx(0.024)
    (other,) = plain.predict_to(1.0)
    assert all(math.isnan(v) for v in (*other.suction_offset_m, other.suction_radius_m))
    assert other.position_m == track.position_m  # the point changes nothing else


def test_the_suction_points_depth_below_the_top_reaches_the_track() -> None:
    """A tipped piece on a 4 cm high neighbour, 3 cm tall: its top is at 7 cm, and the camera
    reports the suction point 12 mm lower, on the sloping upturned face, tilted 0.4 rad. The
    track keeps that depth and tilt (smoothed); without an underside height it has no depth."""
    rng = np.random.default_rng(9)
    tracker = Tracker(TrackingConfig(), classes=CLASSES)
    blind = Tracker(TrackingConfig(), classes=CLASSES)
    for k in range(20):
        t_s = k / RATE_HZ
        detection = _detection(t_s, -0.5 + 0.4 * t_s, 0.45, rng)
        point = {
            "suction_x_m": detection.x_m,
            "suction_y_m": detection.y_m,
            "suction_z_m": 0.07 - 0.012 + rng.normal(0.0, 0.001),
            "suction_radius_m": 0.024,
            "suction_tilt_rad": 0.4 + rng.normal(0.0, 0.02),
        }
        tracker.update(t_s, [dataclasses.replace(detection, base_z_m=0.04, **point)], (0.4, 0.0))
        blind.update(t_s, [dataclasses.replace(detection, **point)], (0.4, 0.0))
    (track,) = tracker.predict_to(1.0)
    assert track.suction_below_top_m == pytest.approx(0.012, abs=0.001)
    assert track.suction_tilt_rad == pytest.approx(0.4, abs=0.02)
    (other,) = blind.predict_to(1.0)
    assert math.isnan(other.suction_below_top_m)
    assert other.suction_tilt_rad == pytest.approx(0.4, abs=0.02)


def test_identities_kept_through_crossing() -> None:
    rng = np.random.default_rng(3)
    tracker = Tracker(TrackingConfig(), classes=CLASSES)
    ids_before: dict[str, int] = {}
    ids_after: dict[str, int] = {}
    for k in range(90):
        t_s = k / RATE_HZ
        # Two objects cross at t = 1.5 s: one drifts towards +y, the other towards -y.
        a = (-0.6 + 0.4 * t_s, 0.35 + 0.1 * t_s)
        b = (-0.6 + 0.4 * t_s, 0.65 - 0.1 * t_s)
        dets = [_detection(t_s, *a, rng, class_name="brick"), _detection(t_s, *b, rng)]
        tracker.update(t_s, dets[:: 1 if k % 2 else -1], (0.4, 0.0))
        tracks = tracker.predict_to(t_s)
        if len(tracks) == 2:
            by_y = sorted(tracks, key=lambda tr: tr.position_m[1])
            target = ids_before if t_s < 1.3 else ids_after if t_s > 1.7 else {}
            target["low_start" if t_s < 1.3 else "high_end"] = by_y[0 if t_s < 1.3 else 1].track_id
    assert len(tracker) == 2
    # The object that started low (moving up) ends high, with the same identity and class.
    assert ids_before["low_start"] == ids_after["high_end"]
    final = {tr.track_id: tr for tr in tracker.predict_to(3.0)}
    assert final[ids_before["low_start"]].class_name == "brick"


def test_birth_and_death() -> None:
    rng = np.random.default_rng(0)
    config = TrackingConfig(confirm_hits=3, max_coast_s=0.2)
    tracker = Tracker(config, classes=CLASSES)
    for k in range(2):
        tracker.update(k / RATE_HZ, [_detection(k / RATE_HZ, 0.0, 0.5, rng)], (0.0, 0.0))
    assert tracker.predict_to(0.1) == ()
    assert len(tracker.predict_to(0.1, confirmed_only=False)) == 1
    tracker.update(2 / RATE_HZ, [_detection(2 / RATE_HZ, 0.0, 0.5, rng)], (0.0, 0.0))
    assert len(tracker.predict_to(0.1)) == 1
    tracker.update(0.5, [], (0.0, 0.0))
    assert len(tracker) == 0


def test_bad_detections_are_counted_and_good_ones_kept() -> None:
    rng = np.random.default_rng(1)
    tracker = Tracker(TrackingConfig(confirm_hits=1), classes=CLASSES)
    good = _detection(0.1, 0.0, 0.5, rng)
    bad = [
        _detection(0.1, math.nan, 0.5, rng),
        _detection(0.1, 0.2, 0.5, rng, length_m=math.inf),
        _detection(0.1, 0.3, 0.5, rng, class_name="glass"),
        _detection(0.05, 0.4, 0.5, rng),
    ]
    tracker.update(0.1, [*bad, good], (0.4, 0.0))
    tracker.update(0.05, [_detection(0.05, 0.0, 0.5, rng)], (0.4, 0.0))
    tracker.update(0.1, [_detection(0.1, 0.0, 0.5, rng)], (0.4, 0.0))
    rejected = tracker.rejected
    assert rejected["non_finite"] == 2
    assert rejected["unknown_class"] == 1
    assert rejected["out_of_order"] == 3
    # the log line names the latest one: why, what and where
    assert tracker.last_rejection.startswith("out_of_order: wood (0.90) at (")
    assert "150 x 50 x 30 mm, stamp 0.100 s" in tracker.last_rejection
    (track,) = tracker.predict_to(0.1)
    assert track.position_m[0] == pytest.approx(good.x_m)


# -- the tracker against a plain reference --------------------------------------------------
class _ReferenceTrack:
    """One track of :class:`_ReferenceTracker`: the textbook 4x4 constant-velocity filter."""

    def __init__(
        self,
        track_id: int,
        det: Detection,
        belt_velocity_mps: tuple[float, float],
        cfg: TrackingConfig,
    ) -> None:
        self.track_id = track_id
        self.x = np.array([det.x_m, det.y_m, *belt_velocity_mps], dtype=float)
        r, v = cfg.position_std_m**2, cfg.initial_velocity_std_mps**2
        self.p = np.diag([r, r, v, v])
        self.stamp_s = det.stamp_s
        self.last_update_s = det.stamp_s
        self.hits = 1
        self.confirmed = cfg.confirm_hits <= 1
        self.votes = {det.class_name: max(det.confidence, 1e-6)}
        self.yaw_vec = np.array([math.cos(2 * det.yaw_rad), math.sin(2 * det.yaw_rad)])
        self.size_m = np.array([det.length_m, det.width_m, det.height_m])
        self.base_z_m = det.base_z_m


def _transition(dt_s: float, accel_var: float) -> tuple[np.ndarray, np.ndarray]:
    """``F`` and ``Q = G G^T accel_var`` of the constant-velocity model, state (x, y, vx, vy)."""
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt_s
    g = np.array([[0.5 * dt_s**2, 0.0], [0.0, 0.5 * dt_s**2], [dt_s, 0.0], [0.0, dt_s]])
    return f, g @ g.T * accel_var


_H = np.eye(2, 4)


class _ReferenceTracker:
    """The tracker's documented algorithm written plainly: matrices, loops, the full cost
    matrix for the Hungarian method."""

    def __init__(self, cfg: TrackingConfig, classes: tuple[str, ...]) -> None:
        self.cfg = cfg
        self.classes = classes
        self.tracks: list[_ReferenceTrack] = []
        self.next_id = 1
        self.last_stamp_s = -math.inf
        self.rejected = dict.fromkeys(REJECT_REASONS, 0)

    def _accepted(self, detections: Sequence[Detection], stamp_s: float) -> list[Detection]:
        accepted = []
        for d in detections:
            numbers = (d.stamp_s, d.confidence, d.x_m, d.y_m, d.yaw_rad)
            if not all(map(math.isfinite, (*numbers, d.length_m, d.width_m, d.height_m))):
                self.rejected["non_finite"] += 1
            elif d.class_name not in self.classes:
                self.rejected["unknown_class"] += 1
            elif d.stamp_s != stamp_s or d.stamp_s <= self.last_stamp_s:
                self.rejected["out_of_order"] += 1
            elif d.confidence < self.cfg.min_confidence:
                self.rejected["low_confidence"] += 1
            elif min(d.length_m, d.width_m, d.height_m) <= 0.0:
                self.rejected["bad_size"] += 1
            else:
                turn = d.width_m > d.length_m
                accepted.append(
                    Detection(
                        stamp_s=d.stamp_s,
                        class_name=d.class_name,
                        confidence=d.confidence,
                        x_m=d.x_m,
                        y_m=d.y_m,
                        yaw_rad=wrap_half_turn(d.yaw_rad + (math.pi / 2 if turn else 0.0)),
                        length_m=max(d.length_m, d.width_m),
                        width_m=min(d.length_m, d.width_m),
                        height_m=d.height_m,
                    )
                )
        return accepted

    def update(
        self, stamp_s: float, detections: Sequence[Detection], belt: tuple[float, float]
    ) -> None:
        cfg = self.cfg
        accepted = self._accepted(detections, stamp_s)
        if not stamp_s > self.last_stamp_s:
            reason = "out_of_order" if math.isfinite(stamp_s) else "non_finite"
            self.rejected[reason] += len(accepted)
            return
        self.last_stamp_s = stamp_s
        for tr in self.tracks:
            f, q = _transition(stamp_s - tr.stamp_s, cfg.process_accel_std_mps2**2)
            tr.x, tr.p, tr.stamp_s = f @ tr.x, f @ tr.p @ f.T + q, stamp_s
        r = np.eye(2) * cfg.position_std_m**2
        cost = np.full((len(self.tracks), len(accepted)), 1e12)
        z = np.array([[d.x_m, d.y_m] for d in accepted]).reshape(-1, 2)
        for i, tr in enumerate(self.tracks):
            nu = z - _H @ tr.x
            d_sq = np.einsum("ji,ik,jk->j", nu, np.linalg.inv(_H @ tr.p @ _H.T + r), nu)
            gated = (d_sq <= cfg.gate_mahalanobis_sq) | (np.hypot(*nu.T) <= cfg.gate_min_m)
            cost[i, gated] = d_sq[gated]
        matched = set()
        for i, j in zip(*linear_sum_assignment(cost), strict=True):
            if cost[i, j] >= 1e12:
                continue
            tr, d = self.tracks[i], accepted[j]
            matched.add(j)
            s = _H @ tr.p @ _H.T + r
            k = tr.p @ _H.T @ np.linalg.inv(s)
            tr.x = tr.x + k @ (np.array([d.x_m, d.y_m]) - _H @ tr.x)
            i_kh = np.eye(4) - k @ _H
            tr.p = i_kh @ tr.p @ i_kh.T + k @ r @ k.T
            tr.last_update_s = stamp_s
            tr.hits += 1
            tr.confirmed = tr.confirmed or tr.hits >= cfg.confirm_hits
            tr.votes[d.class_name] = tr.votes.get(d.class_name, 0.0) + max(d.confidence, 1e-6)
            a = cfg.smoothing
            yaw_vec = np.array([math.cos(2 * d.yaw_rad), math.sin(2 * d.yaw_rad)])
            tr.yaw_vec = (1 - a) * tr.yaw_vec + a * yaw_vec
            tr.size_m = (1 - a) * tr.size_m + a * np.array([d.length_m, d.width_m, d.height_m])
        for j, d in enumerate(accepted):
            if j not in matched:
                self.tracks.append(_ReferenceTrack(self.next_id, d, belt, cfg))
                self.next_id += 1
        self.tracks = [tr for tr in self.tracks if stamp_s - tr.last_update_s <= cfg.max_coast_s]

    def predict_to(self, t_s: float, *, confirmed_only: bool = True) -> list[dict[str, Any]]:
        out = []
        for tr in self.tracks:
            if confirmed_only and not tr.confirmed:
                continue
            x, p = tr.x, tr.p
            if t_s > tr.stamp_s:
                f, q = _transition(t_s - tr.stamp_s, self.cfg.process_accel_std_mps2**2)
                x, p = f @ x, f @ p @ f.T + q
            class_name = max(tr.votes, key=lambda c: tr.votes[c])
            out.append(
                {
                    "track_id": tr.track_id,
                    "stamp_s": max(t_s, tr.stamp_s),
                    "class_name": class_name,
                    "class_confidence": tr.votes[class_name] / sum(tr.votes.values()),
                    "position_m": (x[0], x[1]),
                    "velocity_mps": (x[2], x[3]),
                    "position_std_m": math.sqrt(np.linalg.eigvalsh(p[:2, :2])[-1]),
                    "yaw_rad": wrap_half_turn(0.5 * math.atan2(tr.yaw_vec[1], tr.yaw_vec[0])),
                    "length_m": tr.size_m[0],
                    "width_m": tr.size_m[1],
                    "height_m": tr.size_m[2],
                    "hits": tr.hits,
                    "confirmed": tr.confirmed,
                    "last_update_s": tr.last_update_s,
                    "base_z_m": tr.base_z_m,
                }
            )
        return out


def _assert_same_tracks(tracks: tuple[Track, ...], expected: list[dict[str, Any]]) -> None:
    """Same tracks, same discrete fields, estimates equal to float rounding (1e-9 relative;
    below 1e-12 in the field's unit, absolute: a coordinate or velocity crossing zero)."""
    assert [t.track_id for t in tracks] == [e["track_id"] for e in expected]
    for track, want in zip(tracks, expected, strict=True):
        for name, value in want.items():
            got = getattr(track, name)
            if name in ("track_id", "class_name", "hits", "confirmed", "last_update_s"):
                assert got == value, (track.track_id, name)
            elif name == "base_z_m" and math.isnan(value):
                assert math.isnan(got), (track.track_id, name)
            else:
                pairs = zip(got, value, strict=True) if isinstance(got, tuple) else [(got, value)]
                for g, v in pairs:
                    ok = math.isclose(g, v, rel_tol=1e-9, abs_tol=1e-12)
                    assert ok, (track.track_id, name, g, v)


def _hostile(load: TrackerLoad) -> Iterator[tuple[float, CameraFrame | None]]:
    """The load's events, with now and then a frame delivered twice (out of order) and frames
    carrying a non-finite, an unknown-class, a mis-stamped and a flat detection."""
    previous: CameraFrame | None = None
    for k, (t_s, event) in enumerate(tracker_stream(load)):
        frame = event
        if frame is not None and k % 11 == 0:
            good = frame.detections[0] if frame.detections else None
            if good is not None:
                bad = (
                    dataclasses.replace(good, x_m=math.nan),
                    dataclasses.replace(good, class_name="glass"),
                    dataclasses.replace(good, stamp_s=good.stamp_s - 0.01),
                    dataclasses.replace(good, height_m=0.0),
                )
                frame = CameraFrame(stamp_s=frame.stamp_s, detections=(*frame.detections, *bad))
        if frame is not None and previous is not None and k % 29 == 0:
            yield t_s, previous
        if frame is not None:
            previous = frame
        yield t_s, frame


@pytest.mark.parametrize(
    ("cfg", "load"),
    [
        (
            TrackingConfig(),
            TrackerLoad(
                objects=30,
                seed=11,
                duration_s=6.0,  # 20 s gave 14 times the births and 10 times the calls asked
                drop_rate=0.1,
                misclassification_rate=0.05,
                clutter_per_frame=1.0,
                near_clutter_rate=0.1,
                blackout_rate=0.005,
            ),
        ),
        (
            TrackingConfig(confirm_hits=1, min_confidence=0.5, gate_min_m=0.0, max_coast_s=0.1),
            TrackerLoad(
                objects=20,
                seed=12,
                duration_s=10.0,
                drift_std_mps=0.05,
                drop_rate=0.2,
                misclassification_rate=0.2,
                clutter_per_frame=2.0,
                near_clutter_rate=0.3,
                blackout_rate=0.01,
            ),
        ),
    ],
)
def test_matches_plain_kalman_reference(
    cfg: TrackingConfig, load: TrackerLoad, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The closed-form filter, the direct matching of lone pairs and the cached track fields
    # give the same tracks as the 4x4 filter and the whole-matrix Hungarian method, frame by
    # frame and at every control update, on a stream with clutter, misses, class noise,
    # blackouts and bad detections.
    hungarian_calls = 0

    solve = tracking.min_cost_assignment

    def counted(cost: list[list[float]]) -> list[tuple[int, int]]:
        nonlocal hungarian_calls
        hungarian_calls += 1
        return solve(cost)

    monkeypatch.setattr(tracking, "min_cost_assignment", counted)
    tracker = Tracker(cfg, classes=load.classes)
    reference = _ReferenceTracker(cfg, load.classes)
    belt = (load.belt_speed_mps, 0.0)
    ids: set[int] = set()
    voted_out = 0
    for t_s, frame in _hostile(load):
        if frame is None:
            _assert_same_tracks(tracker.predict_to(t_s), reference.predict_to(t_s))
            continue
        tracker.update(frame.stamp_s, frame.detections, belt)
        reference.update(frame.stamp_s, frame.detections, belt)
        assert tracker.rejected == reference.rejected
        assert len(tracker) == len(reference.tracks)
        for t in (frame.stamp_s - 0.01, frame.stamp_s, t_s):
            every = tracker.predict_to(t, confirmed_only=False)
            _assert_same_tracks(every, reference.predict_to(t, confirmed_only=False))
        ids.update(t.track_id for t in every)
        voted_out += sum(t.class_confidence < 0.8 for t in every)
    # The stream exercised what it is meant to: births and deaths well beyond the objects in
    # view, contested gates, split class votes, every reject reason but low confidence.
    assert len(ids) > 3 * load.objects
    assert hungarian_calls > 50
    assert voted_out > 50
    assert all(tracker.rejected[r] > 0 for r in REJECT_REASONS if r != "low_confidence")


@pytest.mark.parametrize("shape", [(1, 1), (2, 2), (3, 5), (5, 3), (6, 6), (4, 9)])
def test_min_cost_assignment_is_the_optimum(shape: tuple[int, int]) -> None:
    """The tracker's own Hungarian method gives scipy's optimum (total cost and pairs) on
    random blocks, gated-out entries (``1e12``) included."""
    rng = np.random.default_rng(sum(shape))
    for _ in range(200):
        cost = rng.random(shape) * 9.0
        cost[rng.random(shape) < 0.4] = 1e12
        rows, cols = linear_sum_assignment(cost)
        pairs = tracking.min_cost_assignment(cost.tolist())
        assert len(pairs) == min(shape)
        assert len({i for i, _ in pairs}) == len({j for _, j in pairs}) == len(pairs)
        total = sum(cost[i, j] for i, j in pairs)
        assert total == pytest.approx(cost[rows, cols].sum(), rel=1e-12)
        # the gated pairs (what the tracker keeps) are the same; gated-out ones may tie
        expected = [(i, j) for i, j in zip(rows.tolist(), cols.tolist(), strict=True)]
        assert [p for p in pairs if cost[p] < 1e12] == [p for p in expected if cost[p] < 1e12]


def test_a_snapshot_is_the_track_its_constructor_gives() -> None:
    """Tracks are built without the dataclass's ``__init__`` (for speed): they must equal,
    hash, print and be replaced as those built through it."""
    rng = np.random.default_rng(5)
    tracker = Tracker(TrackingConfig(), classes=CLASSES)
    for k in range(6):
        t_s = k / RATE_HZ
        tracker.update(t_s, [_detection(t_s, -0.5 + 0.4 * t_s, 0.45, rng)], (0.4, 0.0))
    (track,) = tracker.predict_to(0.3)
    fields = {f.name: getattr(track, f.name) for f in dataclasses.fields(Track)}
    built = Track(**fields)
    assert track == built
    assert hash(track) == hash(built)
    assert repr(track) == repr(built)
    assert dataclasses.replace(track, hits=99).hits == 99
    with pytest.raises(dataclasses.FrozenInstanceError):
        track.hits = 1  # type: ignore[misc]
