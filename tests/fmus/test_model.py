"""Belt-drive physics: independent solve_ivp check, step response, perturbation, FMI 2 == 3.

The conveyor behaviour of the defaults (ramped steps without overshoot, stops that never run
the belt backwards, the brake at standstill) is in test_conveyor.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu
from scipy.integrate import solve_ivp
from scipy.signal import lti

from twin.belt_drive import BeltDrive

DEFAULTS = {
    "Kt": 0.7, "imax": 9.0, "kp": 24.0, "ki": 168.0, "b": 0.7, "taw": 0.05, "n": 40.0, "r": 0.1,
    "jm": 2e-4, "jd": 0.3, "mb": 30.0, "c": 20.0, "fc": 50.0, "mu": 0.33, "vs": 0.01,
}  # fmt: skip
G = 9.80665
DT_240HZ = 1 / 240
NO_RAMP = {"setpoint_ramp_limit_mps2": 0.0}
"""The solve_ivp comparisons take the reference as the setpoint itself (the ramp is tested
separately); every setpoint in them is positive, so the brake opens at the first grid point
(``Kp b r > 0``) and stays open."""


def reference_rhs(setpoint: float, load: float, p: dict[str, float]):
    """Independent transcription of readme.md's running equations (brake open) for solve_ivp."""
    mass = p["jm"] * (p["n"] / p["r"]) ** 2 + p["jd"] / p["r"] ** 2 + p["mb"] + load
    coulomb = p["fc"] + p["mu"] * G * load

    def rhs(_t: float, x: np.ndarray) -> list[float]:
        v, _s, z = x
        u = p["kp"] * (p["b"] * setpoint - v) + z
        i = min(max(u, -p["imax"]), p["imax"])
        force = p["Kt"] * i * p["n"] / p["r"] - p["c"] * v - coulomb * np.tanh(v / p["vs"])
        return [force / mass, v, p["ki"] * (setpoint - v) + (i - u) / p["taw"]]

    return rhs


def run_drive(
    fmu: Path, inputs: list[tuple[float, float]], dt_s: float, **params: float
) -> np.ndarray:
    """Rows of (t, speed, position, torque, current) after each step."""
    with BeltDrive(fmu, parameters=params) as drive:
        rows = [
            (s.time_s, s.belt_speed_mps, s.belt_position_m, s.motor_torque_Nm, s.motor_current_A)
            for s in (drive.step(dt_s, sp, load) for sp, load in inputs)
        ]
    return np.array(rows)


def test_matches_independent_solve_ivp(fmus: dict[int, Path]) -> None:
    segments = [(0.8, 0.0, 120), (0.8, 50.0, 120), (0.3, 20.0, 120), (0.1, 0.0, 120)]
    inputs = [(sp, load) for sp, load, n in segments for _ in range(n)]
    fmu = run_drive(fmus[3], inputs, DT_240HZ, **NO_RAMP)
    x = np.zeros(3)
    t = 0.0
    expected = []
    for sp, load, n in segments:
        t_eval = t + DT_240HZ * np.arange(1, n + 1)
        sol = solve_ivp(reference_rhs(sp, load, DEFAULTS), (t, t_eval[-1]), x, t_eval=t_eval,
                        method="LSODA", rtol=1e-10, atol=1e-12)  # fmt: skip
        expected.append(sol.y.T)
        x, t = sol.y[:, -1], t_eval[-1]
    expected_arr = np.vstack(expected)
    # Inputs change only at communication points, which are off the 1 ms grid: the FMU applies
    # a new input from the preceding grid point (< 1 ms early), so allow 2 mm/s and 0.5 mm.
    assert np.max(np.abs(fmu[:, 1] - expected_arr[:, 0])) < 2e-3
    assert np.max(np.abs(fmu[:, 2] - expected_arr[:, 1])) < 5e-4


