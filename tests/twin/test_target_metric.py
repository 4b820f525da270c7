"""Tracking time to 4 mm against ground truth (pure, no simulator)."""

from __future__ import annotations

import math

import pytest

from twin.target_metric import TargetTracker

IDENTITY = (0.0, 0.0, 0.0, 1.0)
SPEED_MPS = 0.4
DT_S = 1.0 / 240.0


def _object_at(t_s: float) -> tuple[float, float, float]:
    return (-0.3 + SPEED_MPS * t_s, 0.5, 0.02)


def _run(tcp_of_t: object, *, estimate_error_m: float = 0.0, steps: int = 240) -> TargetTracker:
    tracker = TargetTracker()
    point = _object_at(0.0)
    announced = (point[0] + estimate_error_m, point[1], 0.03)  # a noisy estimate, 1 cm up
    tracker.announce(
        0.0, 7, announced, "approach", {3: (point, IDENTITY), 4: ((0.2, 0.5, 0.02), IDENTITY)}
    )
    for k in range(1, steps):
        t_s = k * DT_S
        tracker.update(
            t_s, tcp_of_t(t_s), lambda oid, t=t_s: (_object_at(t), IDENTITY) if oid == 3 else None
        )  # type: ignore[operator]
    tracker.finish(steps * DT_S)
    return tracker


def test_reference_is_the_true_axis_at_the_announced_height_not_the_estimate() -> None:
    """An estimate 3 mm off does not move the reference: a TCP on the true axis settles."""

    def on_axis_after_half_a_second(t_s: float) -> tuple[float, float, float]:
        x, y, _ = _object_at(t_s)
        return (x, y, 0.03) if t_s >= 0.5 else (x + 0.05, y, 0.2)

    result = _run(on_axis_after_half_a_second, estimate_error_m=0.003).results[0]
    assert result.object_id == 3
    assert result.time_to_threshold_s == pytest.approx(0.5, abs=DT_S)


def test_a_tcp_that_follows_the_estimate_carries_its_error() -> None:
    """Following a point 5 mm off the true axis never settles within 4 mm."""

    def on_estimate(t_s: float) -> tuple[float, float, float]:
        x, y, _ = _object_at(t_s)
        return (x + 0.005, y, 0.03)

    result = _run(on_estimate, estimate_error_m=0.005).results[0]
    assert result.time_to_threshold_s is None


def test_leaving_the_threshold_restarts_the_clock() -> None:
    def in_out_in(t_s: float) -> tuple[float, float, float]:
        x, y, _ = _object_at(t_s)
        away = 0.01 if 0.3 <= t_s < 0.4 else 0.0
        return (x, y + away, 0.03) if t_s >= 0.2 else (x, y, 0.3)

    result = _run(in_out_in).results[0]
    assert result.time_to_threshold_s == pytest.approx(0.4, abs=DT_S)


def test_no_object_near_the_announcement_starts_no_pursuit() -> None:
    tracker = TargetTracker(match_radius_m=0.05)
    tracker.announce(0.0, 1, (5.0, 5.0, 0.0), "approach", {3: (_object_at(0.0), IDENTITY)})
    assert not tracker.active
    tracker.announce(0.0, 1, _object_at(0.0), "carry", {3: (_object_at(0.0), IDENTITY)})
    assert not tracker.active
    assert math.isclose(tracker.threshold_m, 0.004)
