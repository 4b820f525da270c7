"""A belt-drive FMU built by another tool (pythonfmu), chosen in the cell file with its own
variable names mapped there, drives the belt of a closed-loop episode."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.fmus.pythonfmu_belt import LAG_BELT_MAPPING, build_belt_fmu, pythonfmu_unavailable

SCENARIO = """\
name: third_party_drive
cell: cell.yaml
duration_s: 6.0
system: {belt_speed_mps: 0.4}
"""


def _cell_text(fmu: Path) -> str:
    mapping = "\n".join(
        f"    {role}: {'null' if name is None else name}" for role, name in LAG_BELT_MAPPING.items()
    )
    return f"""\
name: lag_belt_cell
drive:
  fmu: {fmu}
  mapping:
{mapping}
  perturbation: null
  parameters: {{T_lag: 0.5}}
stations:
  - name: panda
    robot: panda
    tool: panda_hand
    bins:
      - {{class_name: concrete, centre_x_m: -0.60, centre_y_m: 0.07}}
      - {{class_name: brick, centre_x_m: -0.33, centre_y_m: 0.07}}
      - {{class_name: wood, centre_x_m: 0.33, centre_y_m: 0.07}}
      - {{class_name: rubber, centre_x_m: 0.60, centre_y_m: 0.07}}
"""


@pytest.mark.slow
def test_a_third_party_fmu_named_in_the_cell_file_drives_an_episode(
    builtin_meshes: Path, tmp_path: Path
) -> None:
    reason = pythonfmu_unavailable()
    if reason:
        pytest.skip(reason)
    for module in ("rclpy", "cdw_interfaces"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed in this venv")
    fmu = build_belt_fmu(tmp_path / "fmu")
    (tmp_path / "cell.yaml").write_text(_cell_text(fmu), encoding="utf-8")
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(SCENARIO, encoding="utf-8")
    out = tmp_path / "run"
    done = subprocess.run(
        [
            *(sys.executable, "-m", "twin.cli", "run", str(scenario)),
            *("--dataset", str(builtin_meshes), "--out", str(out), "--json"),
        ],
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    telemetry = json.loads((out / "ep000" / "twin" / "telemetry.json").read_text("utf-8"))
    belt = telemetry["belt"]
    # LagBelt: a first-order lag with T_lag = 0.5 s (set in the cell file; its default is
    # 0.25 s) lengthened by the load: after 0.5 s the belt is well short of the setpoint, after
    # 6 s on it
    at = dict(zip(belt["sim_s"], belt["speed_mps"], strict=True))
    half_s = min(at, key=lambda t: abs(t - 0.5))
    assert 0.1 < at[half_s] < 0.4 * (1 - 0.3)
    assert belt["speed_mps"][-1] == pytest.approx(0.4, abs=0.01)
    summary = json.loads((out / "ep000" / "twin" / "summary.json").read_text("utf-8"))
    assert summary["complete"] is True
    assert summary["scores"]["spawned"] > 0  # objects enter as the FMU's belt position grows
    copy = (out / "cell.yaml").read_text(encoding="utf-8")
    assert str(fmu) in copy
    assert "v_set" in copy
