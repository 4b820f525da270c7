"""``cdw-twin bench camera``: a very short camera and oracle pair prints its figures as JSON."""

from __future__ import annotations

import argparse
import json

import pytest

from experiments.bench_camera import configure, run


def test_a_one_second_pair_prints_both_sources_and_their_ratio(
    capsys: pytest.CaptureFixture[str],
) -> None:
    parser = argparse.ArgumentParser()
    configure(parser)
    assert run(parser.parse_args(["--duration", "1", "--rounds", "1", "--json"])) == 0
    result = json.loads(capsys.readouterr().out)
    for source in ("camera", "oracle"):
        assert result[source]["real_time_factor"] > 0.0
        assert result[source]["cpu_s_per_sim_s"] > 0.0
    # the camera renders and detects on top of everything the oracle episode does
    assert result["camera"]["cpu_s_per_sim_s"] > result["oracle"]["cpu_s_per_sim_s"]
    ratio = result["camera"]["real_time_factor"] / result["oracle"]["real_time_factor"]
    assert result["ratio"] == pytest.approx(ratio, abs=0.002)
    assert result["scenarios"] == [
        "experiments/scenarios/camera.yaml",
        "experiments/scenarios/default.yaml",
    ]
