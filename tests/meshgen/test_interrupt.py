"""Ctrl-C / SIGTERM in the middle of ``cdw-twin meshgen --json``: partial summary, exit 130,
nothing written that looks complete, an earlier output left as it was.

The runs are real ``cdw-twin`` processes interrupted while they are meshing a generated dataset
large enough to take a second or more.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from meshgen.config import MeshgenConfig
from meshgen.interrupts import deferred_interrupts
from meshgen.pipeline import CHUNK_IMAGES, mesh_dataset
from meshgen.sample import write_sample

SAMPLE_IMAGES = 32
COPIES = 120
IMAGES = SAMPLE_IMAGES * COPIES
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def big_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A dataset of ``IMAGES`` images (meshing it takes over ten seconds): a generated sample
    whose label and image files are linked under new stems (cheaper than generating them)."""
    folder = tmp_path_factory.mktemp("big") / "data"
    write_sample(folder, images=SAMPLE_IMAGES, seed=11)
    for label in sorted((folder / "labels").glob("*.txt")):
        photo = folder / "images" / f"{label.stem}.jpg"
        for k in range(1, COPIES):
            os.link(label, folder / "labels" / f"{label.stem}_c{k:03d}.txt")
            os.link(photo, folder / "images" / f"{label.stem}_c{k:03d}.jpg")
    return folder


def _default_stop_signals() -> None:
    """In the child: SIGINT and SIGTERM at their defaults, as in a terminal, even when this
    test session was started in the background (a shell starts background jobs with SIGINT
    ignored, and an ignored signal is inherited across exec)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_DFL)


def _run_and_interrupt(
    dataset: Path, out: Path, sig: int, *, workers: int, whole_group: bool
) -> tuple[int, str, str]:
    """Start ``cdw-twin meshgen --json``, send ``sig`` once some batches are done, wait."""
    command = [sys.executable, "-m", "twin.cli", "meshgen", str(dataset), "--out", str(out)]
    command += ["--json", "--workers", str(workers)]
    proc = subprocess.Popen(
        command,
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=_default_stop_signals,  # noqa: PLW1509 (two signal() calls, no locks)
    )
    staging = out.parent / f".{out.name}.staging-{proc.pid}"
    # image folders that exist once the first batch is done (with one process the files are
    # written by a thread that lags behind the meshing; workers write their own batches)
    wanted = CHUNK_IMAGES + 1 if workers == 1 else 2 * workers * CHUNK_IMAGES + 1
    deadline = time.monotonic() + 120.0
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                done = sum(1 for p in staging.iterdir() if p.is_dir())
            except OSError:
                done = 0
            if done >= wanted:
                break
            time.sleep(0.005)
        assert proc.poll() is None, "the run ended before it could be interrupted"
        assert done < IMAGES
        if whole_group:  # what Ctrl-C in a terminal does
            os.killpg(proc.pid, sig)
        else:
            os.kill(proc.pid, sig)
        stdout, stderr = proc.communicate(timeout=120.0)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return proc.returncode, stdout, stderr


def _partial_summary(stdout: str) -> dict[str, object]:
    summary = json.loads(stdout)
    assert isinstance(summary, dict)
    assert summary["complete"] is False
    return summary


@pytest.mark.parametrize(
    ("sig", "workers", "whole_group"),
    [
        (signal.SIGINT, 1, True),
        (signal.SIGTERM, 1, False),
        (signal.SIGINT, 2, True),
    ],
    ids=["ctrl-c", "sigterm", "ctrl-c-2-workers"],
)
def test_interrupted_run_prints_partial_json_and_writes_nothing(
    big_dataset: Path, tmp_path: Path, sig: int, workers: int, whole_group: bool
) -> None:
    out = tmp_path / "out"
    code, stdout, stderr = _run_and_interrupt(
        big_dataset, out, sig, workers=workers, whole_group=whole_group
    )
    assert code == 130, stderr
    summary = _partial_summary(stdout)
    images = summary["images"]
    assert isinstance(images, int)
    assert images < IMAGES
    if workers == 1:  # batches finish in order: the first was done before the signal
        assert images >= CHUNK_IMAGES
        assert isinstance(summary["objects"], int)
        assert summary["objects"] >= images
    assert "Traceback" not in stderr
    assert stderr.strip().splitlines()[-1] == "cdw-twin: interrupted"
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no staging folder left


def test_interrupt_leaves_the_earlier_output_in_place(big_dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    small = tmp_path / "small"
    write_sample(small, images=3, seed=2)
    mesh_dataset(small, out, MeshgenConfig())
    before = {p.relative_to(out).as_posix(): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    code, stdout, _ = _run_and_interrupt(
        big_dataset, out, signal.SIGINT, workers=1, whole_group=True
    )
    assert code == 130
    _partial_summary(stdout)
    after = {p.relative_to(out).as_posix(): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "small"]


def test_deferred_interrupts_hold_ctrl_c_until_the_block_is_done() -> None:
    # Ctrl-C raises KeyboardInterrupt, as in a foreground terminal (the suite's conftest puts
    # the session's own handler back before the next test)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    handler = signal.getsignal(signal.SIGINT)
    steps: list[str] = []

    def block() -> None:
        with deferred_interrupts():
            signal.raise_signal(signal.SIGINT)
            steps.append("the block went on after the signal")

    with pytest.raises(KeyboardInterrupt):
        block()
    assert steps == ["the block went on after the signal"]
    with deferred_interrupts(redeliver=False):
        signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGTERM)
    assert signal.getsignal(signal.SIGINT) is handler
