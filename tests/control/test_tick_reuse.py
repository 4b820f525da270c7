"""A waiting arm's tick reuses what it computed (issue 37) and gives the same answers as the
computation it skips."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from control import intercept, poses
from control.config import ControllerConfig
from control.ik import Kinematics, yaw_of
from control.pick import Phase, PickController, TcpMeasurement
from control.planner import JointCommander, JointPlanner
from control.predicted_tracks import PredictedTracks
from control.tracking import Detection, Tracker
from tests.control.test_pick import _track


def _planner() -> tuple[Kinematics, JointPlanner, np.ndarray, ControllerConfig]:
    config = ControllerConfig()
    kin = Kinematics.of_station(config.station, config.ik)
    planner = JointPlanner(kin, config.motion)
    q = np.asarray(config.robot.ready_joint_positions_rad, dtype=np.float64)
    planner.reset(q)
    return kin, planner, q, config


def _return_to(planner: JointPlanner, goal: np.ndarray) -> None:
    """Step towards ``goal`` until the step leaves the planner's state unchanged."""
    for _ in range(5000):
        step = planner.step(goal)
        if step is planner.step(goal):
            return
    raise AssertionError("the move never came to rest")


def test_a_resting_planner_hands_out_the_same_step_equal_to_a_fresh_planners() -> None:
    kin, planner, q, config = _planner()
    goal = np.clip(q + 0.3, kin.lower_rad, kin.upper_rad)
    _return_to(planner, goal)
    first = planner.step(goal)
    again = planner.step(goal)
    assert again is first
    assert not first.q.flags.writeable
    # a planner that computes the step from the same state gets the same numbers
    fresh = JointPlanner(kin, config.motion)
    fresh.reset(first.q, first.dq)
    computed = fresh.step(goal)
    assert np.array_equal(computed.q, first.q)
    assert np.array_equal(computed.dq, first.dq)
    assert computed.remaining_s == first.remaining_s


def test_a_new_goal_or_state_plans_again() -> None:
    kin, planner, q, _ = _planner()
    _return_to(planner, q)
    rest = planner.step(q)
    other = np.clip(q + 0.2, kin.lower_rad, kin.upper_rad)
    moving = planner.step(other)
    assert moving is not rest
    assert np.abs(moving.dq).max() > 0.0
    planner.reset(np.asarray(rest.q), np.asarray(rest.dq))
    assert planner.step(q) is rest  # the same state and goal: the same step


def test_the_joint_command_counts_its_changes() -> None:
    kin, _, q, config = _planner()
    commander = JointCommander(kin, config.motion, q)
    v0 = commander.version
    commander.reset(q)
    commander.brake()
    assert commander.version == v0 + 2


def _frame(tracker: Tracker, stamp_s: float, x_m: float) -> None:
    det = Detection(
        stamp_s=stamp_s,
        class_name="brick",
        confidence=1.0,
        x_m=x_m,
        y_m=0.5,
        yaw_rad=0.0,
        length_m=0.1,
        width_m=0.05,
        height_m=0.04,
    )
    tracker.update(stamp_s, [det], (0.4, 0.0))


def test_predicted_tracks_are_the_trackers_prediction_computed_once_when_read() -> None:
    config = ControllerConfig()
    tracker = Tracker(config.tracking, classes=config.classes)
    for k in range(8):
        _frame(tracker, k / 30.0, -0.5 + 0.4 * k / 30.0)
    lazy = PredictedTracks(tracker, 0.3)
    expected = tracker.predict_to(0.3)
    assert expected, "the tracker confirmed its track"
    assert tuple(lazy) == expected
    assert len(lazy) == len(expected)
    assert lazy[0] == expected[0]
    assert lazy[0] is lazy[0]  # computed once, then kept


def _first_pursuit_tick(controller: PickController, x0_m: float, ticks: int) -> int | None:
    """Drive ``controller`` (an ideal arm, 120 Hz) with one track that was at ``x0_m`` at
    t = 0 moving at 0.4 m/s; the first tick that is not idle."""
    kin, q = controller.kinematics, controller.q_ready
    for k in range(ticks):
        t_s = k / 120.0
        track = _track(x0_m, t_s)
        pose = kin.fk(q)
        measured = TcpMeasurement(position_m=tuple(pose.translation), yaw_rad=yaw_of(pose))
        command = controller.update(t_s, measured, (track,), (0.4, 0.0))
        q = np.asarray(command.joint_positions_rad)
        if command.phase != Phase.IDLE:
            return k
    return None


def test_a_resting_arm_does_not_solve_an_upstream_meeting_again_and_targets_it_as_before(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An idle arm asks about a piece coming from upstream at every tick (the reference cell's
    ``replan_period_s: 0``); while the piece is well upstream of the window at its meeting's
    duration, the meeting is not solved again (:data:`control.intercept.EARLY_RECHECK_S`).
    The piece is targeted at the same tick as when every estimate is solved afresh."""
    base = ControllerConfig()
    config = replace(base, pick=replace(base.pick, approach_space="joint"))
    x0_m = base.pick_window_x_m[0] - 0.45
    solved: list[int] = []
    real = poses.solve_meeting

    def counted(*args: Any, **kwargs: Any) -> Any:
        solved.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(intercept, "solve_meeting", counted)
    first = _first_pursuit_tick(PickController(config), x0_m, 240)
    with_memo = len(solved)
    solved.clear()
    monkeypatch.setattr(
        intercept.Intercept,
        "approach_estimate",
        lambda self, track, t_s, tracks: (
            math.inf
            if (m := self.joint_meeting(track, t_s, tracks)) is None
            else m.goal.arrive_s - t_s
        ),
    )
    afresh = _first_pursuit_tick(PickController(config), x0_m, 240)
    assert first is not None
    assert first == afresh
    assert with_memo < len(solved) / 2  # most of the idle ticks' solves were skipped
