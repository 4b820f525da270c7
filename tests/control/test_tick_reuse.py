"""A waiting arm's tick reuses what it computed (issue 37) and gives the same answers as the
computation it skips."""

from __future__ import annotations

import numpy as np

from control.config import ControllerConfig
from control.ik import Kinematics
from control.planner import JointCommander, JointPlanner
from control.predicted_tracks import PredictedTracks
from control.tracking import Detection, Tracker


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