def test_matches_solve_ivp_tightly_on_grid(fmus: dict[int, Path]) -> None:
    fmu = run_drive(fmus[3], [(0.8, 30.0)] * 500, 1e-3, **NO_RAMP)
    sol = solve_ivp(reference_rhs(0.8, 30.0, DEFAULTS), (0, fmu[-1, 0]), np.zeros(3),
                    t_eval=fmu[:, 0], method="LSODA", rtol=1e-11, atol=1e-13)  # fmt: skip
    # RK4 at h = 1 ms: the largest error (~1.4e-5 m/s) is where the current leaves its limit
    # (a kink in the right-hand side, where RK4 loses its order)
    assert np.max(np.abs(fmu[:, 1] - sol.y[0])) < 3e-5
    assert np.max(np.abs(fmu[:, 2] - sol.y[1])) < 1e-5


def test_fmi3_and_fmi2_give_identical_results(fmus: dict[int, Path]) -> None:
    rng = np.random.default_rng(3)
    inputs = [
        (float(sp), float(m))
        for sp, m in zip(
            rng.uniform(0, 0.8, 300).repeat(4), rng.uniform(0, 60, 300).repeat(4), strict=True
        )
    ]
    params = {"perturbation_std_N": 30.0, "perturbation_seed": 11}
    a = run_drive(fmus[3], inputs, 0.003, **params)
    b = run_drive(fmus[2], inputs, 0.003, **params)
    np.testing.assert_array_equal(a, b)


def test_time_is_on_grid_not_accumulated(fmus: dict[int, Path]) -> None:
    coarse = run_drive(fmus[3], [(0.5, 10.0)] * 120, DT_240HZ)
    fine = run_drive(fmus[3], [(0.5, 10.0)] * 500, 1e-3)
    np.testing.assert_array_equal(coarse[-1, 1:], fine[-1, 1:])


def step_metrics(speed: np.ndarray, target: float, dt_s: float) -> tuple[float, float]:
    """(overshoot fraction, 2 % settling time in s)."""
    outside = np.nonzero(np.abs(speed - target) > 0.02 * target)[0]
    return (speed.max() - target) / target, (outside[-1] + 1) * dt_s


def linear_prediction(load: float, target: float, t: np.ndarray) -> np.ndarray:
    """Speed of the linearised loop: Coulomb friction is a constant force once moving."""
    p = DEFAULTS
    mass = p["jm"] * (p["n"] / p["r"]) ** 2 + p["jd"] / p["r"] ** 2 + p["mb"] + load
    kf = p["Kt"] * p["n"] / p["r"]
    system = lti([kf * p["kp"] * p["b"], kf * p["ki"]], [mass, p["c"] + kf * p["kp"], kf * p["ki"]])
    disturbance = lti([-1.0, 0.0], [mass, p["c"] + kf * p["kp"], kf * p["ki"]])
    coulomb = p["fc"] + p["mu"] * G * load
    return target * system.step(T=t)[1] + coulomb * disturbance.step(T=t)[1]


@pytest.mark.parametrize("load", [0.0, 50.0, 150.0])
def test_step_response_agrees_with_parameters(fmus: dict[int, Path], load: float) -> None:
    speed = run_drive(fmus[3], [(0.8, load)] * 1500, 1e-3, **NO_RAMP)[:, 1]
    t = 1e-3 * np.arange(1, 1501)
    overshoot, settling = step_metrics(speed, 0.8, 1e-3)
    lin_overshoot, lin_settling = step_metrics(linear_prediction(load, 0.8, t), 0.8, 1e-3)
    assert overshoot == pytest.approx(lin_overshoot, abs=0.03)
    assert settling == pytest.approx(lin_settling, rel=0.15)
    assert 0.1 < settling < 0.8
    assert abs(speed[-1] - 0.8) < 1e-3


@pytest.mark.parametrize("load", [0.0, 50.0, 150.0])
def test_speed_loop_does_not_oscillate_up_to_the_design_load(
    fmus: dict[int, Path], load: float
) -> None:
    """The gains make the loop critically damped at 150 kg and overdamped below: without the
    ramp and with the proportional part on the speed only (b = 0, no closed-loop zero) a step
    rises without overshoot, and the heavier belt rises more slowly."""
    params = {**NO_RAMP, "setpoint_weight": 0.0}
    speed = run_drive(fmus[3], [(0.8, load)] * 2000, 1e-3, **params)[:, 1]
    overshoot, settling = step_metrics(speed, 0.8, 1e-3)
    assert overshoot < 0.005
    assert settling < 0.8
    light = run_drive(fmus[3], [(0.8, 0.0)] * 2000, 1e-3, **params)[:, 1]
    assert np.argmax(speed > 0.4) >= np.argmax(light > 0.4)


