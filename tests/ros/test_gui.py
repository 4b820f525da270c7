"""``--gui``: PyBullet's window on a real display (Xvfb), and a clear error where there is none."""

from __future__ import annotations

import json
import os
import selectors
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

WINDOW_OPEN = "PyBullet window open"
"""What the twin node prints once its window shows the cell."""
START_TIMEOUT_S = 240.0
"""Every PyBullet call goes through the window's thread: slow on a loaded machine without a GPU
(a short episode, few objects)."""


@pytest.fixture
def xvfb() -> Iterator[str]:
    """A private X display (``:N``, a number Xvfb picks itself) for one test; without Xvfb
    the test skips, or fails under CI (``CI`` set), where it must run."""
    if shutil.which("Xvfb") is None:
        reason = "Xvfb is not installed (.ci/run installs the xvfb package)"
        if os.environ.get("CI"):
            pytest.fail(f"{reason}; CI is set, so the window's test may not be skipped")
        pytest.skip(reason)
    read_fd, write_fd = os.pipe()
    server = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write_fd), "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write_fd)
    try:
        with os.fdopen(read_fd) as numbers:
            number = numbers.readline().strip()
        assert number.isdigit(), f"Xvfb gave no display number (exit {server.poll()})"
        yield f":{number}"
    finally:
        server.terminate()
        server.wait(timeout=10)


def _node(env: dict[str, str], dataset: Path, out: Path, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "twin-node",
            "--dataset",
            str(dataset),
            "--out",
            str(out),
            *args,
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_for_line(proc: subprocess.Popen[str], text: str, timeout_s: float) -> None:
    assert proc.stdout is not None
    selector = selectors.DefaultSelector()
    selector.register(proc.stdout, selectors.EVENT_READ)
    deadline = time.monotonic() + timeout_s
    seen = []
    while time.monotonic() < deadline:
        if not selector.select(timeout=0.5):
            if proc.poll() is not None:
                break
            continue
        line = proc.stdout.readline()
        if not line:
            break
        seen.append(line)
        if text in line:
            return
    pytest.fail(f"no {text!r} within {timeout_s} s; output {''.join(seen)!r}")


@pytest.mark.slow
@pytest.mark.usefixtures("require_interfaces")
def test_the_window_shows_the_cell(
    ros_env: dict[str, str], builtin_meshes: Path, tmp_path: Path, xvfb: str
) -> None:
    from PIL import ImageGrab

    before = ImageGrab.grab(xdisplay=xvfb)
    assert len(np.unique(np.asarray(before.convert("RGB")).reshape(-1, 3), axis=0)) == 1
    out = tmp_path / "ep"
    env = {**ros_env, "DISPLAY": xvfb}
    proc = _node(
        env,
        builtin_meshes,
        out,
        "--gui",
        "--mode",
        "realtime",
        "--duration",
        "2.0",
        "--prefill",
        "0.8",
        "--objects",
        "8",
    )
    try:
        _wait_for_line(proc, WINDOW_OPEN, START_TIMEOUT_S)
        time.sleep(0.5)  # a few frames drawn; the episode (2 s sim) is still running
        shot = ImageGrab.grab(xdisplay=xvfb)
        assert proc.poll() is None, "the episode ended before the screenshot"
        shot.save(tmp_path / "gui.png")
        _, stderr = proc.communicate(timeout=START_TIMEOUT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, stderr[-2000:]
    assert json.loads((out / "summary.json").read_text(encoding="utf-8"))["complete"] is True
    pixels = np.asarray(shot.convert("RGB")).reshape(-1, 3)
    black = int(np.count_nonzero(~pixels.any(axis=1)))
    # the window covers most of the screen, drawing the floor, the belt, the robot, the objects
    assert black < 0.5 * len(pixels), f"{black} of {len(pixels)} pixels still black"
    assert len(np.unique(pixels, axis=0)) > 200, "the window holds no rendered scene"


def test_gui_without_a_display_is_a_one_line_error(
    ros_env: dict[str, str], builtin_meshes: Path, tmp_path: Path
) -> None:
    env = {k: v for k, v in ros_env.items() if k != "DISPLAY"}
    out = tmp_path / "ep"
    proc = _node(env, builtin_meshes, out, "--gui", "--duration", "1")
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 2
    lines = [ln for ln in stderr.splitlines() if not ln.startswith("pybullet build time")]
    assert len(lines) == 1
    assert lines[0].startswith("cdw-twin: error: --gui: no display (DISPLAY is not set)")
    assert not out.exists(), "the episode started without its window"


def test_gui_on_a_display_that_cannot_be_opened_is_a_one_line_error(
    ros_env: dict[str, str], builtin_meshes: Path, tmp_path: Path
) -> None:
    env = {**ros_env, "DISPLAY": ":987"}
    out = tmp_path / "run"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "twin.cli",
            "run",
            "--dataset",
            str(builtin_meshes),
            "--out",
            str(out),
            "--gui",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 2
    lines = [ln for ln in result.stderr.splitlines() if not ln.startswith("pybullet build time")]
    assert lines == [
        "cdw-twin: error: --gui: cannot open display ':987' (DISPLAY); run without --gui"
    ]
    assert not out.exists(), "the run started without its window"
