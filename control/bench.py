"""Benchmark of the controller's pure logic; prints JSON.

Measures the IK solve time per call (warm start, along a moving setpoint), the Cartesian Ruckig
step time, and the tracking time to 4 mm of the kinematic closed loop at 0.2, 0.4 and 0.6 m/s::

    .venv/bin/python -m control.bench --json
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from collections.abc import Sequence


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark's options to ``parser``."""
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--seeds", type=int, default=3, help="closed-loop episodes per speed")
    parser.add_argument("--calls", type=int, default=2000, help="timed IK / Ruckig calls")


def _time_ik(calls: int) -> dict[str, float]:
    import numpy as np

    from control.config import ControllerConfig
    from control.ik import Kinematics, tool_pose

    cfg = ControllerConfig()
    kin = Kinematics.of_station(cfg.station, cfg.ik)
    q = kin.solve(
        tool_pose(cfg.ready_tcp_position_m, cfg.ready_yaw_rad),
        np.asarray(cfg.robot.ready_joint_positions_rad),
    ).q
    iterations = 0
    failures = 0
    start = time.perf_counter()
    for i in range(calls):
        t_s = i * cfg.motion.control_period_s
        position = (-0.3 + 0.4 * t_s % 0.6, 0.5 + 0.05 * math.sin(t_s), 0.05)
        result = kin.solve(tool_pose(position, 1.2 + 0.2 * math.sin(t_s)), q)
        q = result.q
        iterations += result.iterations
        failures += not result.success
    elapsed = time.perf_counter() - start
    return {
        "ik_warm_us_per_call": 1e6 * elapsed / calls,
        "ik_mean_iterations": iterations / calls,
        "ik_failures": float(failures),
    }


def _time_ruckig(calls: int) -> dict[str, float]:
    from control.config import ControllerConfig
    from control.planner import CartesianPlanner, CartesianState, CartesianTarget

    cfg = ControllerConfig()
    planner = CartesianPlanner(cfg.motion, CartesianState(position=(0.0, 0.45, 0.3, 1.57)))
    start = time.perf_counter()
    for i in range(calls):
        t_s = i * cfg.motion.control_period_s
        if i % 200 == 0:
            planner.reset(CartesianState(position=(0.0, 0.45, 0.3, 1.57)))
        planner.step(
            CartesianTarget(position=(-0.5 + 0.4 * t_s, 0.5, 0.05, 0.3), velocity=(0.4, 0, 0, 0))
        )
    elapsed = time.perf_counter() - start
    return {"ruckig_step_us_per_call": 1e6 * elapsed / calls}


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and print the figures."""
    from control.kinematic_sim import run_episode

    report: dict[str, object] = {}
    report.update(_time_ik(args.calls))
    report.update(_time_ruckig(args.calls))
    for speed in (0.2, 0.4, 0.6):
        times = []
        errors = []
        for seed in range(args.seeds):
            result = run_episode(speed, seed=seed)
            times.append(result.tracking_time_4mm_s)
            errors.append(result.max_follow_error_m)
        report[f"tracking_time_4mm_mean_s@{speed}"] = statistics.fmean(times)
        report[f"tracking_time_4mm_max_s@{speed}"] = max(times)
        report[f"max_follow_error_mm@{speed}"] = 1000 * max(errors)
    if args.json:
        print(json.dumps(report, sort_keys=True))
    else:
        for key, value in report.items():
            print(f"{key}: {value}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point for ``python -m control.bench``."""
    parser = argparse.ArgumentParser(prog="python -m control.bench", description=__doc__)
    configure(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
