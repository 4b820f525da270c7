"""The wrapper refuses bad parameter, input and step values itself, naming variable and value.

Every refusal happens before the FMU is called (its logger stays silent), so a third party's FMU
that checks nothing is protected too, and the drive keeps working after a refused call.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from twin.belt_drive import INT32_MAX, INT32_MIN, MAX_STEP_S, BeltDrive
from twin.errors import FmuError


def _invalid(name: str, value: object) -> str:
    return re.escape(f"{name} = {value!r} is invalid")


@pytest.mark.parametrize("version", [3, 2])
@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("drum_radius_m", "0.1"),
        ("drum_radius_m", None),
        ("drum_radius_m", True),
        ("drum_radius_m", [0.1]),
        ("perturbation_seed", "5"),
        ("perturbation_seed", None),
        ("perturbation_seed", False),
        ("perturbation_seed", 1.5),
    ],
)
def test_non_numeric_parameter_is_refused(
    fmus: dict[int, Path], version: int, name: str, value: object
) -> None:
    with pytest.raises(FmuError, match=rf"parameter {_invalid(repr(name), value)}: "):
        BeltDrive(fmus[version], parameters={name: value})  # type: ignore[dict-item]


@pytest.mark.parametrize("version", [3, 2])
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 10**400])
def test_non_finite_float_parameter_is_refused_by_the_wrapper(
    fmus: dict[int, Path], version: int, value: float
) -> None:
    with pytest.raises(FmuError, match=rf"parameter {_invalid(repr('current_limit_A'), value)}"):
        BeltDrive(fmus[version], parameters={"current_limit_A": value})


@pytest.mark.parametrize("version", [3, 2])
@pytest.mark.parametrize("value", [INT32_MAX + 1, INT32_MIN - 1, 2**32 + 1, -(2**63)])
def test_int32_parameter_out_of_range_is_refused_not_wrapped(
    fmus: dict[int, Path], version: int, value: int
) -> None:
    pattern = rf"parameter {_invalid(repr('perturbation_seed'), value)}: outside the Int32 range"
    with pytest.raises(FmuError, match=pattern):
        BeltDrive(fmus[version], parameters={"perturbation_seed": value})


@pytest.mark.parametrize("version", [3, 2])
def test_int32_range_ends_and_numpy_scalars_are_accepted(
    fmus: dict[int, Path], version: int
) -> None:
    noisy = {"perturbation_std_N": 30.0}

    def speeds(seed: object) -> list[float]:
        params = {**noisy, "perturbation_seed": seed}
        with BeltDrive(fmus[version], parameters=params) as drive:  # type: ignore[arg-type]
            return [drive.step(0.01, 0.5, 10.0).belt_speed_mps for _ in range(50)]

    top = speeds(INT32_MAX)
    assert speeds(np.int64(INT32_MAX)) == top
    assert speeds(float(INT32_MAX)) == top
    assert speeds(0) != top
    with BeltDrive(fmus[version], parameters={"drum_radius_m": np.float32(0.125)}) as drive:
        assert drive.step(0.1, 0.5, 0.0).belt_speed_mps > 0.0


@pytest.mark.parametrize("version", [3, 2])
@pytest.mark.parametrize(
    ("setpoint", "load"),
    [
        ("0.5", 0.0),
        (None, 0.0),
        (True, 0.0),
        (math.nan, 0.0),
        (0.5, None),
        (0.5, "heavy"),
        (0.5, math.inf),
        (0.5, np.float64(math.nan)),
    ],
)
def test_bad_input_is_refused_before_the_fmu_and_the_drive_goes_on(
    fmus: dict[int, Path], version: int, setpoint: object, load: object
) -> None:
    bad_setpoint = setpoint != 0.5
    name = "speed_setpoint_mps" if bad_setpoint else "load_mass_kg"
    value = setpoint if bad_setpoint else load
    with BeltDrive(fmus[version]) as drive:
        before = drive.step(0.01, 0.5, 5.0)
        with pytest.raises(FmuError, match=rf"input {_invalid(name, value)}"):
            drive.step(0.01, setpoint, load)  # type: ignore[arg-type]
        assert drive.messages == []
        assert drive.state == before
        after = drive.step(0.01, 0.5, np.float64(5.0))
    assert after.time_s == pytest.approx(0.02)
    assert after.belt_speed_mps > before.belt_speed_mps


@pytest.mark.parametrize("version", [3, 2])
@pytest.mark.parametrize(
    "dt_s", [MAX_STEP_S * 1.0001, 3600.0, 1e9, 0.0, -0.01, math.nan, math.inf, True, "0.01", None]
)
def test_step_size_outside_0_to_max_is_refused(
    fmus: dict[int, Path], version: int, dt_s: object
) -> None:
    with BeltDrive(fmus[version]) as drive:
        with pytest.raises(FmuError, match=rf"step {_invalid('dt_s', dt_s)}: .*\(0, 1\.0\] s"):
            drive.step(dt_s, 0.5, 0.0)  # type: ignore[arg-type]
        assert drive.messages == []
        assert drive.state.time_s == 0.0
        state = drive.step(MAX_STEP_S, 0.3, 0.0)  # the 0.6 s ramp and the settling fit in 1 s
    assert state.time_s == MAX_STEP_S
    assert state.belt_speed_mps == pytest.approx(0.3, abs=0.01)


@pytest.mark.parametrize("start", ["1.0", None, math.nan, math.inf])
def test_non_finite_or_non_numeric_start_time_is_refused(
    fmus: dict[int, Path], start: object
) -> None:
    with pytest.raises(FmuError, match=rf"start_time_s = {re.escape(repr(start))} is invalid"):
        BeltDrive(fmus[3], start_time_s=start)  # type: ignore[arg-type]
