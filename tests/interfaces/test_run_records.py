"""The run folder's records: written and read back equal, and a file that is not its record
refused naming the file and the key."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from interfaces.run_folder import RunFolder, controller_stem, stats_instance, stats_name
from interfaces.run_records import (
    ControllerStats,
    EpisodeMetrics,
    EpisodeSummary,
    FailedEpisode,
    LatencySummary,
    PickStats,
    RecordError,
    RunInfo,
    RunMeans,
    ScopeMetrics,
    StationSummary,
    TimingUs,
    TrackingSummary,
    read_rows,
    write_rows,
)


def _summary() -> EpisodeSummary:
    tracking = TrackingSummary(
        pursuits=3,
        settled=2,
        unsettled=1,
        tracking_time_4mm_mean_s=0.75,
        tracking_time_4mm_p95_s=0.9,
        tracking_times_s=(0.6, 0.9),
    )
    return EpisodeSummary(
        scenario="default",
        seed=4,
        mode="lockstep",
        belt_speed_mps=0.4,
        complete=True,
        sim_seconds=60.0,
        wall_seconds=20.5,
        real_time_factor=2.9,
        cell="reference",
        scores={"picked": 3, "miss_rate": 0.25, "dropped_by_reason": {"slipped": 1}},
        stations={"panda": StationSummary(scores={"picked": 3}, tracking=tracking)},
        landing_in_bins=(7,),
        tracking=tracking,
        latency=LatencySummary(rtt_ms_p50=0.8, rtt_ms_p99=9.5, rtt_ms_mean=1.2, samples=10),
        final_state={"belt_position_m": 24.0, "objects": [{"id": 1, "pose": [0.0] * 7}]},
    )


@pytest.mark.parametrize(
    "summary",
    [
        _summary(),
        dataclasses.replace(
            _summary(), complete=False, stopped_by="SIGTERM", perception={"recall": 0.9}
        ),
    ],
)
def test_a_summary_written_and_read_back_is_equal(tmp_path: Path, summary: EpisodeSummary) -> None:
    path = tmp_path / "summary.json"
    summary.write(path)
    assert EpisodeSummary.read(path) == summary
    data = json.loads(path.read_text(encoding="utf-8"))
    # an episode that was not stopped has no stopped_by, one without a camera no perception
    assert ("stopped_by" in data) == (summary.stopped_by is not None)
    assert ("perception" in data) == (summary.perception is not None)
    assert list(data) == sorted(data)


def test_controller_stats_written_and_read_back_are_equal(tmp_path: Path) -> None:
    stats = ControllerStats(
        mode="lockstep",
        station="panda",
        pick=PickStats(targeted=3, completed=2, aborted={"too_late": 1}, untargeted={"blocked": 4}),
        received={"/joint_states": 10},
        control_update_us=TimingUs(mean=1.0, p50=0.5, p95=2.0, p99=3.0, max=4.0),
    )
    path = tmp_path / "controller.json"
    stats.write(path)
    assert ControllerStats.read(path) == stats


def test_episode_rows_and_the_run_means_written_and_read_back_are_equal(tmp_path: Path) -> None:
    station = ScopeMetrics(
        values={"picked": 2, "success_rate": 1.0, "tracking_time_4mm_mean_s": None},
        untargeted={"too_wide": 1},
        untargeted_share={"too_wide": 0.5},
        bins={"brick": {"purity": 1.0}},
    )
    row = EpisodeMetrics(
        episode=0,
        seed=1,
        mode="lockstep",
        speed_mps=0.4,
        line=ScopeMetrics(values={"picked": 2, "success_rate": 1.0}, dropped_by_reason={"x": 1}),
        stations={"panda": station},
        classes={"brick": {"recovery_rate": 0.5}},
        perception={"recall": 0.95},
    )
    failed = FailedEpisode(episode=1, seed=2, mode="lockstep", reason="twin exited")
    rows: list[EpisodeMetrics | FailedEpisode] = [row, failed]
    path = tmp_path / "episodes.json"
    write_rows(path, rows)
    assert read_rows(path) == rows
    data = json.loads(path.read_text(encoding="utf-8"))
    assert data[0]["picks"] == data[0]["picked"] == 2
    assert data[0]["perception_recall"] == 0.95
    assert row.metric("perception_recall") == 0.95
    assert row.metric("picks") == 2
    assert data[1] == {**failed.to_data(), "failed": True, "complete": False}
    info = RunInfo(
        scenario="s",
        dataset="/d",
        cell="reference",
        stations=("panda",),
        mode="lockstep",
        transport="inproc",
        speed_mps=0.4,
        episodes_planned=2,
    )
    means = RunMeans(
        complete=False,
        episodes=1,
        failed=1,
        failures=("episode 1 (seed 2) failed: twin exited",),
        info=info,
        mean={"picked": 2.0},
        mean_by_station={"panda": {"picked": 2.0}},
        mean_by_class={},
    )
    means.write(tmp_path / "run.json")
    assert RunMeans.read(tmp_path / "run.json") == means
    # settings that do not apply to a plain run are not written
    assert "overrides" not in json.loads((tmp_path / "run.json").read_text(encoding="utf-8"))


@pytest.mark.parametrize(
    ("text", "names"),
    [
        ('{"seed": 1, "complete": true, "sim_seconds": "long"}', "sim_seconds"),
        ('{"seed": 1, "complete": true, "sim_seconds": 1.0, "colour": 3}', "colour"),
        ('{"complete": true, "sim_seconds": 1.0}', "seed"),
        ("[1, 2", "not valid JSON"),
    ],
)
def test_a_summary_that_is_not_one_is_refused_naming_the_file_and_key(
    tmp_path: Path, text: str, names: str
) -> None:
    path = tmp_path / "summary.json"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(RecordError) as info:
        EpisodeSummary.read(path)
    assert str(path) in str(info.value)
    assert names in str(info.value)


def test_a_bad_row_is_refused_naming_the_file_row_and_key(tmp_path: Path) -> None:
    path = tmp_path / "episodes.json"
    good = {"episode": 0, "seed": 1, "mode": "lockstep", "speed_mps": 0.4, "picked": 1}
    path.write_text(json.dumps([good, {**good, "seed": "one"}]), encoding="utf-8")
    with pytest.raises(RecordError, match=r"episodes\.json\[1\]\.seed"):
        read_rows(path)


def test_the_folder_names_the_files_of_a_run_and_its_episodes(tmp_path: Path) -> None:
    run = RunFolder(tmp_path)
    for index in (10, 2, 0):
        run.episode(index).path.mkdir()
    (tmp_path / "epoch").mkdir()  # not an episode folder
    assert [e.index for e in run.episodes()] == [0, 2, 10]
    episode = run.episode(2)
    assert episode.summary == tmp_path / "ep002" / "twin" / "summary.json"
    assert episode.run == run
    assert controller_stem("panda", ["panda"]) == "controller"
    assert controller_stem("s2", ["s1", "s2"]) == "controller-s2"
    assert stats_name("controller-s2", 1) == "controller-s2_1.json"
    assert stats_instance("controller-s2_1.json", "controller-s2") == 1
    assert stats_instance("controller-s2.log", "controller-s2") is None
    for name in ("controller-s2.json", "controller-s2_1.json", "controller-s1.json"):
        (episode.path / name).write_text("{}", encoding="utf-8")
    assert [p.name for p in episode.stats_files("s2", ["s1", "s2"])] == [
        "controller-s2.json",
        "controller-s2_1.json",
    ]
