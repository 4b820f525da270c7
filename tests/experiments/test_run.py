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
    written = Scenario.load(out / "scenario.yaml")
    assert written.duration_s == 3.0
    # the run folder reruns as it ran: its own copy of the parameter file, the absolute dataset
    from control.cmd_controller import DEFAULT_PARAMS
    from experiments.run import controller_params

    assert written.controller == "controller.yaml"
    assert written.dataset == str(builtin_meshes.resolve())
    copy = controller_params(written.controller, out)
    assert copy == (out / "controller.yaml").resolve()
    assert copy.read_bytes() == DEFAULT_PARAMS.read_bytes()
    from experiments.offline import offline_metrics

    for i in range(2):
        summary = _json(out / f"ep00{i}" / "twin" / "summary.json")
        assert summary["sim_seconds"] == pytest.approx(3.0)
        assert summary["lockstep_timeouts"] == 0
        assert (out / f"ep00{i}" / "controller.json").is_file()
        # the twin recorded every message it sent and received, from its first tick to its last
        recording = out / f"ep00{i}" / "recording.mcap"
        assert not recording.with_name("recording.mcap.partial").exists()
        offline = offline_metrics(recording)
        assert offline["complete"] is True
        assert offline["scores"] == summary["scores"]
        counts = offline["message_counts"]
        for topic, n in summary["published"].items():
            assert counts[topic] == n, topic
        assert counts["/lockstep/tick"] == counts["/clock"] == counts["/joint_states"]
        commands = ("/arm_controller/joint_trajectory", "/gripper/command", "/controller/target")
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

    throughput = controller_params("throughput", None)
    assert throughput.name == "throughput.yaml"
    assert load_config(throughput).pick.approach_space == "joint"
    assert load_config(controller_params("default", None)).pick.approach_space == "cartesian"
    own = tmp_path / "mine.yaml"
    own.write_text("controller:\n  ros__parameters:\n    pick: {dwell_s: 0.5}\n", encoding="utf-8")
    assert controller_params("mine.yaml", tmp_path) == own.resolve()


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
duration_s: 16.0
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
    assert summary["sim_seconds"] == pytest.approx(16.0)
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
    end_step = round(16.0 * 240)
    assert last["ticks_acked"] >= end_step - back[1]["step"]
    picks_after = [
        e for e in events if e["type"] == "pick_success" and e["time_s"] > back[1]["time_s"]
    ]
    assert picks_after, [e["type"] for e in events if e["time_s"] > back[1]["time_s"]]


def test_an_object_still_falling_into_its_bin_at_the_end_is_not_counted_targeted(
    tmp_path: Path,
) -> None:
    """The controller counts a pick complete at its release; the twin counts it placed when it
    drops below the bin's top. One released just before the end is in neither tally yet."""
    from experiments.run import episode_metrics

    def summary(landing: list[int]) -> dict[str, Any]:
        return {
            "belt_speed_mps": 0.3,
            "seed": 1,
            "sim_seconds": 60.0,
            "real_time_factor": 1.0,
            "complete": True,
            "scores": {
                "picked": 4,
                "placed_correct": 3,
                "processed": 5,
                "missed": 1,
                "miss_rate": 0.2,
            },
            "tracking": {
                "tracking_time_4mm_mean_s": 0.7,
                "tracking_time_4mm_p95_s": 0.9,
                "pursuits": 4,
                "unsettled": 0,
            },
            "landing_in_bins": landing,
        }

    rows = []
    for landing in ([], [17]):
        folder = tmp_path / f"ep{len(landing)}"
        (folder / "twin").mkdir(parents=True)
        (folder / "twin" / "summary.json").write_text(json.dumps(summary(landing)))
        (folder / "twin" / "events.jsonl").write_text("")
        pick = {"completed": 4, "aborted": {}, "untargeted": {"too_wide": 2}}
        (folder / "controller.json").write_text(json.dumps({"pick": pick}))
        rows.append(episode_metrics(folder, "lockstep"))
    assert (rows[0]["targeted"], rows[0]["success_rate"]) == (4, 0.75)
    assert (rows[1]["targeted"], rows[1]["success_rate"]) == (3, 1.0)
    assert rows[1]["untargeted"] == {"too_wide": 2}
