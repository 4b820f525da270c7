"""Benchmark one belt-drive co-simulation step (set inputs + doStep + get outputs).

Example::

    cdw-twin bench fmu --json --steps 20000 --fmi 3

Target: ``us_per_step`` <= 10 (about 0.2 % of a 240 Hz physics step).
"""

from __future__ import annotations

import json
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import argparse

TARGET_US_PER_STEP = 10.0


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the ``bench fmu`` options."""
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--steps", type=int, default=20_000, help="timed steps (default 20000)")
    parser.add_argument("--fmi", type=int, choices=(2, 3), default=3, help="FMI version")
    parser.add_argument("--dt", type=float, default=1 / 240, help="communication step in s")


def measure_us_per_step(fmi_version: int, steps: int, dt_s: float) -> float:
    """Mean wall-clock microseconds of one ``BeltDrive.step`` over ``steps`` calls."""
    from fmus.build import build_fmus, default_fmu_path
    from twin.belt_drive import BeltDrive
    from twin.errors import ConfigError

    if steps <= 0:
        msg = f"--steps = {steps} must be positive"
        raise ConfigError(msg)
    build_fmus()
    with BeltDrive(default_fmu_path(fmi_version)) as drive:
        for _ in range(min(steps, 1000)):
            drive.step(dt_s, 0.5, 10.0)
        start = time.perf_counter()
        for k in range(steps):
            drive.step(dt_s, 0.8 if k & 256 else 0.4, 25.0)
        elapsed_s = time.perf_counter() - start
    return elapsed_s / steps * 1e6


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and print the result."""
    us = measure_us_per_step(args.fmi, args.steps, args.dt)
    result = {
        "benchmark": "fmu_step",
        "fmi_version": args.fmi,
        "steps": args.steps,
        "dt_s": args.dt,
        "us_per_step": round(us, 3),
        "target_us_per_step": TARGET_US_PER_STEP,
        "meets_target": us <= TARGET_US_PER_STEP,
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"FMI {args.fmi}.0: {us:.2f} us per step (target <= {TARGET_US_PER_STEP} us)")
    return 0
