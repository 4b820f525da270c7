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
