"""Benchmark of the controller's pure logic; prints JSON.

Measures the IK solve time per call (warm start, along a moving setpoint), the Cartesian Ruckig
step time, the multi-object tracker's cost per :meth:`~control.tracking.Tracker.predict_to` (one
per control update) and per :meth:`~control.tracking.Tracker.update` (one per camera frame) on a
seeded synthetic stream of N objects in view (:func:`tracker_stream`), and the tracking time to
4 mm of the kinematic closed loop at 0.2, 0.4 and 0.6 m/s::

    cdw-twin bench control --json
    cdw-twin bench control --json --parts tracker --tracker-objects 20 40
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from control.config import TrackingConfig
    from control.tracking import Detection, Track

PARTS = ("ik", "ruckig", "tracker", "episodes")
"""What the benchmark can measure (``--parts``)."""


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark's options to ``parser``."""
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--seeds", type=int, default=3, help="closed-loop episodes per speed")
    parser.add_argument("--calls", type=int, default=2000, help="timed IK / Ruckig calls")
    parser.add_argument(
        "--parts", nargs="+", choices=PARTS, default=list(PARTS), help="what to measure (all)"
    )
    parser.add_argument(
        "--tracker-objects",
        type=int,
        nargs="+",
        default=[20, 40],
        help="objects in the camera's view of each tracker stream (20 40)",
    )
    parser.add_argument(
        "--tracker-seconds", type=float, default=30.0, help="length of each tracker stream (30)"
    )


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


@dataclass(frozen=True, kw_only=True)
class TrackerLoad:
    """A seeded synthetic camera stream over the default cell's belt, for the tracker.

    ``objects`` objects are always in the camera's field of view (the default cell's
    ``camera``): one that leaves downstream is replaced by a new one entering upstream. They move
    at ``belt_speed_mps`` along x plus a lateral drift (standard deviation ``drift_std_mps``),
    with random classes, footprints (either side the longer) and yaws. Frames are captured at
    ``rate_hz`` and released ``latency_s`` later; control updates run at ``control_rate_hz``.
    Each frame loses each object with probability ``drop_rate``, confuses its class with
    ``misclassification_rate``, adds ``clutter_per_frame`` spurious detections on average
    anywhere on the belt, and with probability ``near_clutter_rate`` per detection a spurious
    twin within ``near_clutter_m`` of it (competing for the same track). With probability
    ``blackout_rate`` per frame, the camera then delivers nothing for ``blackout_s`` (tracks
    coast, and die past the tracker's ``max_coast_s``).
    """

    objects: int = 30
    seed: int = 0
    duration_s: float = 30.0
    belt_speed_mps: float = 0.4
    drift_std_mps: float = 0.01
    rate_hz: float = 30.0
    latency_s: float = 0.03
    control_rate_hz: float = 120.0
    position_std_m: float = 0.002
    yaw_std_rad: float = 0.02
    drop_rate: float = 0.02
    misclassification_rate: float = 0.01
    clutter_per_frame: float = 0.2
    near_clutter_rate: float = 0.0
    near_clutter_m: float = 0.008
    blackout_rate: float = 0.0
    blackout_s: float = 0.4
    classes: tuple[str, ...] = ("concrete", "brick", "wood", "rubber")


@dataclass(frozen=True, kw_only=True)
class CameraFrame:
    """The detections of one frame captured at ``stamp_s`` (each stamped ``stamp_s``)."""

    stamp_s: float
    detections: tuple[Detection, ...]


@dataclass
class _Body:
    x_m: float
    y_m: float
    vy_mps: float
    class_name: str
    yaw_rad: float
    length_m: float
    width_m: float
    height_m: float


