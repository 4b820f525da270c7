"""``cdw-twin run`` and ``sweep`` when a process dies: no orphans, failed episodes flagged.

Real runs: the runner, the twin node and the controller are separate processes, found by
their command lines (which hold the test's own ``tmp_path``) and killed with ``kill -9``.
"""

from __future__ import annotations

import contextlib
import csv
import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

LONG = "name: long\nduration_s: 30.0\nsystem: {prefill_m: 1.0}\n"


def _needs_ros() -> None:
    for module in ("rclpy", "cdw_interfaces"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed in this venv")


def _json(path: Path) -> Any:
    return json.loads(path.read_text(encoding="utf-8"))


def _processes(text: str) -> dict[int, list[str]]:
    """Live processes whose command line contains ``text``: pid -> argv."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            raw = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        argv = [a.decode(errors="replace") for a in raw.split(b"\0") if a]
        if any(text in a for a in argv):
            found[int(entry.name)] = argv
    return found


def _pid_of(text: str, subcommand: str, station: str | None = None) -> int:
    """The one live ``cdw-twin <subcommand>`` process mentioning ``text`` (and, given a
    ``station``, started with ``--station station``)."""
    pids = [
        pid
        for pid, argv in _processes(text).items()
        if subcommand in argv and (station is None or station in argv)
    ]
    assert len(pids) == 1, _processes(text)
    return pids[0]


def _kill_all(text: str) -> None:
    for pid in _processes(text):
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


def _clock_s(recording: Path) -> float:
    """The last ``/clock`` (sim s) in a recording being written (0 before the first)."""
    from experiments.offline import read_topic

    if not recording.is_file():
        return 0.0
    return max(
        (m.clock.sec + 1e-9 * m.clock.nanosec for _, m in read_topic(recording, "/clock")),
        default=0.0,
    )


def _wait(proc: subprocess.Popen[str], done: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + 90
    while not done():
        assert proc.poll() is None, f"exited {proc.returncode} before {what}"
        assert time.monotonic() < deadline, f"no {what} after 90 s"
        time.sleep(0.2)


def _stepping_with_controller(episode: Path, log_name: str = "controller") -> Callable[[], bool]:
    """The controller (``log_name``.log) is up and the lockstep twin has stepped past 1 s of
    sim time."""

    def check() -> bool:
        log = episode / f"{log_name}.log"
        return (
            log.is_file()
            and "controller up" in log.read_text(errors="replace")
            and _clock_s(episode / "recording.mcap.partial") >= 1.0
        )

    return check


def _run(*args: str | int | Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "twin.cli", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.mark.parametrize("command", ["run", "sweep"])
def test_kill_9_of_the_runner_leaves_no_process_behind(
    builtin_meshes: Path, tmp_path: Path, command: str
) -> None:
    """Its twins and controllers get SIGTERM from the kernel (a sweep starts them from worker
    threads) and stop within seconds, each saving what it had."""
    _needs_ros()
    scenario = tmp_path / "long.yaml"
    scenario.write_text(LONG, encoding="utf-8")
    if command == "run":
        out = tmp_path / "run"
        runner = _run("run", scenario, "--dataset", builtin_meshes, "--out", out)
    else:
        grid = tmp_path / "grid.yaml"
        grid.write_text(
            f"scenarios: [long.yaml]\nseeds: [0, 1]\ndataset: {builtin_meshes}\n",
            encoding="utf-8",
        )
        runner = _run("sweep", grid, "--workers", 2, "--record", "--out", tmp_path / "sweep")
        out = tmp_path / "sweep" / "long"
    try:
        _wait(runner, _stepping_with_controller(out / "ep000"), "lockstep stepping")
        children = [pid for pid in _processes(str(tmp_path)) if pid != runner.pid]
        assert len(children) >= 2  # a twin and a controller at least
        # in the runner's process group: a signal to the group reaches them all
        assert {os.getpgid(pid) for pid in children} == {os.getpgid(runner.pid)}
        runner.kill()
        runner.wait(timeout=10)
        deadline = time.monotonic() + 10
        while _processes(str(tmp_path)) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _processes(str(tmp_path)) == {}
    finally:
        if runner.poll() is None:
            runner.kill()
        _kill_all(str(tmp_path))
    # both were told to stop (SIGTERM) rather than killed: each saved what it had
    summary = _json(out / "ep000" / "twin" / "summary.json")
    assert summary["complete"] is False
    assert summary["stopped_by"] == "SIGTERM"
    assert summary["sim_seconds"] < 30.0
    assert (out / "ep000" / "controller.json").is_file()
    assert (out / "ep000" / "recording.mcap").is_file()


@pytest.mark.parametrize(
    ("victim", "station", "reason"),
    [
        pytest.param(
            "controller",
            None,
            r"controller exited with signal SIGKILL at sim (\d+\.\d) s",
            id="controller",
        ),
        pytest.param(
            "twin-node", None, r"twin exited with signal SIGKILL, no summary\.json", id="twin"
        ),
        pytest.param(
            "controller",
            "downstream",
            r"controller 'downstream' exited with signal SIGKILL at sim (\d+\.\d) s",
            id="one-of-two-controllers",
        ),
    ],
)
def test_a_process_killed_mid_episode_fails_the_episode(
    builtin_meshes: Path, tmp_path: Path, victim: str, station: str | None, reason: str
) -> None:
    """The failed episode is listed with its reason, averaged nowhere, and the run stops; in
    a cell of two stations, losing either station's controller fails it too."""
    import re

    _needs_ros()
    scenario = tmp_path / "long.yaml"
    scenario.write_text(LONG + ("cell: two_pandas\n" if station else ""), encoding="utf-8")
    out = tmp_path / "run"
    runner = _run(
        "run", scenario, "--episodes", 2, "--dataset", builtin_meshes, "--out", out, "--json"
    )
    log_name = f"controller-{station}" if station else "controller"
    try:
        _wait(runner, _stepping_with_controller(out / "ep000", log_name), "lockstep stepping")
        os.kill(_pid_of(str(out / "ep000"), victim, station), signal.SIGKILL)
        stdout, stderr = runner.communicate(timeout=60)
    finally:
        if runner.poll() is None:
            runner.kill()
        _kill_all(str(tmp_path))
    assert runner.returncode == 1, stderr[-3000:]
    assert "Traceback" not in stderr
    result = json.loads(stdout)
    run = _json(out / "run.json")
    for data in (result, run):
        assert data["complete"] is False
        assert (data["episodes"], data["failed"]) == (0, 1)
        assert data["picks"] is None if data is result else data["mean"]["picks"] is None
        assert re.fullmatch(f"episode 0 \\(seed 0\\) failed: {reason}", data["stopped"])
        assert data["failures"] == [data["stopped"]]
    rows = _json(out / "episodes.json")
    assert len(rows) == 1  # the run stopped at the failed episode
    assert (rows[0]["episode"], rows[0]["seed"], rows[0]["failed"]) == (0, 0, True)
    match = re.fullmatch(reason, rows[0]["reason"])
    assert match is not None, rows[0]["reason"]
    assert "picks" not in rows[0]
    with (out / "episodes.csv").open(encoding="utf-8") as handle:
        table = list(csv.DictReader(handle))
    assert [(r["seed"], r["failed"], r["picks"]) for r in table] == [("0", "True", "")]
    assert table[0]["reason"] == rows[0]["reason"]
    assert not (out / "ep001").exists()
    if station is not None:
        # the other station's controller was stopped, not killed: it saved its counters
        assert (out / "ep000" / "controller-upstream.json").is_file()
    if victim == "controller":
        # the runner stopped the twin at once: its summary says so, and where it was
        twin = _json(out / "ep000" / "twin" / "summary.json")
        assert twin["complete"] is False
        assert 1.0 <= twin["sim_seconds"] < 30.0
        assert match.group(1) == f"{twin['sim_seconds']:.1f}"


@pytest.mark.slow
def test_a_sweep_leaves_a_failed_episode_out_of_its_intervals(
    builtin_meshes: Path, tmp_path: Path
) -> None:
    _needs_ros()
    (tmp_path / "short.yaml").write_text(
        "name: short\nduration_s: 15.0\nsystem: {prefill_m: 1.0}\n", encoding="utf-8"
    )
    grid = tmp_path / "grid.yaml"
    grid.write_text(
        f"scenarios: [short.yaml]\nseeds: [0, 1]\ndataset: {builtin_meshes}\n", encoding="utf-8"
    )
    out = tmp_path / "sweep"
    sweep = _run("sweep", grid, "--workers", 2, "--record", "--out", out, "--json")
    try:
        _wait(sweep, _stepping_with_controller(out / "short" / "ep000"), "lockstep stepping")
        os.kill(_pid_of(str(out / "short" / "ep000"), "controller"), signal.SIGKILL)
        stdout, stderr = sweep.communicate(timeout=120)
    finally:
        if sweep.poll() is None:
            sweep.kill()
        _kill_all(str(tmp_path))
    assert sweep.returncode == 1, stderr[-3000:]
    printed = json.loads(stdout)
    data = _json(out / "sweep.json")
    assert printed["cells"] == data["cells"]
    assert data["complete"] is False
    assert (data["episodes"], data["failed"]) == (1, 1)
    (cell,) = data["cells"]
    assert cell["complete"] is False
    assert cell["failed"] == 1
    (failure,) = cell["failures"]
    assert failure.startswith("episode 0 (seed 0) failed: controller exited with signal SIGKILL")
    agg = cell["aggregate"]
    assert (agg["episodes"], agg["failed"]) == (1, 1)
    # only the seed-1 episode: its own values, no interval from one sample
    rows = _json(out / "short" / "episodes.json")
    assert [(r["seed"], r["failed"]) for r in rows] == [(0, True), (1, False)]
    assert agg["metrics"]["picked"] == {
        "mean": float(rows[1]["picked"]),
        "ci95_low": None,
        "ci95_high": None,
        "n": 1,
    }
    assert agg["wilson"]["miss_rate"]["trials"] == rows[1]["processed"]
    run = _json(out / "short" / "run.json")
    assert (run["episodes"], run["failed"], run["failures"]) == (1, 1, [failure])
    assert run["mean"]["picks"] == rows[1]["picks"]
    with (out / "sweep.csv").open(encoding="utf-8") as handle:
        (row,) = csv.DictReader(handle)
    assert (row["episodes"], row["failed"]) == ("1", "1")
