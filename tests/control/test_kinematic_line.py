"""The pure closed-loop line (control/kinematic_line.py): two stations share one stream."""

from __future__ import annotations

from pathlib import Path

from control.config import ControllerConfig, load_config
from control.kinematic_line import StreamSpec, random_stream, run_line
from interfaces.cell import load_cell

CONFIG_DIR = Path(__file__).parents[2] / "control" / "config"


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


def test_the_lines_cups_pass_above_every_piece_on_their_way_to_a_target() -> None:
    """The line's suction stations meet each target with one joint-space move, whose TCP path
    is no straight line: ending 2 cm above the top, it came in lower than that on the way and
    ran the cup's stem into pieces (in the twin it pushed them, some off the belt). With the
    line's parameters no approach of the five cup stations runs into a piece at 0.6 m/s."""
    cell = load_cell("line")
    path = CONFIG_DIR / "line.yaml"
    cups = [s for s in cell.stations if "suction" in s.tool.name]
    configs = [load_config(path, cell=cell, station=s.name) for s in cups]
    speed, duration = 0.6, 30.0
    objects = random_stream(StreamSpec(), cell=cell, speed_mps=speed, duration_s=duration, seed=3)
    result = run_line(configs, objects, speed_mps=speed, duration_s=duration, seed=3)
    assert sum(result.placed_by_station.values()) > 30  # the stations picked all along
    assert result.approach_strikes == {s.name: 0 for s in cups}
