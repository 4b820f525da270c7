"""Sweep grids expand and validate; aggregation gives the textbook intervals (no ROS)."""

from __future__ import annotations

import csv
import dataclasses
import io
import math
from pathlib import Path

import pytest
import yaml

from experiments.stats import student_t_interval, wilson_interval
from experiments.sweep import prepare_sweep
from experiments.sweep_grid import Grid, expand
from experiments.sweep_pooling import (
    CI_METRICS,
    WILSON_RATES,
    CellPool,
    Interval,
    pool_line,
    pool_stations,
)
from experiments.sweep_summary import CellSummary, sweep_csv
from interfaces.errors import ConfigError
from interfaces.metrics import METRICS
from interfaces.run_records import EpisodeRow, FailedEpisode, row_from_data

SCENARIOS = Path(__file__).resolve().parents[2] / "experiments" / "scenarios"


def _typed(rows: list[dict]) -> list[EpisodeRow]:
    """Rows of ``episodes.json`` as the runner writes them, from their line (and station and
    class) blocks; ``{"failed": True}`` a failed episode."""
    base = {"seed": 1, "mode": "lockstep", "speed_mps": 0.4}
    return [
        FailedEpisode(episode=i, seed=1, mode="lockstep", reason="test")
        if row.get("failed")
        else row_from_data({"episode": i, **base, **row}, f"rows[{i}]")
        for i, row in enumerate(rows)
    ]


def _cell(rows: list[EpisodeRow], stations: tuple[str, ...] = ()) -> CellSummary:
    """A grid cell's summary of ``rows``."""
    return CellSummary(
        cell="c",
        folder="c",
        scenario="s",
        stations=stations,
        mode="lockstep",
        speed_mps=0.4,
        duration_s=5.0,
        overrides={},
        complete=True,
        failures=(),
        aggregate=CellPool.of(rows),
    )


def _row(placed: int, targeted: int, missed: int, processed: int, **extra: float) -> dict:
    return {
        "picked": placed,
        "placed_correct": placed,
        "sorted": placed,
        "targeted": targeted,
        "missed": missed,
        "processed": processed,
        "success_rate": placed / targeted if targeted else 0.0,
        "miss_rate": missed / processed if processed else 0.0,
        "tracking_time_4mm_mean_s": extra.get("tracking"),
        **{k: v for k, v in extra.items() if k != "tracking"},
    }


def test_student_t_interval_matches_the_textbook_value() -> None:
    mean, low, high = student_t_interval([1.0, 2.0, 3.0, 4.0])
    half = 3.182446305284263 * math.sqrt(5 / 3) / 2  # t(0.975, 3) * s / sqrt(n)
    assert mean == pytest.approx(2.5)
    assert (low, high) == pytest.approx((2.5 - half, 2.5 + half))
    assert student_t_interval([7.0]) == (7.0, None, None)
    assert student_t_interval([]) == (None, None, None)


def test_wilson_interval_matches_the_textbook_value_and_stays_in_unit_range() -> None:
    low, high = wilson_interval(8, 10)
    assert (low, high) == pytest.approx((0.4901624, 0.9433178), abs=1e-6)
    assert wilson_interval(0, 5)[0] == 0.0
    assert wilson_interval(5, 5)[1] == pytest.approx(1.0)
    assert wilson_interval(0, 0) == (None, None)


