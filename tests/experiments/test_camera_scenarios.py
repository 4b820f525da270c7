"""The camera scenarios are the default and line scenarios with the cameras as perception."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from interfaces.cell import load_cell
from interfaces.run_folder import EpisodeFolder, RunFolder, camera_frame_name
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


@pytest.fixture(scope="module")
def camera_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, float]]:
    """Two 2 s episodes of ``camera.yaml`` in process: the run folder and its means."""
    out = tmp_path_factory.mktemp("camera") / "cam"
    proc = subprocess.run(
        [
            *(sys.executable, "-m", "twin.cli", "run", str(SCENARIOS / "camera.yaml")),
            *("--transport", "inproc", "--seed", "1", "--duration", "2", "--episodes", "2"),
            *("--json", "--no-record", "--out", str(out)),
        ],
        capture_output=True,
        text=True,
        check=False,
        timeout=240,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return out, json.loads(proc.stdout)


def _summaries(out: Path) -> list[dict[str, Any]]:
    return [
        json.loads((out / f"ep00{i}" / "twin" / "summary.json").read_text("utf-8"))
        for i in range(2)
    ]


def test_a_camera_episode_writes_its_perception_scores_into_the_summary_and_the_run(
    camera_run: tuple[Path, dict[str, float]],
) -> None:
    """The camera's detections scored against ground truth reach ``summary.json`` (NaN as
    null) and the run's means (``perception_*``), as the run folder's readers take them."""
    out, means = camera_run
    perceptions = [s["perception"] for s in _summaries(out)]
    for perception in perceptions:
        assert perception["frames"] >= 28  # 15 Hz for 2 s (the last one begun is never read)
        assert 0.5 < perception["recall"] <= 1.0
        assert 0.0 < perception["precision"] <= 1.0
        assert not any(isinstance(v, float) and math.isnan(v) for v in perception.values())
    assert means["perception_recall"] == pytest.approx(sum(p["recall"] for p in perceptions) / 2)
    assert means["perception_frames"] == sum(p["frames"] for p in perceptions) / 2


def test_each_camera_episode_keeps_an_example_frame_with_its_detections(
    camera_run: tuple[Path, dict[str, float]],
) -> None:
    from PIL import Image

    out, _ = camera_run
    camera = load_cell("default").cameras[0]
    for i in range(2):
        frames = EpisodeFolder(out / f"ep00{i}").camera_frames()
        assert [f.name for f in frames] == [camera_frame_name(camera.name)]
        with Image.open(frames[0]) as image:
            assert image.size == (camera.width_px, camera.height_px)


def test_the_report_and_the_sweep_pool_the_cameras_scores(
    camera_run: tuple[Path, dict[str, float]], tmp_path: Path
) -> None:
    from experiments.report import write_report
    from experiments.sweep_pooling import pool_perception
    from interfaces.run_records import read_rows

    out, _ = camera_run
    perceptions = [s["perception"] for s in _summaries(out)]
    matched = sum(p["matched"] for p in perceptions)
    truths = sum(p["truth_instances"] for p in perceptions)

    page = write_report([out], tmp_path / "report").read_text("utf-8")
    section = page[page.index('id="perception"') : page.index('id="recovery-stations"')]
    assert f"<td>{matched / truths:.3g}</td>" in section  # recall of the pooled counts
    assert "<td>2</td>" in section  # both episodes
    frames = re.findall(r'<img src="(frames/[^"]+)"', section)
    assert len(frames) == 2
    assert all((tmp_path / "report" / f).is_file() for f in frames)

    pool = pool_perception(read_rows(RunFolder(out).episodes_json))
    assert pool is not None
    assert pool.episodes == 2
    recall = pool.wilson["recall"]
    assert (recall.successes, recall.trials) == (matched, truths)
    assert recall.ci95_low is not None
    assert recall.ci95_low < matched / truths < (recall.ci95_high or 0.0)
    assert pool.metrics["recall"].n == 2
