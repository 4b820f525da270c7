"""A belt drive built by another tool (pythonfmu, FMI 2.0, other variable names) runs in the twin.

``LagBelt`` (``tests/fmus/lag_belt.py``) is a first-order lag of the speed setpoint whose lag
grows with the load; :func:`tests.fmus.pythonfmu_belt.lag_belt_state` is its exact solution.
"""

from __future__ import annotations

import math
from dataclasses import fields
from pathlib import Path

import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from fmus.errors import FmuError
from tests.fmus.pythonfmu_belt import LAG_BELT_MAPPING, LAG_BELT_PARAMETERS, lag_belt_state
from twin.belt_drive import BeltDrive, VariableMapping

DT_S = 1 / 240


def _mapping() -> VariableMapping:
    return VariableMapping(**LAG_BELT_MAPPING)


def test_pythonfmu_builds_a_valid_fmi2_drive_with_its_own_names(
    lag_belt_fmu: Path, fmus: dict[int, Path]
) -> None:
    description = read_model_description(str(lag_belt_fmu))
    assert description.fmiVersion == "2.0"
    assert description.generationTool.startswith("PythonFMU")
    assert description.coSimulation is not None
    assert description.modelExchange is None
    names = {v.name: v.causality for v in description.modelVariables}
    assert names == {
        "v_set": "input",
        "m_load": "input",
        "v_belt": "output",
        "x_belt": "output",
        "T_lag": "parameter",
        "m_belt": "parameter",
    }
    default = VariableMapping()
    ours = {getattr(default, field.name) for field in fields(VariableMapping)} - {None}
    assert not ours & set(names)
    assert validate_fmu(str(lag_belt_fmu)) == []
    # ours are built as FMI 3.0 and FMI 2.0 from one source (fmus/build.py)
    assert read_model_description(str(fmus[3])).fmiVersion == "3.0"
    assert read_model_description(str(fmus[2])).fmiVersion == "2.0"


def test_belt_drive_cosimulates_the_third_party_drive(lag_belt_fmu: Path) -> None:
    lag_s = LAG_BELT_PARAMETERS["T_lag"]
    with BeltDrive(lag_belt_fmu, mapping=_mapping()) as drive:
        assert drive.fmi_version == 2
        assert (drive.state.belt_speed_mps, drive.state.belt_position_m) == (0.0, 0.0)
        # from rest towards 0.5 m/s without load: the lag is T_lag
        for k in range(1, 241):
            state = drive.step(DT_S, 0.5, 0.0)
            speed, distance = lag_belt_state(k * DT_S, 0.5, lag_s=lag_s)
            assert state.belt_speed_mps == pytest.approx(speed, rel=1e-9, abs=1e-12)
            assert state.belt_position_m == pytest.approx(distance, rel=1e-9, abs=1e-12)
        assert state.time_s == pytest.approx(1.0)
        assert 0.49 < state.belt_speed_mps < 0.5
        assert math.isnan(state.motor_torque_Nm)
        assert math.isnan(state.motor_current_A)
        # down to 0.2 m/s carrying as much as the belt weighs: the lag doubles
        v1, x1 = state.belt_speed_mps, state.belt_position_m
        load_kg = LAG_BELT_PARAMETERS["m_belt"]
        for _ in range(120):
            state = drive.step(DT_S, 0.2, load_kg)
        speed, distance = lag_belt_state(120 * DT_S, 0.2, v0_mps=v1, lag_s=2.0 * lag_s)
        assert state.belt_speed_mps == pytest.approx(speed, rel=1e-9)
        assert state.belt_position_m == pytest.approx(x1 + distance, rel=1e-9)
        unloaded, _ = lag_belt_state(120 * DT_S, 0.2, v0_mps=v1, lag_s=lag_s)
        assert state.belt_speed_mps > unloaded + 0.05  # the load slows the change down


def test_parameters_and_mapping_use_the_drives_own_names(lag_belt_fmu: Path) -> None:
    with BeltDrive(lag_belt_fmu, mapping=_mapping(), parameters={"T_lag": 0.1}) as drive:
        for _ in range(72):
            state = drive.step(DT_S, 0.4, 0.0)
    speed, _ = lag_belt_state(72 * DT_S, 0.4, lag_s=0.1)
    assert state.belt_speed_mps == pytest.approx(speed, rel=1e-9)
    with pytest.raises(FmuError, match=r"LagBelt\.fmu: parameter 'load_mass_kg' is not a variable"):
        BeltDrive(lag_belt_fmu, mapping=_mapping(), parameters={"load_mass_kg": 1.0})
    with pytest.raises(
        FmuError, match=r"mapping field 'speed_setpoint' names variable 'speed_setpoint_mps'"
    ):
        BeltDrive(lag_belt_fmu)  # our default names: the mapping is needed
