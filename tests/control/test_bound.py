"""The pursuit bound (``cdw-twin bench bound``): within the joint limits, never faster than the
joints' own speed limits allow, and met inside the pick window."""

from __future__ import annotations

import math

import numpy as np

from control.bound import bound_table, pursuit_bound
from control.config import load_config, params_path
from control.ik import Kinematics, tool_pose
from control.scheduler import grasp_z_m


def test_the_bound_is_no_faster_than_the_joint_speed_limits_and_lies_in_the_window() -> None:
    config = load_config(params_path("default", None))
    kinematics = Kinematics.of_station(config.station, config.ik)
    q_ready = np.asarray(config.robot.ready_joint_positions_rad, dtype=np.float64)
    wait = kinematics.solve(tool_pose(config.ready_tcp_position_m, config.ready_yaw_rad), q_ready)
    q_wait = np.array(wait.q)
    vmax = np.asarray(kinematics.velocity_limit_rps, dtype=np.float64)
    for speed in (0.2, 0.6):
        case = pursuit_bound(
            config, kinematics, q_wait, y_m=0.5, yaw_rad=0.3, height_m=0.04, speed_mps=speed
        )
        assert math.isfinite(case.bound_s)
        assert case.bound_s > 0.0
        x_min, x_max = config.pick_window_x_m
        assert x_min <= case.meet_x_m <= x_max
        grasp = tool_pose((case.meet_x_m, 0.5, grasp_z_m(0.04, config)), 0.3)
        q_meet = np.array(kinematics.solve(grasp, q_wait).q)
        # every joint must cover its distance at no more than its velocity limit
        assert case.bound_s >= float(np.max(np.abs(q_meet - q_wait) / vmax)) - 1e-6


def test_the_table_reports_each_speed_over_the_cases_it_met() -> None:
    config = load_config(params_path("default", None))
    table = bound_table(config, speeds_mps=(0.4,), ys_m=(0.45, 0.55), yaws_rad=(0.0, 1.0))
    row = table["speeds"]["0.4"]  # type: ignore[index]
    assert row["cases"] == 4
    assert 1 <= row["met"] <= 4
    assert row["min_s"] <= row["median_s"] <= row["max_s"]
