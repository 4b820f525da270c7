"""A dataset with its own class names runs end to end through the command line: ``cdw-twin
meshgen`` with a class table, ``cdw-twin run`` with a cell file whose bins sort those classes,
scores per class in the run's tables."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from twin_helpers import box_px

NAMES = ("bricks", "concrete", "tiles")
CLASS_TABLE = """\
classes:
  bricks:   {density_kg_m3: 1900, height_min_m: 0.04, height_max_m: 0.06}
  concrete: {density_kg_m3: 2400, height_min_m: 0.04, height_max_m: 0.06}
  tiles:    {density_kg_m3: 2000, height_min_m: 0.03, height_max_m: 0.04}
"""
CELL = """\
name: three_classes
stations:
  - name: panda
    robot: panda
    tool: panda_hand
    bins:
      - {class_name: bricks, centre_x_m: -0.60, centre_y_m: 0.07}
      - {class_name: concrete, centre_x_m: -0.33, centre_y_m: 0.07}
      - {class_name: tiles, centre_x_m: 0.33, centre_y_m: 0.07}
"""
SCENARIO = """\
name: three_classes
dataset: meshes
cell: cell.yaml
duration_s: 25.0
system: {belt_speed_mps: 0.2, prefill_m: 1.2}
"""


def _cli(*args: str | Path) -> list[str]:
    return [sys.executable, "-m", "twin.cli", *map(str, args)]


def _json(path: Path) -> Any:
    return json.loads(path.read_text(encoding="utf-8"))


def _write_dataset(root: Path) -> Path:
    """Six 1000 x 1000 px images (0.6 mm per pixel) of three small objects each, one per
    class, every one narrow enough for the Panda's hand."""
    data = root / "data"
    (data / "labels").mkdir(parents=True)
    names = "".join(f"  {i}: {name}\n" for i, name in enumerate(NAMES))
    (data / "data.yaml").write_text(f"names:\n{names}", encoding="utf-8")
    for image in range(6):
        lines = []
        for cls in range(3):
            points = box_px(250 + 250 * cls, 300 + 60 * image, 90, 70)
            coords = " ".join(f"{u / 1000:.6f} {v / 1000:.6f}" for u, v in points)
            lines.append(f"{cls} {coords}")
        (data / "labels" / f"img{image}.txt").write_text("\n".join(lines) + "\n", "utf-8")
    return data


@pytest.mark.slow
def test_a_dataset_with_its_own_class_names_is_meshed_run_and_scored_per_class(
    tmp_path: Path,
) -> None:
    for module in ("rclpy", "cdw_interfaces"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed in this venv")
    data = _write_dataset(tmp_path)
    (tmp_path / "classes.yaml").write_text(CLASS_TABLE, encoding="utf-8")
    meshed = subprocess.run(
        _cli(
            "meshgen",
            data,
            "--out",
            tmp_path / "meshes",
            "--image-size",
            "1000x1000",
            "--classes",
            tmp_path / "classes.yaml",
            "--json",
        ),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert meshed.returncode == 0, meshed.stderr
    assert json.loads(meshed.stdout)["objects"] == 18
    (tmp_path / "cell.yaml").write_text(CELL, encoding="utf-8")
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(SCENARIO, encoding="utf-8")
    out = tmp_path / "run"
    done = subprocess.run(
        _cli("run", scenario, "--out", out, "--json"),
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    run = _json(out / "run.json")
    assert set(run["mean_by_class"]) == set(NAMES)
    events = [
        json.loads(line)
        for line in (out / "ep000" / "twin" / "events.jsonl").read_text("utf-8").splitlines()
    ]
    spawned = {e["class_name"] for e in events if e["type"] == "spawned"}
    assert spawned == set(NAMES)
    placed = [e for e in events if e["type"] == "placed_in_bin"]
    assert placed, "the Panda sorted nothing in 25 s"
    for event in placed:
        assert event["data"]["bin"] in NAMES
        assert event["data"]["correct"] == (event["data"]["bin"] == event["class_name"])
    (row,) = _json(out / "episodes.json")
    for name in NAMES:
        block = row["classes"][name]
        assert block["spawned"] == sum(
            1 for e in events if e["type"] == "spawned" and e["class_name"] == name
        )
    assert sum(row["classes"][n]["placed_correct"] for n in NAMES) == row["placed_correct"]
    assert row["placed_correct"] >= 1
    copy = (out / "cell.yaml").read_text(encoding="utf-8")
    assert all(f"class_name: {name}" in copy for name in NAMES)
