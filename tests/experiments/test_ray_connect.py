"""``sweep --backend ray`` connects before it writes anything, within a bounded time, and says
which address failed; SIGTERM stops it while it waits; a Ray that cannot start is one line."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

SCENARIOS = Path(__file__).resolve().parents[2] / "experiments" / "scenarios"


@pytest.fixture
def grid(tmp_path: Path, builtin_meshes: Path) -> Path:
    path = tmp_path / "grid.yaml"
    path.write_text(
        f"scenarios: [{SCENARIOS / 'default.yaml'}]\nseeds: [1]\ndataset: {builtin_meshes}\n",
        encoding="utf-8",
    )
    return path


@pytest.fixture
def silent_port() -> Iterator[int]:
    """A port that accepts TCP connections and never says a word (not a Ray head)."""
    with socket.socket() as listener:
        listener.bind(("0.0.0.0", 0))  # Ray dials this machine's address, not loopback
        listener.listen(64)
        yield int(listener.getsockname()[1])


def _sweep(grid: Path, out: Path, *args: str) -> list[str]:
    return [sys.executable, "-m", "twin.cli", "sweep", str(grid), "--backend", "ray",
            "--transport", "inproc", "--out", str(out), *args]  # fmt: skip


def test_a_ray_head_that_does_not_answer_is_given_up_on_in_bounded_time(
    grid: Path, silent_port: int, tmp_path: Path
) -> None:
    out = tmp_path / "sweep"
    address = f"127.0.0.1:{silent_port}"
    t0 = time.monotonic()
    proc = subprocess.run(
        _sweep(grid, out, "--address", address, "--connect-timeout", "2"),
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert time.monotonic() - t0 < 30
    assert (
        f"cdw-twin: error: --backend ray: cannot connect to the cluster at {address}: "
        "no answer within 2 s (--connect-timeout)"
    ) in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not out.exists()  # nothing written: sweep.json never says ray when it did not run


def test_sigterm_stops_a_sweep_waiting_for_ray(
    grid: Path, silent_port: int, tmp_path: Path
) -> None:
    out = tmp_path / "sweep"
    proc = subprocess.Popen(
        _sweep(grid, out, "--address", f"127.0.0.1:{silent_port}"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        time.sleep(4.0)  # importing Ray, checking the grid, then waiting on the silent head
        assert proc.poll() is None
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == -signal.SIGTERM
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert not out.exists()


def test_a_ray_that_cannot_start_here_is_one_line(grid: Path, tmp_path: Path) -> None:
    out = tmp_path / "sweep"
    env = {**os.environ, "RAY_TMPDIR": "/proc/cdw-twin-no-such"}
    proc = subprocess.run(
        _sweep(grid, out), capture_output=True, text=True, timeout=120, check=False, env=env
    )
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("cdw-twin: error:")]
    assert len(errors) == 1
    assert errors[0].startswith("cdw-twin: error: --backend ray: cannot start a local Ray")
    assert errors[0].endswith("(RAY_TMPDIR=/proc/cdw-twin-no-such)")
    assert not out.exists()
