"""The camera scenarios are the default and line scenarios with the cameras as perception."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from interfaces.cell import load_cell
from twin.scenario import Scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "experiments" / "scenarios"


def test_camera_scenarios_differ_from_theirs_only_in_perception() -> None:
    for camera, base in (("camera", "default"), ("line_camera", "line")):
        scenario = Scenario.load(SCENARIOS / f"{camera}.yaml")
        reference = Scenario.load(SCENARIOS / f"{base}.yaml")
        assert scenario.perception.source == "camera"
        assert reference.perception.source == "oracle"
        assert replace(scenario, name=base, perception=reference.perception) == reference
    line = Scenario.load(SCENARIOS / "line_camera.yaml")
    assert line.perception.rate_hz == 15.0
    assert len(load_cell(line.cell).cameras) == 4


def test_a_camera_episode_writes_its_perception_scores_into_the_summary_and_the_run(
    tmp_path: Path,
) -> None:
    """The camera's detections scored against ground truth reach ``summary.json`` (NaN as
    null) and the run's means (``perception_*``), as the run folder's readers take them."""
    import json
    import math
    import subprocess
    import sys

    out = tmp_path / "cam"
    scenario = Path(__file__).parents[2] / "experiments" / "scenarios" / "camera.yaml"
    proc = subprocess.run(
        [
            *(sys.executable, "-m", "twin.cli", "run", str(scenario), "--transport", "inproc"),
            *("--seed", "1", "--duration", "3", "--json", "--no-record", "--out", str(out)),
        ],
        capture_output=True,
        text=True,
        check=False,
        timeout=240,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    means = json.loads(proc.stdout)
    summary = json.loads((out / "ep000" / "twin" / "summary.json").read_text("utf-8"))
    perception = summary["perception"]
    assert perception["frames"] >= 30  # 15 Hz for 3 s (the first frame at 0 s)
    assert 0.5 < perception["recall"] <= 1.0
    assert 0.0 < perception["precision"] <= 1.0
    assert means["perception_recall"] == perception["recall"]
    assert means["perception_frames"] == perception["frames"]
    assert not any(isinstance(v, float) and math.isnan(v) for v in perception.values())
