"""The IK's refusals without iterating (reach bounds) never refuse a pose the arm reaches."""

from __future__ import annotations

import math

import numpy as np
import pytest

from control.ik import Kinematics, tool_pose
from interfaces.cell import load_cell


@pytest.fixture(scope="module", params=["default", "line"])
def kinematics(request: pytest.FixtureRequest) -> Kinematics:
    """A Panda with its hand (the reference cell) or a UR10 with a suction cup (the line)."""
    cell = load_cell(request.param)
    return Kinematics.of_station(cell.stations[0])


def test_every_reachable_pose_is_solved_from_its_own_configuration(
    kinematics: Kinematics,
) -> None:
    """The TCP poses of random configurations within the limits: solved from the configuration
    that reaches them (the refusals let them through), and none of them lies beyond
    :meth:`Kinematics.beyond_reach`."""
    rng = np.random.default_rng(3)
    lower, upper = kinematics.lower_rad, kinematics.upper_rad
    solved = 0
    for _ in range(300):
        q = rng.uniform(lower, upper)
        pose = kinematics.fk(q)
        assert not kinematics.beyond_reach(tuple(pose.translation))
        result = kinematics.solve(pose, q)
        assert result.success
        assert result.iterations == 0  # already there: the first error is below tolerance
        solved += 1
    assert solved == 300


def test_a_downward_pose_beyond_the_wrists_reach_fails_without_iterating(
    kinematics: Kinematics,
) -> None:
    """Pointing down, far out at the base's height but inside the loose bound of every joint
    and the tool (:attr:`Kinematics.reach_m`): refused at once. Nearer in, the same pose is
    solved."""
    base = kinematics.oMbase.translation
    origin = kinematics.oMbase.act(kinematics.reach_origin_m)
    z = float(origin[2])
    far = kinematics.reach_m - 0.02
    pose = tool_pose((float(base[0]) + far, float(base[1]), z), 0.0)
    assert not kinematics.beyond_reach(tuple(pose.translation))
    seed = 0.5 * (kinematics.lower_rad + kinematics.upper_rad)
    result = kinematics.solve(pose, seed)
    assert not result.success
    assert result.iterations == 0
    assert math.isinf(result.error_norm)


def test_beyond_reach_agrees_with_the_solver_for_every_yaw(kinematics: Kinematics) -> None:
    """Points on rays from the base out to twice the bound: where :meth:`beyond_reach` says
    so, the solver fails for every yaw without iterating; where it does not, at least one
    yaw's solve iterates."""
    base = kinematics.oMbase.translation
    seed = 0.5 * (kinematics.lower_rad + kinematics.upper_rad)
    beyond = 0
    for angle in np.linspace(0.0, 2.0 * math.pi, 7, endpoint=False):
        for distance in np.linspace(0.2, 2.0 * kinematics.reach_m, 9):
            point = (
                float(base[0] + distance * math.cos(angle)),
                float(base[1] + distance * math.sin(angle)),
                float(base[2] + 0.3),
            )
            results = [kinematics.solve(tool_pose(point, yaw), seed) for yaw in (0.0, 1.0, 2.5)]
            if kinematics.beyond_reach(point):
                beyond += 1
                assert all(not r.success and r.iterations == 0 for r in results)
    assert beyond > 0


def test_no_stretched_configuration_is_refused(kinematics: Kinematics) -> None:
    """The wrist bound comes from a search over the joint limits (plus a margin), not a proof:
    the most stretched of 20,000 random configurations, pushed outwards joint by joint (an
    ascent of their own, not the bound's), come within the margin of the bound but not
    beyond it, and the solver accepts the poses they reach from where they are."""
    rng = np.random.default_rng(7)
    lower, upper = kinematics.lower_rad, kinematics.upper_rad

    def stretch(q: np.ndarray) -> float:
        return kinematics.wrist_distance_m(kinematics.fk(q))

    samples = sorted(rng.uniform(lower, upper, size=(20000, kinematics.nq)), key=stretch)[-10:]
    farthest = 0.0
    for sample in samples:
        q = sample
        for _ in range(300):
            j = int(rng.integers(kinematics.nq))
            trial = q.copy()
            trial[j] = np.clip(trial[j] + rng.normal(0.0, 0.1), lower[j], upper[j])
            if stretch(trial) > stretch(q):
                q = trial
        farthest = max(farthest, stretch(q))
        assert stretch(q) <= kinematics.wrist_reach_m
        result = kinematics.solve(kinematics.fk(q), q)
        assert result.success, f"a pose reached at q={q.tolist()} was refused"
        assert result.iterations == 0
    assert farthest > kinematics.wrist_reach_m - 0.015  # the ascent got out to the margin
