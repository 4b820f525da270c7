"""``cdw-twin bench render``: how long the camera takes per frame, on each renderer.

The twin of the reference cell (``interfaces/cells/default.yaml``) with the built-in sample
(dense: 9 to 12 pieces per image) and its belt prefilled with ``--objects`` pieces (40), the
arm sweeping through a joint-space motion over its home pose (as ``bench twin`` moves it). Two
cameras: ``reference`` (the cell's default camera, straight down from 1.2 m upstream of the pick
window) and ``wide`` (straight down from 1.6 m with a 70 degree field, seeing the whole
prefilled stretch and the arm's base and links: every piece and the arm in the frame). Per
renderer (``gl``: OpenGL through moderngl on EGL; ``tiny``: PyBullet's TinyRenderer), camera
and size (640x480, 320x240):

- ``render_ms``: colour + depth + instance ids of one frame, poses already read (OpenGL: the
  draw calls, the readback and the depth linearisation; TinyRenderer: ``getCameraImage`` and
  the conversions);
- ``capture_ms`` (640x480): the whole capture, :meth:`twin.camera.rig.CameraRig.capture`:
  reading every pose from PyBullet, rendering, reading back and the depth noise.

Each round times every configuration once, in turn (interleaved, so a neighbour's load falls
on all alike), then steps the twin 1/30 s (untimed); median and 90th percentile over the rounds
of the wall time, and of the process's CPU time (all its threads: the cost on one core even
when other processes share it, where the wall time also counts their turns).
Run it pinned to one core (``taskset -c 0 cdw-twin bench render --json``): the target is
<= 20 ms per 640x480 frame on one core.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

if TYPE_CHECKING:
    from interfaces.camera import RgbdCameraSpec, RgbdFrame
    from twin.camera.rig import CameraRig
    from twin.sim import Twin

__all__ = ["configure", "run"]

TARGET_MS = 20.0
"""Issue 36's target: colour + depth + ids, 640x480, 40 pieces + arm, one core."""

