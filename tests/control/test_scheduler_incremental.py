"""The scheduler's cheap tests before the intercept search give the reasons the search would."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from control.config import ControllerConfig
from control.scheduler import _timing_reason, descend_after_s, schedule
from control.tracking import Track


def _track(track_id: int, x: float, vx: float) -> Track:
    """A confirmed brick on the belt's centre line at ``x`` moving at ``vx``."""
    return Track(
        track_id=track_id,
        stamp_s=0.0,
        class_name="brick",
        class_confidence=1.0,
        position_m=(x, 0.5),
        velocity_mps=(vx, 0.0),
        position_std_m=0.001,
        yaw_rad=0.0,
        length_m=0.12,
        width_m=0.05,
        height_m=0.04,
        hits=10,
        confirmed=True,
        last_update_s=0.0,
    )


def test_a_track_past_the_window_is_too_late_without_an_intercept_search() -> None:
    config = ControllerConfig()
    x_max = config.pick_window_x_m[1]
    asked: list[int] = []

    def estimate(track: Track) -> float:
        asked.append(track.track_id)
        return 0.5

    x_min = config.pick_window_x_m[0]
    past = _track(1, x_max + 0.01, 0.2)
    inside = _track(2, x_min + 0.05, 0.2)
    result = schedule(
        [past, inside],
        now_s=0.0,
        tcp_position_m=(0.0, 0.45, 0.3),
        config=config,
        approach_estimate=estimate,
    )
    assert {u.track_id: u.reason for u in result.untargeted}.get(1) == "too_late"
    assert asked == [2]  # only the track in the window was searched


def test_the_skipped_search_would_have_said_too_late_whatever_it_found() -> None:
    """Over tracks all along the window and beyond, moving either way, and every intercept time
    the search could return (0 s up, or none), the reason :func:`schedule` gives equals the
    reason of the full timing check with that intercept time."""
    config = ControllerConfig()
    x_min, x_max = config.pick_window_x_m
    held_m = descend_after_s(config) + config.timing.held_after_s
    rng = np.random.default_rng(7)
    xs = [*np.linspace(x_min - 0.5, x_max + 0.5, 41), x_max, x_max - 0.4 * held_m]
    approaches = [0.0, 1e-9, 0.05, 0.3, 1.0, 4.0, math.inf, *rng.uniform(0.0, 3.0, 5)]
    compared = 0
    for i, x in enumerate(xs):
        for vx in (0.4, 0.2, -0.1, 0.0):
            track = _track(i, float(x), vx)
            for approach_s in approaches:

                def estimate(_track: Track, a: float = float(approach_s)) -> float:
                    return a

                result = schedule(
                    [track],
                    now_s=0.0,
                    tcp_position_m=(0.0, 0.45, 0.3),
                    config=config,
                    approach_estimate=estimate,
                )
                reason = result.untargeted[0].reason if result.untargeted else None
                expected = _timing_reason(track, 0.0, float(approach_s), config, others=[track])
                assert reason == expected, (x, vx, approach_s)
                compared += 1
    assert compared == len(xs) * 4 * len(approaches)


def test_a_track_stamped_earlier_is_judged_where_it_is_predicted() -> None:
    config = ControllerConfig()
    x_max = config.pick_window_x_m[1]
    # seen 1 s ago 0.3 m before the exit at 0.4 m/s: 0.1 m past it now
    old = replace(_track(1, x_max - 0.3, 0.4), stamp_s=-1.0)
    asked: list[int] = []

    def estimate(track: Track) -> float:
        asked.append(track.track_id)
        return 0.2

    result = schedule(
        [old], now_s=0.0, tcp_position_m=(0.0, 0.45, 0.3), config=config, approach_estimate=estimate
    )
    assert [u.reason for u in result.untargeted] == ["too_late"]
    assert asked == []
