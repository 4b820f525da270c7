"""Kalman tracking: convergence on noisy trajectories, identities through crossings, rejects."""

from __future__ import annotations

import math

import numpy as np
import pytest

from control.config import TrackingConfig
from control.tracking import Detection, Tracker, wrap_half_turn

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
    (track,) = tracker.predict_to(0.1)
    assert track.position_m[0] == pytest.approx(good.x_m)