SIZES = ((640, 480), (320, 240))


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark's options."""
    parser.add_argument("--objects", type=int, default=40, help="pieces on the belt (40)")
    parser.add_argument("--rounds", type=int, default=40, help="timed rounds (40)")
    parser.add_argument(
        "--renderers",
        default="gl,tiny",
        help="comma-separated renderers to time (gl,tiny; one missing here is reported)",
    )
    parser.add_argument(
        "--dataset",
        type=Path,
        default=None,
        help="meshgen output folder (default: the built-in sample, dense)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def _arm_sweep(home: np.ndarray, t_s: float) -> tuple[float, ...]:
    """A smooth joint-space sweep around the home pose (keeps the arm moving)."""
    phase = 2.0 * math.pi * 0.25 * t_s
    return tuple(float(v) for v in home + 0.25 * np.sin(phase + np.arange(home.size)))


Sample = tuple[float, float]
"""One timed frame: wall seconds, and CPU seconds of the whole process (every thread: Mesa's
rasteriser threads too)."""


def _stats(samples: list[Sample]) -> dict[str, float]:
    """Median, 90th percentile and minimum of the wall times, and the median and 90th
    percentile of the CPU times, ms."""
    wall = np.array([s[0] for s in samples]) * 1000.0
    cpu = np.array([s[1] for s in samples]) * 1000.0
    return {
        "median": round(float(np.median(wall)), 2),
        "p90": round(float(np.percentile(wall, 90)), 2),
        "min": round(float(wall.min()), 2),
        "cpu_median": round(float(np.median(cpu)), 2),
        "cpu_p90": round(float(np.percentile(cpu, 90)), 2),
    }


def _timed(action: Callable[[], object]) -> tuple[object, Sample]:
    """``action()``'s result and its wall and process CPU time."""
    wall, cpu = time.perf_counter(), time.process_time()
    result = action()
    return result, (time.perf_counter() - wall, time.process_time() - cpu)


def _cameras() -> dict[str, RgbdCameraSpec]:
    """The benchmark's two cameras (see the module)."""
    from interfaces.camera import RgbdCameraSpec

    return {
        "reference": RgbdCameraSpec(),
        "wide": RgbdCameraSpec(name="wide", position_m=(-0.75, 0.45, 1.6), hfov_deg=70.0),
    }


def _sized(spec: RgbdCameraSpec, width_px: int, height_px: int) -> RgbdCameraSpec:
    """``spec`` with another image size (the same field of view across)."""
    return dataclasses.replace(spec, width_px=width_px, height_px=height_px)


def _renderers(text: str) -> list[str]:
    """The renderers named by ``--renderers``."""
    from twin.errors import ConfigError

    names = [name.strip() for name in text.split(",") if name.strip()]
    for name in names:
        if name not in ("gl", "tiny"):
            msg = f"--renderers: {name!r} is not a renderer (gl, tiny)"
            raise ConfigError(msg)
    return names


def _time_rounds(
    twin: Twin, rigs: dict[str, CameraRig], rounds: int, result: dict[str, Any]
) -> dict[tuple[str, str, str, str], list[Sample]]:
    """Every configuration timed once per round, in turn; the twin stepped 1/30 s between
    rounds. Round 0 warms up (uploads, first draws) and is not kept."""
    from twin.sim import ArmCommand

    cameras = _cameras()
    home = np.array(twin.cell.stations[0].robot.home_joint_positions)
    samples: dict[tuple[str, str, str, str], list[Sample]] = {}
    rng = np.random.default_rng(0)
    for round_index in range(rounds + 1):
        for renderer, rig in rigs.items():
            snapshot = rig.snapshot()
            for camera, spec in cameras.items():
                for width, height in SIZES:
                    sized = _sized(spec, width, height)
                    _, sample = _timed(lambda: rig.draw(sized, snapshot))  # noqa: B023
                    key = (renderer, camera, f"{width}x{height}", "render_ms")
                    samples.setdefault(key, []).append(sample)
                captured, sample = _timed(lambda: rig.capture(spec, rng=rng))  # noqa: B023
                samples.setdefault((renderer, camera, "640x480", "capture_ms"), []).append(sample)
                frame = cast("RgbdFrame", captured)
                if round_index == 0 and frame.instance_ids is not None:
                    seen = len(np.unique(frame.instance_ids)) - 1
                    result.setdefault("objects_in_view", {})[camera] = seen
            if round_index == 0:
                for values in samples.values():
                    values.clear()
        for _ in range(8):  # 1/30 s of simulated time
            twin.advance(ArmCommand(_arm_sweep(home, twin.time_s)))
    return samples


def _figures(
    samples: dict[tuple[str, str, str, str], list[Sample]], result: dict[str, Any]
) -> None:
    """The statistics of every configuration into ``result``, with the ratio of the
    renderers' wall medians and whether OpenGL's CPU median per 640x480 render meets the
    target."""
    figures: dict[str, Any] = {}
    for (renderer, camera, size, what), values in samples.items():
        figures.setdefault(renderer, {}).setdefault(camera, {}).setdefault(size, {})[what] = _stats(
            values
        )
    result["figures"] = figures
    cameras = _cameras()
    if "gl" in figures and "tiny" in figures:
        result["tiny_over_gl_render_640x480"] = {
            camera: round(
                figures["tiny"][camera]["640x480"]["render_ms"]["median"]
                / figures["gl"][camera]["640x480"]["render_ms"]["median"],
                2,
            )
            for camera in cameras
        }
    if "gl" in figures:
        worst = max(figures["gl"][c]["640x480"]["render_ms"]["cpu_median"] for c in cameras)
        result["gl_render_640x480_cpu_median_within_target"] = worst <= TARGET_MS


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and print its figures."""
    from twin.builtin import builtin_dataset
    from twin.camera.choose import choose_renderer
    from twin.camera.errors import RenderError
    from twin.camera.gl import gl_renderer_name
    from twin.camera.rig import CameraRig
    from twin.errors import ConfigError
    from twin.scenario import ObjectLevel, Scenario, SystemLevel
    from twin.sim import Twin

    if args.objects < 1 or args.rounds < 1:
        msg = f"--objects {args.objects} and --rounds {args.rounds} must be at least 1"
        raise ConfigError(msg)
    wanted = _renderers(args.renderers)
    scenario = Scenario(
        name="bench-render",
        duration_s=3600.0,
        objects=ObjectLevel(max_objects=args.objects),
        system=SystemLevel(belt_speed_mps=0.05, image_gap_m=0.0, prefill_m=1.75),
    )
    result: dict[str, Any] = {
        "default_renderer": choose_renderer("auto"),
        "cpu_affinity": sorted(os.sched_getaffinity(0)),
        "rounds": args.rounds,
        "target_ms_640x480": TARGET_MS,
        "statistic": (
            "per configuration one frame per round, rounds interleaved; ms of wall clock "
            "(median, p90, min) and of the process's CPU time (cpu_median, cpu_p90: the "
            "cost on one core, whatever else shares it)"
        ),
    }
    try:
        result["gl_renderer"] = gl_renderer_name()
    except RenderError as exc:
        result["gl_renderer"] = None
        result["gl_unavailable"] = str(exc)
    dataset = args.dataset or builtin_dataset(dense=True)
    with Twin(scenario, dataset_dir=dataset, perception_enabled=False) as twin:
        twin.reset(seed=0)
        rigs: dict[str, CameraRig] = {}
        for name in wanted:
            try:
                rigs[name] = CameraRig(twin, renderer=name)
            except RenderError as exc:
                result.setdefault("unavailable", {})[name] = str(exc)
        try:
            samples = _time_rounds(twin, rigs, args.rounds, result)
        finally:
            for rig in rigs.values():
                rig.close()
        result["objects_on_belt"] = sum(1 for o in twin.observe_objects() if o.on_belt)
    _figures(samples, result)
    print(json.dumps(result) if args.json else json.dumps(result, indent=2))
    return 0
