"""A twin node stopped early (Ctrl-C, SIGTERM, ``kill -9``) keeps its episode folder.

The reference for the event log is the same scenario stepped in this process without a
controller: the node without a controller receives no command, so its events are the same,
step for step.
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

ARGS = ("--mode", "realtime", "--speed", "0.4", "--prefill", "1.2", "--objects", "8", "--seed", "4")


def _twin(
    env: dict[str, str], dataset: Path, out: Path, duration_s: float
) -> subprocess.Popen[bytes]:
    cmd = [
        sys.executable,
        "-m",
        "twin.cli",
        "twin-node",
        "--dataset",
        str(dataset),
        "--duration",
        str(duration_s),
        "--out",
        str(out),
        "--record",
        str(out / "recording.mcap"),
        *ARGS,
    ]
    return subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def _wait_for_events(proc: subprocess.Popen[bytes], events: Path, timeout_s: float = 90) -> None:
    """Until the streamed ``events.jsonl`` holds a line (the node is stepping)."""
    deadline = time.monotonic() + timeout_s
    while not (events.is_file() and events.read_text(encoding="utf-8").strip()):
        assert proc.poll() is None, proc.communicate()[1].decode()[-3000:]
        assert time.monotonic() < deadline, f"no event in {events} after {timeout_s} s"
        time.sleep(0.1)


def _clock_s(recording: Path) -> float:
    """The last ``/clock`` (sim s) in a recording that is being written (0 before the first)."""
    from experiments.offline import read_topic

    if not recording.is_file():
        return 0.0
    return max(
        (m.clock.sec + 1e-9 * m.clock.nanosec for _, m in read_topic(recording, "/clock")),
        default=0.0,
    )


def _wait_for_sim_time(proc: subprocess.Popen[bytes], out: Path, sim_s: float) -> None:
    """Until the node's recording (flushed every 0.5 s) shows ``/clock`` past ``sim_s``."""
    deadline = time.monotonic() + 60
    while _clock_s(out / "recording.mcap.partial") < sim_s:
        assert proc.poll() is None, proc.communicate()[1].decode()[-3000:]
        assert time.monotonic() < deadline, f"the node did not reach sim {sim_s} s"
        time.sleep(0.2)


def _reference_lines(dataset: Path, duration_s: float, steps: int) -> list[str]:
    """``events.jsonl`` lines of the first ``steps`` steps, stepped in this process."""
    from twin.cmd_node import build_scenario, spawn_judge
    from twin.sim import Twin

    args = argparse.Namespace(
        scenario=None,
        dataset=dataset,
        speed=0.4,
        duration=duration_s,
        seed=4,
        objects=8,
        prefill=1.2,
        cell=None,
    )
    scenario, _, cell = build_scenario(args)
    lines: list[str] = []
    sink = lines.append
    with Twin(
        scenario, dataset_dir=dataset, cell=cell, event_sink=lambda e: sink(e.to_json())
    ) as twin:
        twin.spawn_judge = spawn_judge(args, scenario, cell)
        twin.reset()
        for _ in range(steps):
            twin.advance()
        assert lines == [e.to_json() for e in twin.events]
    return [line + "\n" for line in lines]


def _json(path: Path) -> Any:
    return json.loads(path.read_text(encoding="utf-8"))


@pytest.mark.usefixtures("require_interfaces")
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_stop_signal_writes_the_episode_folder_and_exits_130(
    ros_env: dict[str, str], builtin_meshes: Path, tmp_path: Path, signum: signal.Signals
) -> None:
    out = tmp_path / "ep"
    twin = _twin(ros_env, builtin_meshes, out, 60.0)
    try:
        _wait_for_events(twin, out / "events.jsonl")
        _wait_for_sim_time(twin, out, 2.0)
        assert _json(out / "status.json")["state"] == "running"
        assert not (out / "summary.json").exists()
        twin.send_signal(signum)
        _, stderr = twin.communicate(timeout=30)
    finally:
        if twin.poll() is None:
            twin.kill()
    assert twin.returncode == 130, stderr.decode()[-3000:]
    assert b"Traceback" not in stderr
    summary = _json(out / "summary.json")
    assert summary["complete"] is False
    assert summary["stopped_by"] == signum.name
    assert 0.0 < summary["sim_seconds"] < 60.0
    status = _json(out / "status.json")
    assert (status["state"], status["complete"]) == ("interrupted", False)
    assert status["sim_seconds"] == summary["sim_seconds"]
    assert _json(out / "telemetry.json")
    from experiments.offline import is_complete

    assert is_complete(out / "recording.mcap")
    assert not (out / "recording.mcap.partial").exists()
    # every event of the steps it ran, in the log's format, nothing more
    steps = summary["final_state"]["step"]
    logged = (out / "events.jsonl").read_text(encoding="utf-8")
    reference = _reference_lines(builtin_meshes, 60.0, steps)
    assert len(reference) > 0
    assert logged == "".join(reference)
    assert summary["scores"]["missed"] == sum('"type": "missed"' in line for line in reference) > 0


@pytest.mark.usefixtures("require_interfaces")
def test_kill_9_keeps_every_event_up_to_the_last_second(
    ros_env: dict[str, str], builtin_meshes: Path, tmp_path: Path
) -> None:
    """Events are on disk within 0.5 s of wall time; the recording's last ``/clock`` (flushed
    every 0.5 s) bounds the sim time the node had reached when it was killed."""
    out = tmp_path / "ep"
    twin = _twin(ros_env, builtin_meshes, out, 60.0)
    try:
        _wait_for_events(twin, out / "events.jsonl")
        _wait_for_sim_time(twin, out, 4.0)  # objects left the window unpicked from 1.5 s on
        twin.kill()
        twin.wait(timeout=10)
    finally:
        if twin.poll() is None:
            twin.kill()
    assert not (out / "summary.json").exists()
    assert _json(out / "status.json")["state"] == "running"
    reached_s = _clock_s(out / "recording.mcap.partial")
    assert reached_s >= 4.0
    logged = (out / "events.jsonl").read_text(encoding="utf-8").splitlines(keepends=True)
    reference = _reference_lines(builtin_meshes, 60.0, round((reached_s + 2.0) * 240))
    # whole lines, in order, exactly the reference's
    assert logged == reference[: len(logged)]
    # realtime: sim time runs at most 0.25 s ahead of the wall clock (catching up), so an event
    # 1.5 sim seconds before the last recorded /clock happened more than a wall second before
    # the kill
    due = [line for line in reference if json.loads(line)["time_s"] <= reached_s - 1.5]
    assert any(json.loads(line)["type"] == "missed" for line in due)
    assert len(logged) >= len(due)
