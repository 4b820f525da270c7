"""``cdw-twin perception fit``: the camera's errors measured on the twin's renders become an
oracle's ``perception:`` block that a scenario loads, saying where it comes from."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from twin.cli import main
from twin.scenario import Scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "experiments" / "scenarios"


def test_a_camera_scenario_is_fitted_into_a_loadable_oracle(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "fit.yaml"
    camera = SCENARIOS / "camera.yaml"
    args = ["perception", "fit", str(camera), "--duration", "2", "--prefill", "1.5"]
    assert main([*args, "--out", str(out), "--json"]) == 0
    fit = json.loads(capsys.readouterr().out)
    assert fit["frames"] == 30  # 2 s at 15 Hz
    assert fit["matched"] >= 0.8 * fit["truth_in_view"] > 0
    assert 0.0005 < fit["position_noise_m"] < 0.01
    assert 0.0 <= fit["misclassification_rate"] < 0.2
    scenario_file = tmp_path / "fitted.yaml"
    scenario_file.write_text("name: fitted\n" + out.read_text(encoding="utf-8"), encoding="utf-8")
    perception = Scenario.load(scenario_file).perception
    assert perception.source == "oracle"
    assert perception.rate_hz == 15.0  # the camera's rate and latency
    assert perception.latency_s == 0.1
    assert perception.position_noise_m == pytest.approx(fit["position_noise_m"], abs=1e-5)
    assert perception.drop_rate == pytest.approx(fit["drop_rate"], abs=1e-4)
    assert str(camera) in perception.fitted_from
    assert f"{fit['matched']} of {fit['truth_in_view']} pieces" in perception.fitted_from


def test_an_oracle_scenario_cannot_be_fitted(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["perception", "fit", str(SCENARIOS / "default.yaml"), "--duration", "1"])
    assert code != 0
    err = capsys.readouterr().err
    assert "perception.source = 'oracle'" in err
    assert "needs the camera" in err
