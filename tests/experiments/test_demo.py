"""``cdw-twin demo`` end to end (short): the single-station speeds, then the line, the line's
table per station and for the line, and the report that includes it."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

LINE_STANDIN = Path(__file__).resolve().parent / "cells" / "line_standin.yaml"


@pytest.mark.slow
def test_the_demo_runs_the_line_after_the_speeds_and_prints_its_table(tmp_path: Path) -> None:
    for module in ("rclpy", "cdw_interfaces"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed in this venv")
    scenario = tmp_path / "line.yaml"
    scenario.write_text(
        f"name: line\ncell: {LINE_STANDIN}\nsystem: {{belt_speed_mps: 0.4, prefill_m: 4.0}}\n",
        encoding="utf-8",
    )
    out = tmp_path / "demo"
    cmd = [sys.executable, "-m", "twin.cli", "demo", "--out", str(out), "--images", "4"]
    cmd += ["--seconds", "3", "--line-seconds", "4", "--line-scenario", str(scenario)]
    cmd += ["--camera-seconds", "2"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=400, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    text = done.stdout
    assert text.index("closed loop at 0.6 m/s") < text.index("the line (line.yaml), 4 s")
    table = text[text.index("The line: cell line_standin, 3 stations, 0.4 m/s, 4 s") :]
    lines = table.splitlines()
    assert lines[1].split() == ["station", "picks", "picks/min", "recovery", "success", "miss"]
    rows = [line.split() for line in lines[3:7]]
    assert [r[0] for r in rows] == ["first", "second", "third", "line"]
    (episode,) = json.loads((out / "runs" / "line" / "episodes.json").read_text("utf-8"))
    assert rows[3][1:] == [
        str(episode["picked"]),
        f"{episode['pick_throughput_per_min']:.1f}",
        f"{episode['recovery_rate']:.2f}",
        f"{episode['success_rate']:.2f}",
        f"{episode['miss_rate']:.2f}",
    ]
    assert rows[0][1] == str(episode["stations"]["first"]["picked"])
    page = (out / "report" / "report.html").read_text(encoding="utf-8")
    assert "<td>line_standin</td>" in page
    assert 'id="per-station"' in page
    assert 'id="fig-recovery_stations"' in page

    # the camera against the oracle: both rows, the camera's scores only on its own, the frame
    table = text[text.index("The camera against the oracle: reference cell, 0.4 m/s, 2 s") :]
    lines = table.splitlines()
    assert lines[1].split()[:2] == ["perception", "picks"]
    camera, oracle = (line.split() for line in lines[3:5])
    assert (camera[0], oracle[0]) == ("camera", "oracle")
    (row,) = json.loads((out / "runs" / "camera" / "episodes.json").read_text("utf-8"))
    assert camera[5] == f"{row['perception_recall']:.3f}"
    assert oracle[5:9] == ["-", "-", "-", "-"]
    frame = out / "camera_frame.png"
    assert f"a camera frame with its detections: {frame}" in text
    from PIL import Image

    from interfaces.cell import load_cell

    spec = load_cell("default").cameras[0]
    with Image.open(frame) as image:
        assert image.size == (spec.width_px, spec.height_px)
    assert 'id="perception"' in page