def test_aggregate_cell_pools_counts_and_skips_missing_values() -> None:
    rows = _typed(
        [
            _row(4, 5, 1, 6, tracking=1.0),
            _row(3, 5, 2, 6),
            _row(5, 5, 0, 6, tracking=3.0),
        ]
    )
    agg = pool_line(rows).to_data()
    assert agg["episodes"] == 3
    assert set(agg["metrics"]) == set(CI_METRICS)
    success = agg["metrics"]["success_rate"]
    assert success["mean"] == pytest.approx(0.8)
    assert success["ci95_low"] < 0.8 < success["ci95_high"]
    tracking = agg["metrics"]["tracking_time_4mm_mean_s"]
    assert tracking["n"] == 2
    assert tracking["mean"] == pytest.approx(2.0)
    wilson = agg["wilson"]["success_rate"]
    assert (wilson["successes"], wilson["trials"]) == (12, 15)
    assert (wilson["ci95_low"], wilson["ci95_high"]) == pytest.approx(wilson_interval(12, 15))
    miss = agg["wilson"]["miss_rate"]
    assert (miss["successes"], miss["trials"], miss["pooled"]) == (3, 18, pytest.approx(1 / 6))
    table = list(csv.DictReader(io.StringIO(sweep_csv([_cell(rows)]))))
    assert float(table[0]["success_rate_mean"]) == pytest.approx(0.8)
    assert float(table[0]["success_rate_wilson_low"]) == pytest.approx(wilson["ci95_low"])


def test_the_sweep_aggregates_every_line_metric_of_the_table_and_pools_every_rate() -> None:
    assert set(CI_METRICS) == {m.name for m in METRICS if "line" in m.scopes}
    assert {
        m.name: m.ratio_of for m in METRICS if m.kind == "rate" and "line" in m.scopes
    } == WILSON_RATES
    assert WILSON_RATES["success_rate"] == ("sorted", "targeted")
    assert WILSON_RATES["pick_success_rate"] == ("picked", "processed")


def _station_row(up: tuple[int, int], down: tuple[int, int]) -> dict:
    return {
        "picked": up[0] + down[0],
        "stations": {
            "upstream": {"picked": up[0], "processed": up[1], "real_time_factor": 9.0},
            "downstream": {"picked": down[0], "processed": down[1]},
        },
    }


def test_a_cell_of_two_stations_gets_intervals_and_csv_rows_per_station() -> None:
    rows = _typed([_station_row((2, 4), (1, 2)), _station_row((3, 4), (0, 2)), {"failed": True}])
    stations = {k: v.to_data() for k, v in pool_stations(rows).items()}
    assert list(stations) == ["upstream", "downstream"]
    up = stations["upstream"]
    assert up["episodes"] == 2
    assert up["metrics"]["picked"]["mean"] == pytest.approx(2.5)
    assert "real_time_factor" not in up["metrics"]  # a line metric only
    pooled = up["wilson"]["pick_success_rate"]
    assert (pooled["successes"], pooled["trials"], pooled["pooled"]) == (5, 8, 5 / 8)
    assert stations["downstream"]["wilson"]["pick_success_rate"]["pooled"] == pytest.approx(0.25)
    cell = _cell(rows)
    table = list(csv.DictReader(io.StringIO(sweep_csv([cell]))))
    assert [r["station"] for r in table] == ["", "upstream", "downstream"]
    assert float(table[0]["picked_mean"]) == pytest.approx(3.0)
    assert float(table[1]["picked_mean"]) == pytest.approx(2.5)
    assert table[1]["real_time_factor_mean"] == ""
    assert float(table[2]["pick_success_rate_pooled"]) == pytest.approx(0.25)
    # a cell of one station has its line row only, which also gives the per-station metrics
    upstream = cell.aggregate.stations["upstream"]
    one = dataclasses.replace(cell.aggregate, stations={"upstream": upstream})
    (line,) = csv.DictReader(io.StringIO(sweep_csv([dataclasses.replace(cell, aggregate=one)])))
    assert float(line["picked_mean"]) == pytest.approx(3.0)  # the line's own
    assert "unfit_share_mean" in line
    assert line["unfit_share_mean"] == ""  # these rows have no unfit share
    unfit = Interval(mean=0.04, ci95_low=0.01, ci95_high=0.07, n=2)
    upstream = dataclasses.replace(upstream, metrics={**upstream.metrics, "unfit_share": unfit})
    one = dataclasses.replace(cell.aggregate, stations={"upstream": upstream})
    (line,) = csv.DictReader(io.StringIO(sweep_csv([dataclasses.replace(cell, aggregate=one)])))
    assert float(line["unfit_share_mean"]) == pytest.approx(0.04)


