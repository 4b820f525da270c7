"""The telemetry recorder: stamp matching, ring eviction, percentiles, step rate, belt sampling."""

from __future__ import annotations

import json

import numpy as np
import pytest

from twin.telemetry import TelemetryRecorder, stamp_key

DT_S = 1.0 / 240.0


def test_rtt_is_command_arrival_minus_publish_time_of_the_same_stamp() -> None:
    rec = TelemetryRecorder()
    for k in range(10):
        rec.on_state_published(k * DT_S, 100.0 + k * 0.01)
    assert rec.on_command(3 * DT_S, 100.0 + 0.03 + 0.002) == pytest.approx(2.0)
    assert rec.on_command(7 * DT_S, 100.0 + 0.07 + 0.0005) == pytest.approx(0.5)
    assert rec.rtt_sim_s == [3 * DT_S, 7 * DT_S]
    assert rec.rtt_wall_s == pytest.approx([0.032, 0.0705])


def test_stamps_survive_the_ros_time_round_trip() -> None:
    """The controller echoes sec + nanosec; the key must equal the one of the float time."""
    for k in (0, 1, 239, 240, 12_345, 1_000_001):
        t = k * DT_S
        sec = int(t)
        nanosec = round((t - sec) * 1e9) % 1_000_000_000
        assert stamp_key(sec + 1e-9 * nanosec) == stamp_key(t)


def test_unknown_and_evicted_stamps_are_counted_not_measured() -> None:
    rec = TelemetryRecorder(ring_size=4)
    for k in range(10):
        rec.on_state_published(k * DT_S, float(k))
    assert rec.on_command(99 * DT_S, 20.0) is None
    assert rec.on_command(2 * DT_S, 20.0) is None
    assert rec.on_command(6 * DT_S, 6.5) == pytest.approx(500.0)
    assert rec.unmatched_commands == 2
    assert rec.latency().samples == 1
    assert rec.latency().unmatched_commands == 2


def test_ring_holds_exactly_the_newest_stamps() -> None:
    rec = TelemetryRecorder(ring_size=8)
    for k in range(100):
        rec.on_state_published(k * DT_S, float(k))
    matched = [k for k in range(100) if rec.on_command(k * DT_S, 200.0) is not None]
    assert matched == list(range(92, 100))


def test_summary_percentiles_match_numpy() -> None:
    rng = np.random.default_rng(1)
    rtts = rng.lognormal(0.0, 0.7, 500)
    rec = TelemetryRecorder(ring_size=1000)
    for k, rtt in enumerate(rtts):
        rec.on_state_published(k * DT_S, k * 0.01)
        rec.on_command(k * DT_S, k * 0.01 + rtt * 1e-3)
    latency = rec.latency()
    assert latency.samples == 500
    assert latency.rtt_ms_p50 == pytest.approx(np.percentile(rtts, 50), rel=1e-9)
    assert latency.rtt_ms_p99 == pytest.approx(np.percentile(rtts, 99), rel=1e-9)
    assert latency.rtt_ms_mean == pytest.approx(rtts.mean(), rel=1e-9)
    assert latency.rtt_ms_p50 <= latency.rtt_ms_p99


def test_empty_record_has_empty_summary() -> None:
    rec = TelemetryRecorder()
    assert rec.latency().samples == 0
    assert rec.latency().rtt_ms_p50 is None
    assert rec.step_rate_hz_mean() is None
    data = json.loads(rec.to_json())
    assert data["summary"]["latency"]["samples"] == 0
    assert data["rtt"] == {"wall_s": [], "sim_s": [], "rtt_ms": []}


def test_step_rate_rows_per_wall_second() -> None:
    rec = TelemetryRecorder()
    # 480 steps per wall second, each 1/240 s of sim: rtf 2
    for k in range(480 * 3 + 1):
        rec.on_step(k * DT_S, 10.0 + k / 480.0)
    assert len(rec.rate_wall_s) == 3
    assert rec.rate_steps_per_s == pytest.approx([480.0] * 3)
    assert rec.rate_rtf == pytest.approx([2.0] * 3)
    assert rec.rate_wall_s == pytest.approx([1.0, 2.0, 3.0])
    assert rec.step_rate_hz_mean() == pytest.approx(480.0)


def test_an_episode_shorter_than_a_window_still_has_its_step_rate() -> None:
    rec = TelemetryRecorder()
    # 0.6 wall seconds at 400 steps per second, each 1/240 s of sim: rtf 400/240
    for k in range(241):
        rec.on_step(k * DT_S, 5.0 + k / 400.0)
    assert rec.rate_wall_s == []
    assert rec.step_rate_hz_mean() == pytest.approx(400.0)
    rows = json.loads(rec.to_json())["step_rate"]
    assert rows["wall_s"] == pytest.approx([0.6])
    assert rows["rtf"] == pytest.approx([400.0 / 240.0], rel=1e-4)


def test_belt_is_sampled_every_period_of_sim_time() -> None:
    rec = TelemetryRecorder(belt_period_s=0.1)
    for k in range(240 * 2):
        if k % 4 == 0:
            rec.on_belt(k * DT_S, 0.4, 0.39)
    assert len(rec.belt_sim_s) == 20
    assert np.diff(rec.belt_sim_s) == pytest.approx(np.full(19, 0.1), abs=4 * DT_S)
    assert set(rec.belt_setpoint_mps) == {0.4}


def test_json_has_the_documented_arrays_of_equal_length() -> None:
    rec = TelemetryRecorder()
    for k in range(600):
        wall = k / 300.0
        rec.on_step(k * DT_S, wall)
        rec.on_state_published(k * DT_S, wall)
        if k % 4 == 0:
            rec.on_belt(k * DT_S, 0.3, 0.29)
            rec.on_command(k * DT_S, wall + 0.001)
    data = json.loads(rec.to_json())
    for key, columns in {
        "rtt": ("wall_s", "sim_s", "rtt_ms"),
        "step_rate": ("wall_s", "steps_per_s", "rtf"),
        "belt": ("sim_s", "setpoint_mps", "speed_mps"),
    }.items():
        lengths = {len(data[key][c]) for c in columns}
        assert len(lengths) == 1
        assert lengths != {0}
    assert data["summary"]["latency"]["rtt_ms_p50"] == pytest.approx(1.0, abs=1e-3)
