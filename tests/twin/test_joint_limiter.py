"""The joint limiter on its own (no simulator): what passes unchanged, what is limited."""

from __future__ import annotations

import numpy as np
import pytest

from twin.joint_limiter import JointLimiter

DT_S = 1.0 / 240.0
HOLD_S = 0.05
VMAX, AMAX = 2.175, 15.0


def _limiter(start: float = 0.0) -> JointLimiter:
    return JointLimiter(
        velocity_rps=np.array([VMAX]),
        acceleration_rps2=np.array([AMAX]),
        jerk_rps3=np.array([7500.0]),
        dt_s=DT_S,
        hold_s=HOLD_S,
        start_rad=np.array([start]),
    )


def _trapezoid(distance: float, accel: float, t_s: float) -> tuple[float, float]:
    """Position and velocity of a rest-to-rest move at ``accel`` and ``VMAX``."""
    v_peak = min(VMAX, np.sqrt(distance * accel))
    t_acc = v_peak / accel
    t_end = t_acc + distance / v_peak
    t = min(t_s, t_end)
    late = t_end - t
    if t < t_acc:
        return 0.5 * accel * t * t, accel * t
    if late < t_acc:
        return distance - 0.5 * accel * late * late, accel * late
    return v_peak * (t - 0.5 * t_acc), v_peak


def _stream(
    accel: float, *, backward: bool, every: int = 2, steps: int = 400
) -> tuple[np.ndarray, np.ndarray, int]:
    """A 1.6 rad move at ``accel`` commanded every ``every`` steps (exact velocities, or
    backward differences as the controller sends them), extrapolated between commands as the
    twin does; returns the desired targets, the motors' targets and the steps limited."""
    limiter = _limiter()
    desired, handed, limited = [], [], 0
    q_cmd = qd = 0.0
    since = 0.0
    last = 0.0
    for k in range(steps):
        if k % every == 0:
            q, v = _trapezoid(1.6, accel, k * DT_S)
            qd = (q - last) / (every * DT_S) if backward else v
            last = q_cmd = q
            since = 0.0
            limiter.command(np.array([q]), np.array([qd]))
        elif qd and since < HOLD_S:
            since += DT_S
        target = q_cmd + qd * min(since, HOLD_S)
        moving = qd != 0.0 and since < HOLD_S
        out, _ = limiter.step(np.array([target]), np.array([qd]) if moving else None)
        desired.append(target)
        handed.append(out[0])
        limited += limiter.any_limited
    return np.array(desired), np.array(handed), limited


@pytest.mark.parametrize("backward", [False, True], ids=["exact-velocities", "backward-diff"])
@pytest.mark.parametrize("every", [2, 4], ids=["120Hz", "60Hz"])
def test_a_trajectory_within_the_limits_passes_unchanged(backward: bool, every: int) -> None:
    desired, handed, limited = _stream(AMAX, backward=backward, every=every)
    assert limited == 0
    assert np.array_equal(handed, desired)


def _late_stream(*, stamped: bool, steps: int = 400) -> int:
    """The 120 Hz stream at the acceleration limit (backward differences), each command
    arriving 0 or 1 step after its stamp (seeded), as commands over DDS do in realtime; the
    twin extrapolates a command from its stamp when ``stamped``, from its arrival otherwise.
    Returns the steps limited."""
    rng = np.random.default_rng(7)
    arrivals: dict[int, tuple[float, float, int]] = {}
    last = 0.0
    for k in range(0, steps, 2):
        q, _ = _trapezoid(1.6, AMAX, k * DT_S)
        delay = int(rng.integers(0, 2))
        arrivals[k + delay] = (q, (q - last) / (2 * DT_S), delay)
        last = q
    limiter, limited = _limiter(), 0
    q_cmd = qd = 0.0
    since = 0.0
    for k in range(steps):
        if k in arrivals:
            q_cmd, qd, delay = arrivals[k]
            age_s = delay * DT_S if stamped else 0.0
            since = age_s
            limiter.command(np.array([q_cmd]), np.array([qd]), age_s=age_s)
        elif qd and since < HOLD_S:
            since += DT_S
        target = q_cmd + qd * min(since, HOLD_S)
        moving = qd != 0.0 and since < HOLD_S
        limiter.step(np.array([target]), np.array([qd]) if moving else None)
        limited += limiter.any_limited
    return limited


def test_commands_that_arrive_late_are_judged_at_their_stamps() -> None:
    """A command stamped for step k that arrives at step k + 1 continues the trajectory it
    samples: judged by its stamp it passes. Judged by arrival (the interval between two
    commands one step shorter or longer than between their stamps), the same stream is taken
    over by the limiter, whose reference lags the command: in realtime that lag made the
    controller's feedback ring by several cm."""
    assert _late_stream(stamped=True) == 0
    assert _late_stream(stamped=False) > 20


def test_a_trajectory_beyond_the_acceleration_limit_is_limited() -> None:
    desired, handed, limited = _stream(1.5 * AMAX, backward=True)
    assert limited > 100
    assert np.abs(handed - desired).max() > 0.01  # it lags the command
    velocity = np.diff(handed) / DT_S
    assert np.abs(velocity).max() <= VMAX + 1e-9
    assert handed[-1] == pytest.approx(1.6, abs=1e-9)  # it gets there all the same


def test_a_step_is_followed_within_the_velocity_and_acceleration_limits() -> None:
    limiter = _limiter()
    limiter.command(np.array([1.0]), None)
    positions = [0.0]
    for _ in range(240):
        out, _ = limiter.step(np.array([1.0]), None)
        positions.append(out[0])
    p = np.array(positions)
    v = np.diff(p) / DT_S
    a = np.diff(v) / DT_S
    assert np.abs(v).max() <= VMAX * (1 + 1e-9)
    assert np.abs(a).max() <= AMAX * (1 + 1e-6)
    assert p[-1] == 1.0
    assert not limiter.any_limited  # arrived: the next commands pass again


def test_bad_limits_are_refused() -> None:
    with pytest.raises(ValueError, match="must be positive"):
        JointLimiter(
            velocity_rps=np.array([1.0]),
            acceleration_rps2=np.array([0.0]),
            jerk_rps3=np.array([1.0]),
            dt_s=DT_S,
            hold_s=HOLD_S,
            start_rad=np.array([0.0]),
        )