def test_every_grid_cell_folder_keeps_its_resolved_cell_before_anything_runs(
    tmp_path: Path, builtin_meshes: Path
) -> None:
    from interfaces.cell import load_cell
    from twin.scenario import Scenario

    (tmp_path / "one.yaml").write_text("name: one\nduration_s: 2.0\n", encoding="utf-8")
    (tmp_path / "two.yaml").write_text(
        "name: two\ncell: two_pandas\nduration_s: 2.0\n", encoding="utf-8"
    )
    grid = tmp_path / "grid.yaml"
    grid.write_text(
        f"scenarios: [one.yaml, two.yaml]\nseeds: [3]\ndataset: {builtin_meshes}\n",
        encoding="utf-8",
    )
    runs = prepare_sweep(grid, tmp_path / "sweep")
    assert [r.options.stations for r in runs] == [("panda",), ("upstream", "downstream")]
    for run, shipped in zip(runs, ("default", "two_pandas"), strict=True):
        written = yaml.safe_load((run.folder / "scenario.yaml").read_text(encoding="utf-8"))
        assert (written["cell"], written["controller"]) == ("cell.yaml", "controller.yaml")
        assert Scenario.load(run.folder / "scenario.yaml").cell == str(run.folder / "cell.yaml")
        assert run.options.cell_path == (run.folder / "cell.yaml").resolve()
        copy = load_cell(run.folder / "cell.yaml")
        assert copy.stations == load_cell(shipped).stations
        assert [e.seed for e in run.episodes()] == [3]


def test_aggregate_of_no_episodes_has_no_numbers() -> None:
    agg = pool_line([]).to_data()
    assert agg["metrics"]["picked"] == {"mean": None, "ci95_low": None, "ci95_high": None, "n": 0}
    assert agg["wilson"]["success_rate"]["pooled"] is None


def test_grid_expands_scenarios_times_overrides_with_resolved_values(tmp_path: Path) -> None:
    grid_path = tmp_path / "grid.yaml"
    grid_path.write_text(
        f"scenarios: [{SCENARIOS / 'default.yaml'}, {SCENARIOS / 'dense.yaml'}]\n"
        "episodes: 2\n"
        "overrides: {speed: [0.2, 0.6], duration_s: [5], mode: [lockstep]}\n",
        encoding="utf-8",
    )
    cells = expand(Grid.load(grid_path), tmp_path)
    assert [c.name for c in cells] == [
        "default-speed0.2-duration_s5.0-modelockstep",
        "default-speed0.6-duration_s5.0-modelockstep",
        "dense-speed0.2-duration_s5.0-modelockstep",
        "dense-speed0.6-duration_s5.0-modelockstep",
    ]
    assert [c.scenario.system.belt_speed_mps for c in cells] == [0.2, 0.6, 0.2, 0.6]
    assert all(c.scenario.duration_s == 5.0 and c.seeds == (0, 1) for c in cells)
    assert cells[2].scenario.system.image_gap_m == 0.0


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("scenarios: [a.yaml]\nworkers: 3\n", r"unknown key 'workers'"),
        ("scenarios: []\n", r"scenarios = \[\]"),
        ("scenarios: [a.yaml]\nseeds: [1]\nepisodes: 2\n", r"seeds and episodes"),
        ("scenarios: [a.yaml]\noverrides: {speed: [3.0]}\n", r"overrides\.speed\[0\] = 3\.0"),
        ("scenarios: [a.yaml]\noverrides: {mode: [fast]}\n", r"overrides\.mode\[0\] = 'fast'"),
        ("scenarios: [a.yaml]\noverrides: {belt: [1]}\n", r"overrides: unknown key 'belt'"),
    ],
)
def test_bad_grids_name_the_file_and_key(tmp_path: Path, text: str, pattern: str) -> None:
    path = tmp_path / "grid.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=pattern) as info:
        Grid.load(path)
    assert str(path) in str(info.value)