def test_current_limit_is_respected(fmus: dict[int, Path]) -> None:
    free = run_drive(fmus[3], [(0.8, 100.0)] * 1000, 1e-3, **NO_RAMP)
    limited = run_drive(fmus[3], [(0.8, 100.0)] * 1000, 1e-3, current_limit_A=2.0, **NO_RAMP)
    assert np.max(np.abs(limited[:, 4])) <= 2.0
    assert np.max(np.abs(limited[:, 4])) == pytest.approx(2.0)
    np.testing.assert_allclose(limited[:, 3], 0.7 * limited[:, 4])
    assert np.max(np.abs(free[:, 4])) > 2.0
    reach = [np.argmax(run[:, 1] > 0.7) for run in (free, limited)]
    assert reach[1] > reach[0]


def test_setpoint_ramp_limits_reference_rate(fmus: dict[int, Path]) -> None:
    result = simulate_fmu(str(fmus[3]), stop_time=1.0, output_interval=0.01,
                          start_values={"speed_setpoint_mps": 0.8, "setpoint_ramp_limit_mps2": 1.0},
                          output=["speed_reference_mps", "belt_speed_mps"])  # fmt: skip
    rate = np.diff(result["speed_reference_mps"]) / 0.01
    assert np.max(rate) <= 1.0 + 1e-9
    assert result["speed_reference_mps"][50] == pytest.approx(0.5, abs=2e-3)
    assert result["speed_reference_mps"][-1] == pytest.approx(0.8)


def test_zero_amplitude_is_exactly_deterministic(fmus: dict[int, Path]) -> None:
    inputs = [(0.6, 20.0)] * 400
    base = run_drive(fmus[3], inputs, DT_240HZ)
    other_seed = run_drive(fmus[3], inputs, DT_240HZ, perturbation_std_N=0.0, perturbation_seed=99)
    np.testing.assert_array_equal(base, other_seed)
    result = simulate_fmu(str(fmus[3]), stop_time=1.0, output=["perturbation_force_N"],
                          start_values={"perturbation_seed": 5})  # fmt: skip
    assert np.all(result["perturbation_force_N"] == 0.0)


def test_seed_determinism(fmus: dict[int, Path]) -> None:
    inputs = [(0.6, 20.0)] * 400
    params = {"perturbation_std_N": 40.0, "perturbation_correlation_time_s": 0.1}
    a = run_drive(fmus[3], inputs, DT_240HZ, perturbation_seed=7, **params)
    b = run_drive(fmus[3], inputs, DT_240HZ, perturbation_seed=7, **params)
    c = run_drive(fmus[3], inputs, DT_240HZ, perturbation_seed=8, **params)
    np.testing.assert_array_equal(a, b)
    assert np.max(np.abs(a[:, 1] - c[:, 1])) > 1e-4


def test_perturbation_statistics_match_parameters(fmus: dict[int, Path]) -> None:
    std_n, tau_s, dt_s = 25.0, 0.1, 0.01
    result = simulate_fmu(str(fmus[3]), stop_time=200.0, output_interval=dt_s,
                          start_values={"perturbation_std_N": std_n,
                                        "perturbation_correlation_time_s": tau_s,
                                        "perturbation_seed": 3, "speed_setpoint_mps": 0.5},
                          output=["perturbation_force_N"])  # fmt: skip
    force = result["perturbation_force_N"]
    # about 1000 correlation times: std is known to ~3 %, the lag-1 correlation to ~1 %
    assert np.std(force) == pytest.approx(std_n, rel=0.1)
    centred = force - force.mean()
    rho = np.dot(centred[:-1], centred[1:]) / np.dot(centred, centred)
    assert -dt_s / np.log(rho) == pytest.approx(tau_s, rel=0.15)
