"""``cdw-twin run`` end to end across real processes: two episodes, bad input, interruption."""

from __future__ import annotations

import csv
import importlib.util
import json
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from interfaces.errors import CdwTwinError
from twin.scenario import Scenario

SCENARIO = "name: e2e\nduration_s: 3.0\nsystem: {prefill_m: 1.0}\n"


def _needs_ros() -> None:
    for module in ("rclpy", "cdw_interfaces"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed in this venv")


def _cli(*args: str | Path) -> list[str]:
    return [sys.executable, "-m", "twin.cli", "run", *map(str, args)]


def _json(path: Path) -> Any:
    return json.loads(path.read_text(encoding="utf-8"))


def _yaml(path: Path) -> Any:
    import yaml

    return yaml.safe_load(path.read_text(encoding="utf-8"))


def test_two_episodes_end_to_end(builtin_meshes: Path, tmp_path: Path) -> None:
    _needs_ros()
    scenario = tmp_path / "e2e.yaml"
    scenario.write_text(SCENARIO, encoding="utf-8")
    out = tmp_path / "run"
    done = subprocess.run(
        _cli(scenario, "--episodes", 2, "--seed", 5, "--dataset", builtin_meshes, "--out", out),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        umask=0o002,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    # every file of the run folder has the mode an ordinary open gives under that umask
    modes = {
        str(p.relative_to(out)): stat.S_IMODE(p.stat().st_mode)
        for p in out.rglob("*")
        if p.is_file()
    }
    assert {"ep000/controller.json", "ep000/twin/summary.json", "run.json"} <= set(modes)
    assert {name: mode for name, mode in modes.items() if mode != 0o664} == {}
    assert "episode 2/2 (seed 6)" in done.stdout
    run = _json(out / "run.json")
    assert run["complete"] is True
    assert "stopped" not in run
    assert run["episodes"] == 2
    assert run["dataset"] == str(builtin_meshes.resolve())
    assert run["scenario_path"] == str(scenario)
    rows = _json(out / "episodes.json")
    assert [r["seed"] for r in rows] == [5, 6]
    assert all(r["complete"] and r["mode"] == "lockstep" for r in rows)
    assert all(r["processed"] >= r["missed"] >= 0 for r in rows)
    with (out / "episodes.csv").open(encoding="utf-8") as handle:
        assert [row["seed"] for row in csv.DictReader(handle)] == ["5", "6"]
    _check_the_copies_a_rerun_needs(out, builtin_meshes)
    _check_one_station(out, run, rows)
    _check_recordings(out, rows)


def _check_one_station(out: Path, run: dict[str, Any], rows: list[dict[str, Any]]) -> None:
    """A cell of one station: its station block agrees with the line's."""
    from interfaces.cell import default_cell

    (station,) = (s.name for s in default_cell().stations)
    assert (run["cell"], run["stations"]) == (default_cell().name, [station])
    for row in rows:
        # one station: the station's block is the line's, but for what it alone can see
        block = row["stations"][station]
        for key in ("picked", "missed", "processed", "targeted", "placed_correct", "faults"):
            assert block[key] == row[key], key
        assert block["spawned"] <= row["spawned"]
        assert row["picks"] == row["picked"]
        assert sum(c["spawned"] for c in row["classes"].values()) == row["spawned"]
    assert set(run["mean_by_station"]) == {station}


def _check_the_copies_a_rerun_needs(out: Path, dataset: Path) -> None:
    """The run folder reruns as it ran: its own copies of the cell and of the parameter file,
    the absolute dataset."""
    from control.cmd_controller import DEFAULT_PARAMS
    from experiments.run import controller_params
    from interfaces.cell import default_cell, load_cell

    written = Scenario.load(out / "scenario.yaml")
    assert written.duration_s == 3.0
    assert _yaml(out / "scenario.yaml")["cell"] == "cell.yaml"  # beside it, wherever it goes
    assert load_cell(out / "cell.yaml").stations == default_cell().stations
    assert written.controller == "controller.yaml"
    assert written.dataset == str(dataset.resolve())
    copy = controller_params(written.controller, out, load_cell(out / "cell.yaml"))
    assert copy == (out / "controller.yaml").resolve()
    assert copy.read_bytes() == DEFAULT_PARAMS.read_bytes()


def _check_recordings(out: Path, rows: list[dict[str, Any]]) -> None:
    """The twin recorded every message it sent and received, from its first tick to its
    last, and the scores recomputed from each recording are the twin's and the run's."""
    from experiments.offline import offline_metrics
    from interfaces.cell import default_cell
    from interfaces.contract import COMMANDS

    (station,) = (s.name for s in default_cell().stations)
    for i in range(2):
        summary = _json(out / f"ep00{i}" / "twin" / "summary.json")
        assert summary["sim_seconds"] == pytest.approx(3.0)
        assert summary["lockstep_timeouts"] == 0
        assert (out / f"ep00{i}" / "controller.json").is_file()
        recording = out / f"ep00{i}" / "recording.mcap"
        assert not recording.with_name("recording.mcap.partial").exists()
        offline = offline_metrics(recording, out / "cell.yaml")
        assert offline.complete is True
        assert offline.scores == summary["scores"]
        assert offline.stations == {station: summary["stations"][station]["scores"]}
        assert offline.scores["picked"] == rows[i]["picked"]
        counts = offline.message_counts
        for topic, n in summary["published"].items():
            assert counts[topic] == n, topic
        assert counts["/lockstep/tick"] == counts["/clock"] == counts["/joint_states"]
        commands = [t.resolve("") for t in COMMANDS]  # the station's commands, claims included
        assert sum(counts.get(t, 0) for t in commands) == summary["received_commands"] > 0


def test_a_bad_scenario_is_rejected_before_anything_starts(tmp_path: Path) -> None:
    scenario = tmp_path / "bad.yaml"
    scenario.write_text("faults: {belt_stall: [[5, 2]]}\n", encoding="utf-8")
    out = tmp_path / "run"
    done = subprocess.run(
        _cli(scenario, "--out", out), capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 2
    assert "faults.belt_stall[0] = [5.0, 2.0]" in done.stderr
    assert str(scenario) in done.stderr
    assert not out.exists()


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("fastest", "controller = 'fastest': no parameter file of that name (shipped: default"),
        ("params.yaml", "controller = 'params.yaml': "),
    ],
)
def test_a_bad_controller_parameter_file_is_rejected_before_anything_starts(
    tmp_path: Path, value: str, message: str
) -> None:
    (tmp_path / "params.yaml").write_text(
        "controller:\n  ros__parameters:\n    pick: {approach_space: diagonal}\n", encoding="utf-8"
    )
    scenario = tmp_path / "bad.yaml"
    scenario.write_text(f"controller: {value}\n", encoding="utf-8")
    out = tmp_path / "run"
    done = subprocess.run(
        _cli(scenario, "--out", out), capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 2
    assert message in done.stderr
    if value == "params.yaml":  # the file's own error names the key inside it
        assert "pick.approach_space" in done.stderr
    assert not out.exists()


def test_shipped_controller_parameter_files_resolve_and_load(tmp_path: Path) -> None:
    from control.config import load_config
    from experiments.run import controller_params
    from interfaces.cell import default_cell

    cell = default_cell()
    throughput = controller_params("throughput", None, cell)
    assert throughput.name == "throughput.yaml"
    assert load_config(throughput).pick.approach_space == "joint"
    assert load_config(controller_params("default", None, cell)).pick.approach_space == "joint"
    own = tmp_path / "mine.yaml"
    own.write_text("controller:\n  ros__parameters:\n    pick: {dwell_s: 0.5}\n", encoding="utf-8")
    assert controller_params("mine.yaml", tmp_path, cell) == own.resolve()


def test_the_parameter_file_is_checked_against_the_scenarios_own_cell(tmp_path: Path) -> None:
    """A file that names the line's stations and a class of the dataset is right for the line
    resolved for that dataset, and refused, naming the key, for a cell it does not fit: the
    reference cell (no station s6), or the line resolved for a dataset without wood."""
    from experiments.run import controller_params
    from interfaces.cell import default_cell, load_cell, resolve_cell
    from interfaces.materials import table_from_data

    own = tmp_path / "line_mine.yaml"
    own.write_text(
        "controller:\n  ros__parameters:\n"
        "    allocation: {strategy: class_priority, preferred_classes: {s6: [wood]}}\n"
        "    scheduler: {class_priorities: {wood: 2.0}}\n",
        encoding="utf-8",
    )
    line = load_cell("line")
    assert controller_params("line_mine.yaml", tmp_path, line) == own.resolve()
    with pytest.raises(CdwTwinError, match=r"preferred_classes\.s6 .*not a station of the cell"):
        controller_params("line_mine.yaml", tmp_path, default_cell())
    tiles = table_from_data({"classes": {"bricks": {}, "tiles": {}}}, "t", line.materials)
    with pytest.raises(CdwTwinError, match=r"class_priorities\.wood = 2\.0: not a class of"):
        controller_params("line_mine.yaml", tmp_path, resolve_cell(line, tiles))
    # the shipped line file checks against any dataset's line: it names no class
    assert controller_params("line", None, resolve_cell(line, tiles)).name == "line.yaml"


def test_interrupt_keeps_the_finished_episodes_and_says_incomplete(
    builtin_meshes: Path, tmp_path: Path
) -> None:
    _needs_ros()
    scenario = tmp_path / "e2e.yaml"
    scenario.write_text(SCENARIO, encoding="utf-8")
    out = tmp_path / "run"
    proc = subprocess.Popen(
        _cli(scenario, "--episodes", 3, "--dataset", builtin_meshes, "--out", out, "--json"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 90
        while not (out / "ep001" / "twin.log").is_file():
            assert proc.poll() is None, proc.communicate()[1][-3000:]
            assert time.monotonic() < deadline
            time.sleep(0.2)
        time.sleep(1.0)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr[-3000:]
    assert "stopped after 1/3 episodes" in stderr
    run = _json(out / "run.json")
    assert run["complete"] is False
    assert run["stopped"] == "interrupted (SIGINT)"
    # --json prints what finished: the first episode's metrics, flagged incomplete
    printed = json.loads(stdout)
    assert (printed["complete"], printed["stopped"]) == (False, "interrupted (SIGINT)")
    assert (printed["episodes"], printed["failed"], printed["out"]) == (1, 0, str(out))
    assert printed["picks"] == run["mean"]["picks"] == _json(out / "episodes.json")[0]["picks"]
    rows = _json(out / "episodes.json")
    assert [r["seed"] for r in rows] == [0]
    assert _json(out / "ep000" / "twin" / "summary.json")["complete"] is True
    assert not (out / "ep002").exists()


RESTART_SCENARIO = """\
name: restarts
duration_s: 30.0
objects: {max_width_m: 0.065, min_height_m: 0.02}
system: {belt_speed_mps: 0.3, object_order: shuffled, image_gap_m: 0.0, prefill_m: 0.5}
faults: {controller_restart_at_s: [4.0, 8.0]}
"""


def test_a_controller_restarted_twice_mid_episode_recovers(
    builtin_meshes: Path, tmp_path: Path
) -> None:
    """Each restart costs one ack timeout, the new controller brings the twin back to lockstep
    (no further waits), and the last one picks objects after it took over."""
    _needs_ros()
    scenario = tmp_path / "restarts.yaml"
    scenario.write_text(RESTART_SCENARIO, encoding="utf-8")
    out = tmp_path / "run"
    done = subprocess.run(
        _cli(scenario, "--dataset", builtin_meshes, "--out", out, "--mode", "lockstep"),
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    row = _json(out / "episodes.json")[0]
    assert row["complete"] is True
    assert row["controller_restarts"] == 2
    episode = out / "ep000"
    summary = _json(episode / "twin" / "summary.json")
    assert summary["sim_seconds"] == pytest.approx(30.0)
    assert summary["lockstep_timeouts"] == 2
    events = [
        json.loads(line)
        for line in (episode / "twin" / "events.jsonl").read_text(encoding="utf-8").splitlines()
    ]
    lost = [e for e in events if e["type"] == "fault"]
    back = [e for e in events if e["type"] == "controller_resumed"]
    assert [e["data"]["kind"] for e in lost] == ["controller_timeout"] * 2
    assert len(back) == 2
    for fault, resumed in zip(lost, back, strict=True):
        assert fault["time_s"] <= resumed["time_s"] < fault["time_s"] + 3.0
        assert resumed["data"]["outage_s"] == pytest.approx(resumed["time_s"] - fault["time_s"])
    assert 4.0 <= lost[0]["time_s"] < lost[1]["time_s"]
    # the last controller acknowledged every tick from its resumption to the end
    last = _json(episode / "controller_2.json")
    end_step = round(30.0 * 240)
    assert last["ticks_acked"] >= end_step - back[1]["step"]
    picks_after = [
        e for e in events if e["type"] == "pick_success" and e["time_s"] > back[1]["time_s"]
    ]
    assert picks_after, [e["type"] for e in events if e["time_s"] > back[1]["time_s"]]


def _event(kind: str, oid: int, **data: Any) -> str:
    raw = {"time_s": 1.0, "step": 240, "type": kind, "object_id": oid, "class_name": "brick"}
    return json.dumps({**raw, "data": data})


def _episode_folder(run: Path, cell: str, events: list[str], landing: list[int]) -> Path:
    from interfaces.cell import load_cell
    from interfaces.run_folder import RunFolder

    run.mkdir(parents=True)
    load_cell(cell).save(RunFolder(run).cell)
    episode = RunFolder(run).episode(0)
    episode.twin.mkdir(parents=True)
    summary = {
        "belt_speed_mps": 0.3,
        "seed": 1,
        "sim_seconds": 60.0,
        "real_time_factor": 1.0,
        "complete": True,
        "tracking": {"tracking_time_4mm_mean_s": 0.7, "pursuits": 4, "unsettled": 0},
        "landing_in_bins": landing,
    }
    episode.summary.write_text(json.dumps(summary), encoding="utf-8")
    episode.events.write_text("\n".join(events) + "\n", encoding="utf-8")
    return episode.path


def _stats(completed: int, **untargeted: int) -> str:
    pick = {"targeted": completed, "completed": completed, "aborted": {}}
    return json.dumps({"pick": {**pick, "untargeted": untargeted}})


def test_an_object_still_falling_into_its_bin_at_the_end_is_not_counted_targeted(
    tmp_path: Path,
) -> None:
    """The controller counts a pick complete at its release; the twin counts it placed when it
    drops below the bin's top. One released just before the end is in neither tally yet."""
    from experiments.scoring import score_episode

    events = [_event("spawned", i) for i in range(1, 6)]
    events += [_event("pick_success", oid, station="panda") for oid in range(1, 5)]
    events += [_event("placed_in_bin", i, station="panda", correct=True) for i in (1, 2, 3)]
    events.append(_event("missed", 5, station="panda"))
    rows = []
    for landing in ([], [4]):
        run = tmp_path / f"run{len(landing)}"
        folder = _episode_folder(run, "default", events, landing)
        (folder / "controller.json").write_text(_stats(4, too_wide=2), encoding="utf-8")
        rows.append(score_episode(folder, "lockstep"))
    assert (rows[0].metric("targeted"), rows[0].metric("success_rate")) == (4, 0.75)
    assert (rows[1].metric("targeted"), rows[1].metric("success_rate")) == (3, 1.0)
    assert rows[1].line.untargeted == {"too_wide": 2}
    assert rows[1].stations["panda"]["targeted"] == 3
    assert [rows[1].metric(k) for k in ("picked", "missed", "processed")] == [4, 1, 5]


def test_each_station_is_credited_its_own_targets_less_its_own_landing_objects(
    tmp_path: Path,
) -> None:
    from experiments.scoring import score_episode

    up, down = {"station": "upstream"}, {"station": "downstream"}
    events = [_event("spawned", i) for i in range(1, 6)]
    for oid in (1, 2, 3):
        events.append(_event("pick_success", oid, **up))
        events.append(_event("placed_in_bin", oid, correct=True, **up))
    events.append(_event("missed", 4, **up))
    events.append(_event("missed", 5, **up))  # still on its way downstream at the end
    events.append(_event("pick_success", 4, **down))  # released, still falling at the end
    folder = _episode_folder(tmp_path / "run", "two_pandas", events, landing=[4])
    (folder / "controller-upstream.json").write_text(_stats(3, too_wide=1), encoding="utf-8")
    (folder / "controller-upstream_1.json").write_text(_stats(0), encoding="utf-8")
    (folder / "controller-downstream.json").write_text(_stats(1, flat=2), encoding="utf-8")
    row = score_episode(folder, "lockstep")
    up_row, down_row = row.stations["upstream"], row.stations["downstream"]
    assert (up_row["targeted"], up_row["success_rate"]) == (3, 1.0)
    assert (down_row["targeted"], down_row["success_rate"]) == (0, 0.0)
    assert (row.metric("targeted"), row.metric("success_rate")) == (3, 1.0)
    assert row.line.untargeted == {"too_wide": 1, "flat": 2}
    assert (up_row["controller_restarts"], down_row["controller_restarts"]) == (1, 0)
    assert row.metric("controller_restarts") == 1
    # object 5, missed upstream only, is undecided for the line
    assert [row.metric(k) for k in ("missed", "processed", "picks")] == [0, 4, 4]
    assert (up_row["missed"], up_row["processed"]) == (2, 5)
    assert down_row["picked"] == 1


def test_an_episode_row_gives_bin_purity_drops_and_allocation_per_station(
    tmp_path: Path,
) -> None:
    """The line scores of a run row: each station's bins and their purity, drops by reason, the
    controllers' untargeted objects by reason (new reasons too) and their share of the window's
    objects, per class purity over the line."""
    from experiments.scoring import score_episode

    up, down = {"station": "upstream"}, {"station": "downstream"}
    events = [_event("spawned", i) for i in range(1, 5)]
    events += [_event("entered_workspace", i, **up) for i in range(1, 5)]
    events += [
        _event("pick_success", 1, **up),
        _event("placed_in_bin", 1, bin="brick", correct=True, **up),
        _event("pick_success", 2, **up),
        _event("pick_dropped", 2, reason="suction_overload", **up),
        _event("entered_workspace", 2, **down),
        _event("pick_success", 2, **down),
        _event("placed_in_bin", 2, bin="wood", correct=False, **down),
        _event("pick_success", 3, **up),
        _event("pick_dropped", 3, reason="seal_lost", **up),
    ]
    folder = _episode_folder(tmp_path / "run", "two_pandas", events, landing=[])
    (folder / "controller-upstream.json").write_text(
        _stats(3, too_wide=1, claimed_by_other=1), encoding="utf-8"
    )
    (folder / "controller-downstream.json").write_text(
        _stats(1, too_small=1, left_for_downstream=2), encoding="utf-8"
    )
    row = score_episode(folder, "lockstep")
    up_row, down_row = row.stations["upstream"], row.stations["downstream"]
    assert up_row.bins == {"brick": {"binned": 1, "placed_correct": 1, "purity": 1.0}}
    assert down_row.bins == {"wood": {"binned": 1, "placed_correct": 0, "purity": 0.0}}
    assert row.line.dropped_by_reason == {"seal_lost": 1, "suction_overload": 1}
    assert (row.metric("dropped"), up_row["dropped"], down_row["dropped"]) == (2, 2, 0)
    # the upstream controller targeted 3 objects and left 2; the downstream one 1 and 3
    assert up_row.untargeted == {"too_wide": 1, "claimed_by_other": 1}
    assert up_row["considered"] == 5
    assert up_row.untargeted_share == {"claimed_by_other": 0.2, "too_wide": 0.2}
    assert (up_row["untargeted_unfit"], up_row["unfit_share"]) == (1, 0.2)
    assert (down_row["untargeted_unfit"], down_row["unfit_share"]) == (1, 0.25)
    assert row.line.untargeted["left_for_downstream"] == 2
    # a station's figure: a line counts an object per station
    assert "unfit_share" not in row.line.values
    assert (row.metric("binned"), row.metric("purity")) == (2, 0.5)
    assert row.classes["brick"]["purity"] == 1.0
    # 4 entered the upstream window with no fate at the end: the cohort is 1-3, 1 recovered
    assert [row.metric(k) for k in ("entered", "recovered", "spawned")] == [3, 1, 4]
    assert row.classes["brick"]["recovery_rate"] == pytest.approx(1 / 3)


TWO_STATIONS = """\
name: two
cell: two_pandas
duration_s: 15.0
objects: {max_width_m: 0.065, min_height_m: 0.02}
system: {belt_speed_mps: 0.3, object_order: shuffled, image_gap_m: 0.0, prefill_m: 2.5}
faults: {controller_restart_at_s: [3.0]}
"""


@pytest.mark.slow
def test_a_cell_of_two_stations_runs_a_controller_per_station_and_scores_each(
    builtin_meshes: Path, tmp_path: Path
) -> None:
    """The shipped two-Panda cell in lockstep: one controller process per station (each
    restarted at 3 s), picks by both, scores per station and for the line that agree with the
    twin's summary and with the recording."""
    _needs_ros()
    from experiments.offline import offline_metrics
    from interfaces.metrics import in_scope

    scenario = tmp_path / "two.yaml"
    scenario.write_text(TWO_STATIONS, encoding="utf-8")
    out = tmp_path / "run"
    done = subprocess.run(
        _cli(scenario, "--dataset", builtin_meshes, "--out", out, "--json"),
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    episode = out / "ep000"
    names = {p.name for p in episode.iterdir()}
    for station in ("upstream", "downstream"):
        assert {f"controller-{station}.json", f"controller-{station}_1.json"} <= names
        log = (episode / f"controller-{station}.log").read_text(encoding="utf-8")
        assert log.count(f"station {station} of {(out / 'cell.yaml').resolve()}") == 2
    assert "controller.json" not in names
    summary = _json(episode / "twin" / "summary.json")
    assert summary["complete"] is True
    (row,) = _json(out / "episodes.json")
    stations = row["stations"]
    assert list(stations) == ["upstream", "downstream"]
    for name, block in stations.items():
        assert set(in_scope("station")) <= set(block)
        assert block["picked"] > 0, name  # both stations picked
        assert block["controller_restarts"] == 1
        twin_scores = summary["stations"][name]["scores"]
        for key in ("spawned", "picked", "missed", "processed", "placed_correct"):
            assert block[key] == twin_scores[key], (name, key)
        stats = [_json(episode / f"controller-{name}{s}.json") for s in ("", "_1")]
        assert all(s["ticks_acked"] > 0 for s in stats)
    assert row["controller_restarts"] == 1
    assert row["targeted"] == sum(b["targeted"] for b in stations.values())
    assert row["untargeted_total"] == sum(b["untargeted_total"] for b in stations.values())
    assert row["faults"] == sum(b["faults"] for b in stations.values()) == 2
    assert row["picked"] <= sum(b["picked"] for b in stations.values())
    # the line: what the twin, the run and the recording say agree
    offline = offline_metrics(episode / "recording.mcap", out / "cell.yaml")
    for key in ("spawned", "picked", "missed", "processed", "lost", "placed_correct"):
        assert row[key] == offline.scores[key] == summary["scores"][key], key
    assert offline.stations == {n: summary["stations"][n]["scores"] for n in stations}
    assert offline.classes == row["classes"]
    assert offline.bins == {n: b["bins"] for n, b in stations.items() if b["bins"]}
    run = _json(out / "run.json")
    assert run["stations"] == ["upstream", "downstream"]
    assert run["mean_by_station"]["downstream"]["picked"] == stations["downstream"]["picked"]
    printed = json.loads(done.stdout)
    assert printed["mean_by_station"] == run["mean_by_station"]


TWO_STATIONS_REALTIME = """\
name: two_realtime
cell: two_pandas
controller: throughput
duration_s: 15.0
objects: {max_width_m: 0.065, min_height_m: 0.02}
system: {belt_speed_mps: 0.3, object_order: shuffled, image_gap_m: 0.0, prefill_m: 2.5}
"""


@pytest.mark.slow
def test_a_cell_of_two_stations_runs_in_realtime_and_both_pick(
    builtin_meshes: Path, tmp_path: Path
) -> None:
    """The shipped two-Panda cell paced to the wall clock: two controller processes, each in
    its namespace, both pick, the line's and each station's scores agree with the twin. The
    throughput parameters (joint-space approach) pick about twice as often as the default's
    in these 15 s, so the test does not hang on one or two picks per station."""
    _needs_ros()
    scenario = tmp_path / "two.yaml"
    scenario.write_text(TWO_STATIONS_REALTIME, encoding="utf-8")
    out = tmp_path / "run"
    done = subprocess.run(
        _cli(scenario, "--mode", "realtime", "--dataset", builtin_meshes, "--out", out, "--json"),
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    (row,) = _json(out / "episodes.json")
    assert row["mode"] == "realtime"
    summary = _json(out / "ep000" / "twin" / "summary.json")
    assert summary["mode"] == "realtime"
    assert summary["complete"] is True
    for name in ("upstream", "downstream"):
        block = row["stations"][name]
        assert block["picked"] > 0, name
        assert block["picked"] == summary["stations"][name]["scores"]["picked"]
        stats = _json(out / "ep000" / f"controller-{name}.json")
        assert stats["mode"] == "realtime"
        assert stats["control_updates"] > 0
    assert row["picked"] == summary["scores"]["picked"] > 0
    # commands that reach the twin a step late are applied as of their stamps: the arm tracks
    # as in lockstep (judged by arrival, the joint limiter took such commands over and the
    # tool rang around its target: 0 of 20 pursuits settled within 4 mm)
    tracking = summary["tracking"]
    assert tracking["settled"] >= tracking["pursuits"] / 4 > 0


def test_a_run_folder_reruns_as_it_ran_with_its_own_cell(
    builtin_meshes: Path, tmp_path: Path
) -> None:
    """The scenario names a cell file beside it; the run folder keeps the resolved copy, so
    ``cdw-twin run RUN/scenario.yaml`` reruns the episode exactly after the original is gone."""
    _needs_ros()
    from interfaces.cell import DEFAULT_CELL, load_cell

    cell_text = DEFAULT_CELL.read_text(encoding="utf-8")
    assert "name: panda\n" in cell_text
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "left.yaml").write_text(
        cell_text.replace("name: panda\n", "name: left\n"), encoding="utf-8"
    )
    scenario = tmp_path / "e2e.yaml"
    scenario.write_text(SCENARIO + "cell: cells/left.yaml\n", encoding="utf-8")
    first = tmp_path / "first"
    done = subprocess.run(
        _cli(scenario, "--seed", 3, "--dataset", builtin_meshes, "--out", first),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert _yaml(first / "scenario.yaml")["cell"] == "cell.yaml"
    assert [s.name for s in load_cell(first / "cell.yaml").stations] == ["left"]
    (tmp_path / "cells" / "left.yaml").unlink()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    second = tmp_path / "second"
    done = subprocess.run(
        [*_cli(first / "scenario.yaml", "--out", second)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        cwd=elsewhere,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert (second / "cell.yaml").read_text() == (first / "cell.yaml").read_text()
    events = [
        (run / "ep000" / "twin" / "events.jsonl").read_text(encoding="utf-8")
        for run in (first, second)
    ]
    assert events[0] == events[1]
    assert '"station": "left"' in events[0]
    rows = [_json(run / "episodes.json")[0] for run in (first, second)]
    assert list(rows[0]["stations"]) == ["left"]
    assert rows[0]["seed"] == rows[1]["seed"] == 3
    for key in ("spawned", "picked", "missed", "processed", "targeted", "stations"):
        assert rows[0][key] == rows[1][key], key
