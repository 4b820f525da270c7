"""A run folder as written by ``cdw-twin run``: every file is its typed record, read back to
the same bytes, and the metrics written for each episode are what its recording gives.

One two-station episode in process (``--transport inproc``: the ROS path is tested elsewhere),
shared by the tests of this module.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from interfaces.run_folder import RunFolder
from interfaces.run_records import (
    ControllerStats,
    EpisodeMetrics,
    EpisodeSummary,
    RunMeans,
    ScopeMetrics,
    read_rows,
    write_rows,
)

SCENARIO = (
    "name: two_station_folder\ncell: two_pandas\nduration_s: 12.0\n"
    "system: {prefill_m: 3.0, belt_speed_mps: 0.3}\n"
)


@pytest.fixture(scope="module")
def run(builtin_meshes: Path, tmp_path_factory: pytest.TempPathFactory) -> RunFolder:
    root = tmp_path_factory.mktemp("run_folder")
    scenario = root / "two.yaml"
    scenario.write_text(SCENARIO, encoding="utf-8")
    out = root / "run"
    done = subprocess.run(
        [
            *(sys.executable, "-m", "twin.cli", "run", str(scenario)),
            *("--dataset", str(builtin_meshes), "--out", str(out), "--seed", "2"),
            *("--transport", "inproc"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return RunFolder(out)


def _same_bytes(original: Path, written: Path) -> None:
    assert written.read_bytes() == original.read_bytes(), original


def test_every_file_of_a_run_reads_as_its_record_and_writes_back_the_same(
    run: RunFolder, tmp_path: Path
) -> None:
    (episode,) = run.episodes()
    stations = ("upstream", "downstream")
    summary = EpisodeSummary.read(episode.summary)
    assert summary.complete
    assert summary.sim_seconds == pytest.approx(12.0)
    assert set(summary.stations) == set(stations)
    summary.write(tmp_path / "summary.json")
    _same_bytes(episode.summary, tmp_path / "summary.json")
    for station in stations:
        (path,) = episode.stats_files(station, stations)
        assert path.name == f"controller-{station}.json"
        stats = ControllerStats.read(path)
        assert stats.station == station
        assert stats.pick is not None
        assert stats.ticks_acked > 0
        stats.write(tmp_path / path.name)
        _same_bytes(path, tmp_path / path.name)
    rows = read_rows(run.episodes_json)
    write_rows(tmp_path / "episodes.json", rows)
    _same_bytes(run.episodes_json, tmp_path / "episodes.json")
    (row,) = rows
    assert isinstance(row, EpisodeMetrics)
    assert list(row.stations) == list(stations)
    means = RunMeans.read(run.run_json)
    assert means.complete
    assert means.episodes == 1
    assert means.info.stations == stations
    assert means.mean["picked"] == row.line["picked"]
    means.write(tmp_path / "run.json")
    _same_bytes(run.run_json, tmp_path / "run.json")


def test_the_metrics_written_for_an_episode_are_what_its_recording_gives(run: RunFolder) -> None:
    """Scored once: the row the runner wrote and the metric table applied to the recording
    agree on every metric the events give (the line's, each station's, classes, bins)."""
    from experiments.offline import offline_metrics

    (episode,) = run.episodes()
    (row,) = read_rows(run.episodes_json)
    assert isinstance(row, EpisodeMetrics)
    offline = offline_metrics(episode.recording, run.cell)
    assert offline.complete
    assert offline.duration_s == pytest.approx(12.0)
    assert row.line["picked"]
    assert row.line["picked"] == offline.scores["picked"]
    assert set(offline.stations) == set(row.stations)
    assert offline.mismatches(row) == []
    # the comparison is not vacuous: a changed count is found, in the scope it was changed in
    name = next(iter(row.stations))
    block = row.stations[name]
    changed = replace(
        row,
        stations={
            **row.stations,
            name: ScopeMetrics(
                values={**block.values, "missed": int(block["missed"] or 0) + 1},
                untargeted=block.untargeted,
                dropped_by_reason=block.dropped_by_reason,
                untargeted_share=block.untargeted_share,
                bins=block.bins,
            ),
        },
    )
    assert [m.split(":")[0] for m in offline.mismatches(changed)] == [f"{name}.missed"]
