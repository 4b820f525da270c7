"""``cdw-twin bench line``: a very short run prints its figures as JSON, of the right shape."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest
import yaml

from experiments.bench_line import (
    LINE_SCENARIO,
    BenchLineError,
    configure,
    cut_cell,
    run,
    station_counts,
)


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    configure(parser)
    return parser.parse_args(list(argv))


def test_a_two_second_episode_of_one_station_prints_positive_figures(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert run(_args("--duration", "2", "--stations", "1", "--json")) == 0
    result = json.loads(capsys.readouterr().out)
    row = result["stations"]["1"]
    for key in ("real_time_factor", "cpu_s_per_sim_s", "cpu_s", "wall_s", "episodes_per_core_hour"):
        assert row[key] > 0.0, key
    assert row["cpu_s_per_sim_s"] == pytest.approx(row["cpu_s"] / 2.0, abs=0.01)
    assert list(row["tick_us"]) == ["s1"]
    tick = row["tick_us"]["s1"]
    assert 0.0 < tick["mean"] <= tick["max"]
    assert 0.0 < tick["p95"] <= tick["max"]
    assert result["cpu_s_per_added_station"] is None  # one count: no slope
    assert result["duration_s"] == 2.0
    assert result["transport"] == "inproc"
    assert "vs" not in result


def test_the_cut_cell_keeps_the_first_stations_in_order(tmp_path: Path) -> None:
    path = cut_cell(LINE_SCENARIO, 3, tmp_path)
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    assert [s["name"] for s in data["stations"]] == ["s1", "s2", "s3"]
    assert data["name"] == "line_first3"
    with pytest.raises(BenchLineError, match="has 8 station"):
        cut_cell(LINE_SCENARIO, 9, tmp_path)


def test_station_counts_are_positive_integers() -> None:
    assert station_counts("1,2,4,8") == (1, 2, 4, 8)
    for bad in ("", "0", "1,x", "-2"):
        with pytest.raises(BenchLineError, match="--stations"):
            station_counts(bad)


def test_a_vs_tree_that_is_no_checkout_is_refused(tmp_path: Path) -> None:
    with pytest.raises(BenchLineError, match="not a cdw-twin checkout"):
        run(_args("--duration", "1", "--stations", "1", "--vs", str(tmp_path)))