def tracker_stream(load: TrackerLoad) -> list[tuple[float, CameraFrame | None]]:
    """The events of ``load`` in time order: ``(t_s, frame)`` when a frame is released at
    ``t_s``, ``(t_s, None)`` for a control update at ``t_s`` (frames released at or before a
    control update come before it). Deterministic in ``load``."""
    import numpy as np

    from control.tracking import Detection
    from interfaces.cell import BeltSpec, CameraSpec

    belt, camera = BeltSpec(), CameraSpec()
    rng = np.random.default_rng(load.seed)
    fov_m = camera.fov_max_x_m - camera.fov_min_x_m
    half_width_m = 0.5 * belt.width_m - 0.05
    dt_s = 1.0 / load.rate_hz

    def body(x_m: float) -> _Body:
        length, width = rng.uniform(0.04, 0.25), rng.uniform(0.03, 0.15)
        return _Body(
            x_m=x_m,
            y_m=belt.centre_y_m + rng.uniform(-half_width_m, half_width_m),
            vy_mps=rng.normal(0.0, load.drift_std_mps),
            class_name=load.classes[int(rng.integers(len(load.classes)))],
            yaw_rad=rng.uniform(-math.pi, math.pi),
            length_m=length,
            width_m=width,
            height_m=rng.uniform(0.01, 0.12),
        )

    def detection(stamp_s: float, b: _Body, x_m: float, y_m: float, correct: bool) -> Detection:
        class_name = b.class_name
        if not correct:
            others = [c for c in load.classes if c != b.class_name]
            class_name = others[int(rng.integers(len(others)))]
        mean = 0.9 if correct else 0.55
        return Detection(
            stamp_s=stamp_s,
            class_name=class_name,
            confidence=float(rng.beta(20 * mean, 20 * (1 - mean))),
            x_m=x_m + load.position_std_m * rng.standard_normal(),
            y_m=y_m + load.position_std_m * rng.standard_normal(),
            yaw_rad=b.yaw_rad + load.yaw_std_rad * rng.standard_normal(),
            length_m=b.length_m,
            width_m=b.width_m,
            height_m=b.height_m,
        )

    bodies = [
        body(camera.fov_min_x_m + fov_m * (i + rng.random()) / load.objects)
        for i in range(load.objects)
    ]
    frames: list[tuple[float, CameraFrame | None]] = []
    blackout_until_s = -math.inf
    for k in range(round(load.duration_s * load.rate_hz)):
        stamp_s = k * dt_s
        found: list[Detection] = []
        for b in bodies:
            if rng.random() >= load.drop_rate:
                correct = rng.random() >= load.misclassification_rate
                found.append(detection(stamp_s, b, b.x_m, b.y_m, correct))
                if rng.random() < load.near_clutter_rate:
                    angle = rng.uniform(-math.pi, math.pi)
                    x_m = b.x_m + load.near_clutter_m * math.cos(angle)
                    y_m = b.y_m + load.near_clutter_m * math.sin(angle)
                    found.append(detection(stamp_s, b, x_m, y_m, rng.random() < 0.5))
        for _ in range(int(rng.poisson(load.clutter_per_frame))):
            ghost = body(rng.uniform(camera.fov_min_x_m, camera.fov_max_x_m))
            found.append(detection(stamp_s, ghost, ghost.x_m, ghost.y_m, rng.random() < 0.5))
        if rng.random() < load.blackout_rate:
            blackout_until_s = stamp_s + load.blackout_s
        if stamp_s >= blackout_until_s:
            order = rng.permutation(len(found))
            frame = CameraFrame(stamp_s=stamp_s, detections=tuple(found[i] for i in order))
            frames.append((stamp_s + load.latency_s, frame))
        for i, b in enumerate(bodies):
            b.x_m += load.belt_speed_mps * dt_s
            b.y_m += b.vy_mps * dt_s
            if abs(b.y_m - belt.centre_y_m) > half_width_m:
                b.vy_mps = -b.vy_mps
            if b.x_m > camera.fov_max_x_m:
                bodies[i] = body(b.x_m - fov_m)
    ticks = [
        (k / load.control_rate_hz, None)
        for k in range(round(load.duration_s * load.control_rate_hz))
    ]
    events: list[tuple[float, CameraFrame | None]] = [*frames, *ticks]
    # Stable sort: a frame released at a control update's time comes first.
    events.sort(key=lambda event: (event[0], event[1] is None))
    return events


class _TrackerLike(Protocol):
    """What :func:`time_tracker` needs of a tracker (the one of :mod:`control.tracking`)."""

    def update(
        self,
        stamp_s: float,
        detections: Sequence[Detection],
        belt_velocity_mps: tuple[float, float],
    ) -> None: ...

    def predict_to(self, t_s: float, *, confirmed_only: bool = True) -> tuple[Track, ...]: ...

    def __len__(self) -> int: ...


def time_tracker(
    load: TrackerLoad,
    make: Callable[[TrackingConfig, tuple[str, ...]], _TrackerLike] | None = None,
    *,
    warmup_s: float = 2.0,
    passes: int = 3,
) -> dict[str, float]:
    """Replay ``load`` through fresh trackers (``make(config, classes)``, default
    :class:`~control.tracking.Tracker`) ``passes`` times and time every call after
    ``warmup_s``: the median and 95th percentile of ``predict_to`` and of ``update`` in
    microseconds, each the lowest of the passes (other processes on the machine only ever add
    time), and the mean number of live tracks at the control updates."""
    import numpy as np

    from control.config import TrackingConfig
    from control.tracking import Tracker

    if make is None:
        make = lambda config, classes: Tracker(config, classes=classes)  # noqa: E731
    events = tracker_stream(load)
    belt_velocity_mps = (load.belt_speed_mps, 0.0)
    clock = time.perf_counter_ns
    figures: dict[str, float] = {}
    for _ in range(passes):
        tracker = make(TrackingConfig(), load.classes)
        predict_ns: list[int] = []
        update_ns: list[int] = []
        tracks: list[int] = []
        for t_s, frame in events:
            if frame is None:
                start = clock()
                tracker.predict_to(t_s)
                elapsed = clock() - start
                if t_s >= warmup_s:
                    predict_ns.append(elapsed)
                    tracks.append(len(tracker))
            else:
                start = clock()
                tracker.update(frame.stamp_s, frame.detections, belt_velocity_mps)
                elapsed = clock() - start
                if t_s >= warmup_s:
                    update_ns.append(elapsed)
        predict_us = np.asarray(predict_ns) / 1000.0
        update_us = np.asarray(update_ns) / 1000.0
        this_pass = {
            "predict_us_median": float(np.median(predict_us)),
            "predict_us_p95": float(np.percentile(predict_us, 95)),
            "update_us_median": float(np.median(update_us)),
            "update_us_p95": float(np.percentile(update_us, 95)),
        }
        for key, value in this_pass.items():
            figures[key] = min(figures.get(key, math.inf), value)
        figures["mean_tracks"] = statistics.fmean(tracks)
    return figures


def _time_trackers(objects: Sequence[int], seconds: float) -> dict[str, float]:
    report: dict[str, float] = {}
    for n in objects:
        figures = time_tracker(TrackerLoad(objects=n, duration_s=seconds))
        report.update({f"tracker_{key}@{n}": value for key, value in figures.items()})
    return report


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and print the figures."""
    from control.kinematic_sim import run_episode

    report: dict[str, object] = {}
    if "ik" in args.parts:
        report.update(_time_ik(args.calls))
    if "ruckig" in args.parts:
        report.update(_time_ruckig(args.calls))
    if "tracker" in args.parts:
        report.update(_time_trackers(args.tracker_objects, args.tracker_seconds))
    for speed in (0.2, 0.4, 0.6) if "episodes" in args.parts else ():
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
