"""The twin's wrapper: state, mapping of a drive without torque/current, FMI 2 and 3 alike."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from twin.belt_drive import BeltDrive, BeltState, VariableMapping


@pytest.mark.parametrize("version", [3, 2])
def test_state_tracks_steps(fmus: dict[int, Path], version: int) -> None:
    with BeltDrive(fmus[version], start_time_s=2.0) as drive:
        assert drive.state.time_s == 2.0
        assert drive.state.belt_speed_mps == 0.0
        for _ in range(480):
            state = drive.step(1 / 240, 0.5, 5.0)
        assert state is drive.state
        assert state.time_s == pytest.approx(4.0)
        assert state.belt_speed_mps == pytest.approx(0.5, abs=5e-3)
        # 0.25 m during the 1 s ramp to 0.5 m/s, 0.5 m in the next second, less the belt's lag
        assert 0.65 < state.belt_position_m < 0.75
        assert state.motor_torque_Nm == pytest.approx(0.7 * state.motor_current_A)


def test_minimal_mapping_for_a_third_party_style_drive(fmus: dict[int, Path]) -> None:
    mapping = VariableMapping(load_mass=None, motor_torque=None, motor_current=None)
    with BeltDrive(fmus[2], mapping=mapping) as drive:
        state = drive.step(0.05, 0.4, 1000.0)
    assert isinstance(state, BeltState)
    assert math.isnan(state.motor_torque_Nm)
    assert math.isnan(state.motor_current_A)
    assert state.belt_speed_mps > 0.0


def test_close_is_idempotent(fmus: dict[int, Path]) -> None:
    drive = BeltDrive(fmus[3])
    drive.close()
    drive.close()
