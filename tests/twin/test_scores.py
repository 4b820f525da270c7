"""Scores from events: fates, rates, throughput."""

from __future__ import annotations

import pytest

from interfaces.events import Event, EventType
from twin.scores import compute_scores


def _e(kind: EventType, oid: int, t: float = 0.0, **data: object) -> Event:
    return Event(time_s=t, step=0, type=kind, object_id=oid, data=dict(data))


def test_fates_and_rates() -> None:
    events = [_e(EventType.SPAWNED, i) for i in range(1, 6)] + [
        _e(EventType.PICK_SUCCESS, 1),
        _e(EventType.PLACED_IN_BIN, 1, bin="wood", correct=True),
        _e(EventType.PICK_SUCCESS, 2),
        _e(EventType.PLACED_IN_BIN, 2, bin="wood", correct=False),
        _e(EventType.MISSED, 3),
        _e(EventType.FELL_OFF, 3),
        _e(EventType.PICK_SUCCESS, 4),
        _e(EventType.PICK_DROPPED, 4),
        _e(EventType.UNINTENDED_CONTACT, 5),
    ]
    s = compute_scores(events, duration_s=120.0)
    assert (s.spawned, s.processed, s.picked, s.missed, s.lost) == (5, 4, 2, 1, 1)
    assert s.success_rate == pytest.approx(0.5)
    assert s.miss_rate == pytest.approx(0.25)
    assert s.throughput_per_min == pytest.approx(1.0)
    assert s.correct_bin_ratio == pytest.approx(0.5)
    assert s.time_per_object_s == pytest.approx(60.0)
    assert s.unintended_contacts == 1


def test_repick_after_drop_counts_as_picked_and_json_round_trips() -> None:
    events = [
        _e(EventType.PICK_SUCCESS, 1),
        _e(EventType.PICK_DROPPED, 1),
        _e(EventType.PICK_SUCCESS, 1),
    ]
    assert compute_scores(events, 60.0).picked == 1
    assert all(Event.from_json(e.to_json()) == e for e in events)


def test_no_events_gives_zero_rates_not_nan() -> None:
    s = compute_scores([], 0.0)
    assert (s.success_rate, s.miss_rate, s.throughput_per_min) == (0.0, 0.0, 0.0)
