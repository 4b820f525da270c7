"""No run ever mixes with another, and nothing half-written looks complete: ``--out`` is
refused or replaced whole (run, sweep, report), a report is swapped in whole, and a full or
read-only disk ends a run or a sweep as failed, saying so, without a traceback."""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from matplotlib.figure import Figure

from experiments import report as report_module
from experiments.outdir import REPORT, RUN, SWEEP, holds_marker
from twin.cli import main

SCENARIOS = Path(__file__).resolve().parents[2] / "experiments" / "scenarios"
QUIET_RUN = ("--transport", "inproc", "--no-record", "--json")


def _main(*argv: str) -> int:
    try:
        return main(list(argv))
    except SystemExit as exc:
        return int(exc.code or 0)


@contextlib.contextmanager
def _tmpfs(folder: Path, size: str, *, read_only: bool = False) -> Iterator[Path]:
    """A tiny tmpfs mounted at ``folder`` (the test is skipped where mounting is refused)."""
    folder.mkdir(parents=True, exist_ok=True)
    mount = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)],
        capture_output=True,
        check=False,
    )
    if mount.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mount.stderr.decode().strip()}")
    try:
        if read_only:
            subprocess.run(["mount", "-o", "remount,ro", str(folder)], check=True)
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)


def test_a_run_never_mixes_with_an_earlier_one_in_its_out(
    tmp_path: Path, builtin_meshes: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The issue's repro: two episodes into X, then a one-episode run of another scenario into
    X. Refused (X untouched); with --replace X is replaced whole: no stale ep001 beside a
    run.json saying complete."""
    out = tmp_path / "X"
    data = ("--dataset", str(builtin_meshes))
    assert _main("run", *QUIET_RUN, "--duration", "1", "--episodes", "2", "--seed", "1",
                 "--out", str(out), *data) == 0  # fmt: skip
    assert holds_marker(out, RUN)
    first = json.loads((out / "run.json").read_text(encoding="utf-8"))
    suction = str(SCENARIOS / "suction.yaml")
    capsys.readouterr()
    assert _main("run", suction, *QUIET_RUN, "--duration", "1", "--seed", "9", "--out",
                 str(out), *data) == 2  # fmt: skip
    assert "exists and is not empty" in capsys.readouterr().err
    assert json.loads((out / "run.json").read_text(encoding="utf-8")) == first
    assert _main("run", suction, *QUIET_RUN, "--duration", "1", "--seed", "9", "--out",
                 str(out), "--replace", *data) == 0  # fmt: skip
    run = json.loads((out / "run.json").read_text(encoding="utf-8"))
    assert (run["scenario"], run["episodes"], run["complete"]) == ("suction", 1, True)
    assert sorted(p.name for p in out.glob("ep[0-9]*")) == ["ep000"]
    assert holds_marker(out, RUN)
    assert not list(tmp_path.glob(".X.old-*"))


def test_a_full_disk_ends_the_run_as_failed_and_says_so(
    tmp_path: Path, builtin_meshes: Path
) -> None:
    with _tmpfs(tmp_path / "disk", "48k") as disk:
        proc = subprocess.run(
            [sys.executable, "-m", "twin.cli", "run", *QUIET_RUN[:-1], "--duration", "3",
             "--dataset", str(builtin_meshes), "--out", str(disk / "run")],
            capture_output=True, text=True, timeout=120, check=False,
        )  # fmt: skip
        assert proc.returncode == 1, proc.stderr[-2000:]
        assert "Traceback" not in proc.stderr
        assert "No space left on device" in proc.stderr
        run = json.loads((disk / "run" / "run.json").read_text(encoding="utf-8"))
        assert run["complete"] is False
        assert run["failed"] >= 1
        assert any("No space left on device" in f or "twin exited" in f for f in run["failures"])
        assert "No space left on device" in run["stopped"]
        status = disk / "run" / "ep000" / "twin" / "status.json"
        if status.is_file():
            assert json.loads(status.read_text(encoding="utf-8"))["state"] != "running"


def test_a_full_disk_ends_the_sweep_as_failed_and_says_so(
    tmp_path: Path, builtin_meshes: Path
) -> None:
    grid = tmp_path / "grid.yaml"
    grid.write_text(
        f"scenarios: [{SCENARIOS / 'default.yaml'}]\nseeds: [1, 2]\n"
        f"overrides: {{duration_s: [1.0]}}\ndataset: {builtin_meshes}\n",
        encoding="utf-8",
    )
    with _tmpfs(tmp_path / "disk", "64k") as disk:
        proc = subprocess.run(
            [sys.executable, "-m", "twin.cli", "sweep", str(grid), "--transport", "inproc",
             "--out", str(disk / "sweep")],
            capture_output=True, text=True, timeout=120, check=False,
        )  # fmt: skip
        assert proc.returncode == 1, proc.stderr[-2000:]
        assert "Traceback" not in proc.stderr
        sweep = json.loads((disk / "sweep" / "sweep.json").read_text(encoding="utf-8"))
        assert sweep["complete"] is False
        assert "cannot write the sweep's tables: No space left on device" in sweep["stopped"]


@pytest.mark.parametrize("command", ["run", "sweep", "report"])
def test_a_read_only_out_is_one_line(
    command: str, tmp_path: Path, builtin_meshes: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    grid = tmp_path / "grid.yaml"
    grid.write_text(f"scenarios: [{SCENARIOS / 'default.yaml'}]\nseeds: [1]\n", encoding="utf-8")
    (tmp_path / "runs" / "r").mkdir(parents=True)
    (tmp_path / "runs" / "r" / "run.json").write_text("{}", encoding="utf-8")
    argv = {
        "run": ["run", *QUIET_RUN, "--dataset", str(builtin_meshes)],
        "sweep": ["sweep", str(grid), "--transport", "inproc", "--dataset", str(builtin_meshes)],
        "report": ["report", str(tmp_path / "runs" / "r")],
    }[command]
    with _tmpfs(tmp_path / "ro", "64k", read_only=True) as ro:
        assert _main(*argv, "--out", str(ro / "out")) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"cdw-twin: error: --out {ro / 'out'}: cannot create"), err
    assert "Read-only file system" in err
    assert "\n" not in err


def _report_files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


def test_a_report_is_swapped_in_whole_and_an_interrupted_one_leaves_the_old(
    tmp_path: Path, builtin_meshes: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    run = tmp_path / "run"
    assert _main("run", *QUIET_RUN, "--duration", "1", "--out", str(run),
                 "--dataset", str(builtin_meshes)) == 0  # fmt: skip
    out = tmp_path / "report"
    assert _main("report", str(run), "--out", str(out)) == 0
    assert holds_marker(out, REPORT)
    (out / "stale.png").write_bytes(b"from an older report")
    before = _report_files(out)

    def interrupted(_data: report_module.RunData) -> Figure:
        raise KeyboardInterrupt

    figures = list(report_module.FIGURES)
    stem, heading, _ = figures[3]
    figures[3] = (stem, heading, interrupted)
    monkeypatch.setattr(report_module, "FIGURES", tuple(figures))
    with pytest.raises(KeyboardInterrupt):
        report_module.write_report([run], out, replace=True)
    assert _report_files(out) == before  # the old report, whole
    assert not list(tmp_path.glob(".report.*"))  # no staging folder left behind
    monkeypatch.undo()
    assert _main("report", str(run), "--out", str(out), "--replace") == 0
    assert not (out / "stale.png").exists()  # replaced whole
    assert (out / "report.html").is_file()


def test_replace_takes_only_an_output_of_the_same_command(tmp_path: Path) -> None:
    from experiments.outdir import OutputError, check_output, fresh_output

    sweep = fresh_output(tmp_path / "s", SWEEP, replace=False)
    (sweep / "sweep.json").write_text("{}", encoding="utf-8")
    with pytest.raises(OutputError, match=r"not a `cdw-twin run` output \(it has no \.cdw-run"):
        check_output(sweep, RUN, replace=True)
    again = fresh_output(sweep, SWEEP, replace=True)
    assert [p.name for p in again.iterdir()] == [".cdw-sweep"]