def test_a_bad_scenario_in_a_grid_fails_before_anything_runs(tmp_path: Path) -> None:
    (tmp_path / "bad.yaml").write_text("system: {belt_speed_mps: 9}\n", encoding="utf-8")
    (tmp_path / "grid.yaml").write_text("scenarios: [bad.yaml]\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"bad\.yaml: .*system\.belt_speed_mps = 9\.0"):
        expand(Grid.load(tmp_path / "grid.yaml"), tmp_path)


@pytest.mark.parametrize(
    ("flag", "value"), [("--rounds", "0"), ("--episodes", "0"), ("--workers", "1")]
)
def test_bench_sweep_rejects_a_pass_it_cannot_compare_before_running_anything(
    flag: str, value: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from twin.cli import main

    assert main(["bench", "sweep", flag, value, "--json"]) == 2
    err = capsys.readouterr().err
    assert f"{flag} {value}" in err
    assert "need rounds >= 1, episodes >= 1 and workers >= 2" in err


@pytest.mark.parametrize("value", ["dds", "ros,ros", ""])
def test_bench_sweep_rejects_an_unknown_or_repeated_transport(
    value: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from twin.cli import main

    assert main(["bench", "sweep", "--transports", value, "--json"]) == 2
    err = capsys.readouterr().err
    assert f"--transports {value!r}: a comma-separated list of distinct ros, inproc" in err


def test_a_grid_with_a_repeated_seed_is_refused_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A seed twice in a cell would count one sample as two (a narrower interval for nothing)."""
    from twin.cli import main

    grid = tmp_path / "grid.yaml"
    grid.write_text(
        f"scenarios: [{SCENARIOS / 'default.yaml'}]\nseeds: [1, 1, 2]\n", encoding="utf-8"
    )
    with pytest.raises(ConfigError, match=r"seeds = \[1, 1, 2\]: seed\(s\) 1 repeated") as info:
        Grid.load(grid)
    assert str(info.value).startswith(f"{grid}: ")
    out = tmp_path / "sweep"
    assert main(["sweep", str(grid), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"cdw-twin: error: {grid}: seeds = [1, 1, 2]: seed(s) 1 repeated")
    assert err.count("\n") == 1
    assert not out.exists()


LINE_STANDIN = Path(__file__).resolve().parent / "cells" / "line_standin.yaml"


def test_a_stations_override_runs_the_first_k_stations_of_the_scenarios_cell(
    tmp_path: Path, builtin_meshes: Path
) -> None:
    """One grid gives recovery against the number of stations: each grid cell's run folder
    keeps the truncated cell; the scenario's own cell file is untouched."""
    from interfaces.cell import load_cell

    (tmp_path / "line.yaml").write_text(
        f"name: line\ncell: {LINE_STANDIN}\nduration_s: 2.0\n", encoding="utf-8"
    )
    grid = tmp_path / "grid.yaml"
    grid.write_text(
        "scenarios: [line.yaml]\nseeds: [1, 2]\n"
        "overrides: {stations: [1, 2, 3], speed: [0.2, 0.6]}\n",
        encoding="utf-8",
    )
    before = LINE_STANDIN.read_bytes()
    runs = prepare_sweep(grid, tmp_path / "sweep", dataset=builtin_meshes)
    assert LINE_STANDIN.read_bytes() == before
    assert [
        (r.cell.overrides["stations"], r.cell.scenario.system.belt_speed_mps) for r in runs
    ] == [
        (1, 0.2),
        (2, 0.2),
        (3, 0.2),
        (1, 0.6),
        (2, 0.6),
        (3, 0.6),
    ]
    full = load_cell(LINE_STANDIN)
    for run in runs:
        k = run.cell.overrides["stations"]
        written = load_cell(run.folder / "cell.yaml")
        assert written.stations == full.stations[:k]
        assert run.options.stations == tuple(s.name for s in full.stations[:k])
        assert run.options.dataset == builtin_meshes.resolve()
        assert run.folder.name == f"line-speed{run.cell.scenario.system.belt_speed_mps}-stations{k}"
    assert load_cell(runs[0].folder / "cell.yaml").name == "line_standin_first1"
    assert load_cell(runs[2].folder / "cell.yaml").name == "line_standin"


def test_more_stations_than_the_cell_has_is_refused_before_anything_is_written(
    tmp_path: Path, builtin_meshes: Path
) -> None:
    (tmp_path / "line.yaml").write_text(f"name: line\ncell: {LINE_STANDIN}\n", encoding="utf-8")
    grid = tmp_path / "grid.yaml"
    grid.write_text(
        f"scenarios: [line.yaml]\ndataset: {builtin_meshes}\noverrides: {{stations: [2, 4]}}\n",
        encoding="utf-8",
    )
    pattern = rf"{grid}: overrides\.stations = 4: the cell {LINE_STANDIN} has 3 station\(s\)"
    with pytest.raises(ConfigError, match=pattern):
        prepare_sweep(grid, tmp_path / "sweep")
    assert not (tmp_path / "sweep").exists()
    grid.write_text("scenarios: [line.yaml]\noverrides: {stations: [0]}\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"overrides\.stations\[0\] = 0: must be >= 1"):
        Grid.load(grid)


def test_a_cell_override_runs_a_scenario_on_another_cell(
    tmp_path: Path, builtin_meshes: Path
) -> None:
    """E.g. the throughput scenario on the suction cup's station: a shipped name, or a cell
    file relative to the grid file."""
    from interfaces.cell import load_cell

    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "mine.yaml").write_bytes(LINE_STANDIN.read_bytes())
    grid = tmp_path / "grid.yaml"
    grid.write_text(
        f"scenarios: [{SCENARIOS / 'throughput.yaml'}]\nseeds: [1]\n"
        f"dataset: {builtin_meshes}\noverrides: {{cell: [two_pandas, cells/mine.yaml]}}\n",
        encoding="utf-8",
    )
    runs = prepare_sweep(grid, tmp_path / "sweep")
    assert [r.folder.name for r in runs] == ["throughput-celltwo_pandas", "throughput-cellmine"]
    assert [len(r.options.stations) for r in runs] == [2, 3]
    assert load_cell(runs[1].folder / "cell.yaml").stations == load_cell(LINE_STANDIN).stations
    assert runs[0].cell.scenario.controller == "throughput"


def _reason_row(untargeted: dict, drops: dict, spawned: int) -> dict:
    share = {k: v / spawned for k, v in untargeted.items()}
    station = {"considered": spawned, "untargeted": untargeted, "untargeted_share": share}
    station |= {"untargeted_unfit": untargeted.get("too_wide", 0), "dropped_by_reason": drops}
    classes = {
        "brick": {
            "spawned": spawned + 1,
            "entered": spawned,
            "placed_correct": 3,
            "recovered": 2,
            "binned": 4,
            "recovery_rate": 2 / spawned,
        },
        "wood": {
            "spawned": 1,
            "entered": 1,
            "placed_correct": 1,
            "recovered": 1,
            "binned": 1,
            "recovery_rate": 1.0,
        },
    }
    return {
        "untargeted": untargeted,
        "dropped_by_reason": drops,
        "stations": {"s": station},
        "classes": classes,
    }


def test_the_sweep_gives_each_reason_and_each_class_a_mean_and_interval() -> None:
    """The untargeted objects and drops by reason (a reason an episode lacks counts 0 there),
    each reason's share of a station's window, and the class scores (recovery, purity)."""
    from experiments.sweep_pooling import pool_classes, pool_reasons

    rows = _typed(
        [
            _reason_row({"too_wide": 2, "claimed_by_other": 4}, {"slipped": 1}, 10),
            _reason_row({"too_wide": 0}, {}, 10),
            _reason_row({"too_wide": 1, "too_flat": 3}, {"slipped": 2, "seal_lost": 1}, 20),
            {"failed": True},
        ]
    )
    agg = pool_line(rows).to_data()
    assert list(agg["untargeted"]) == ["claimed_by_other", "too_flat", "too_wide"]
    assert agg["untargeted"]["too_wide"]["mean"] == pytest.approx(1.0)
    assert agg["untargeted"]["claimed_by_other"]["mean"] == pytest.approx(4 / 3)
    assert agg["untargeted"]["claimed_by_other"]["n"] == 3
    assert agg["dropped_by_reason"]["slipped"]["mean"] == pytest.approx(1.0)
    assert agg["dropped_by_reason"]["seal_lost"]["mean"] == pytest.approx(1 / 3)
    assert "untargeted_share" not in agg  # per station only
    station = pool_stations(rows)["s"].to_data()
    share = station["untargeted_share"]["too_wide"]
    assert share["mean"] == pytest.approx((0.2 + 0.0 + 0.05) / 3)
    assert share["ci95_low"] < share["mean"] < share["ci95_high"]
    unfit = station["wilson"]["unfit_share"]
    assert (unfit["successes"], unfit["trials"]) == (3, 40)
    assert pool_reasons([], "untargeted") == {}
    classes = {k: v.to_data() for k, v in pool_classes(rows).items()}
    assert list(classes) == ["brick", "wood"]
    # each episode: 3 bricks in their bins of 4 objects there, 2 of them in the complete cohort
    assert classes["brick"]["wilson"]["purity"]["pooled"] == pytest.approx(9 / 12)
    assert classes["brick"]["wilson"]["recovery_rate"]["pooled"] == pytest.approx(6 / 40)
    assert classes["wood"]["metrics"]["recovery_rate"]["mean"] == 1.0


def test_the_headline_lists_the_grids_figures_first(tmp_path: Path) -> None:
    """A grid names the metrics it exists to measure; ``sweep.json`` lists them per grid cell
    with their intervals: the line's, or each station's for a per-station metric."""
    from experiments.sweep_summary import headline

    rows = [_row(4, 5, 1, 6), _row(3, 5, 2, 6), _row(5, 5, 0, 6)]
    for row, share in zip(rows, (0.1, 0.2, 0.3), strict=True):
        row["stations"] = {"s1": {"untargeted_unfit": round(share * 10), "considered": 10}}
        row["stations"]["s1"]["unfit_share"] = share
    cell = _cell(_typed(rows), stations=("s1",))
    success, unfit = (r.to_data() for r in headline(cell, ["success_rate", "unfit_share"]))
    assert (success["metric"], success["scope"], success["stations"]) == ("success_rate", "line", 1)
    assert success["mean"] == pytest.approx(0.8)
    assert success["ci95_low"] < 0.8 < success["ci95_high"]
    assert success["pooled"] == pytest.approx(12 / 15)
    assert (unfit["scope"], unfit["mean"], unfit["n"]) == ("station s1", pytest.approx(0.2), 3)
    assert unfit["pooled"] == pytest.approx(6 / 30)
    grid = tmp_path / "grid.yaml"
    grid.write_text("scenarios: [a.yaml]\nheadline: [recovery]\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"headline\[0\] = 'recovery': not a metric"):
        Grid.load(grid)


def test_wilson_bounds_are_exactly_0_and_1_at_none_and_all() -> None:
    """Tables print the bounds: none of n is [0, ...], not [5.6e-17, ...]."""
    for n in range(1, 200):
        assert wilson_interval(0, n)[0] == 0.0, n
        assert wilson_interval(n, n)[1] == 1.0, n
    assert wilson_interval(3, 2) == (None, None)  # more successes than trials: no proportion
