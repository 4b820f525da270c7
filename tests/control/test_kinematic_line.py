"""The pure closed-loop line (control/kinematic_line.py): two stations share one stream."""

from __future__ import annotations

from control.config import ControllerConfig
from control.kinematic_line import StreamSpec, random_stream, run_line
from interfaces.cell import load_cell


def test_two_stations_share_the_stream_without_taking_the_same_object() -> None:
    cell = load_cell("two_pandas")
    configs = [ControllerConfig(cell=cell, station_name=s.name) for s in cell.stations]
    speed, duration = 0.4, 20.0
    objects = random_stream(
        StreamSpec(rate_per_s=1.5, narrow_m=(0.03, 0.06)),
        cell=cell,
        speed_mps=speed,
        duration_s=duration,
        seed=3,
    )
    result = run_line(configs, objects, speed_mps=speed, duration_s=duration, seed=3)
    # both stations place objects; the downstream one left what the upstream one claimed
    assert result.placed_by_station["upstream"] > 0
    assert result.placed_by_station["downstream"] > 0
    assert result.stats["downstream"].untargeted.get("claimed_by_other", 0) > 0
    assert result.placed_wrong == 0
    # no station went for an object the other one had taken (it would have closed on nothing)
    for stats in result.stats.values():
        assert stats.aborted.get("grip_missed", 0) == 0
    assert 0.0 < result.recovery <= 1.0
