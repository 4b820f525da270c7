"""``cdw-twin perception fit``: refit the oracle's error model from the camera's measured errors.

Runs the twin of a camera scenario (``perception.source: camera``) alone, no controller (the
arms wait at home, so nothing hides a piece but other pieces), sets every released detection
frame against the ground truth at its exposure (:mod:`twin.oracle_fit`) and writes the
``perception:`` block of an oracle that errs as the camera did: position noise with its share of
outliers, yaw noise, drop and misclassification rates, the camera's rate and latency, and
``fitted_from`` naming the run it came from. Paste the block into a scenario (or start from the
one written) to run the cheap oracle with the camera's error figures, and compare it with the
camera in the closed loop to see what the oracle's model leaves out (spurious fragments, errors
that persist from frame to frame, pieces hidden by the arm: counted in the output, not
modelled).

Example::

    cdw-twin perception fit experiments/scenarios/line_camera.yaml --duration 20 \\
        --out perception_fit.yaml --json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from interfaces.fileio import write_atomic
from twin.errors import CdwTwinError
from twin.oracle_fit import FitSample, FrameMatch, OracleFit, TruthPiece, fit_oracle, match_frame

if TYPE_CHECKING:
    from interfaces.cell import Cell
    from twin.ground_truth import GroundTruth
    from twin.scenario import Scenario

__all__ = ["FitError", "configure", "fit_header", "fit_yaml", "measure", "run"]

FLUSH_S = 0.3
"""Simulated seconds stepped after the duration so that the last frames are released."""


class FitError(CdwTwinError):
    """A fit that cannot be made: the scenario has no camera, or nothing was matched."""


def _views(cell: Cell) -> tuple[tuple[float, float], ...]:
    from interfaces.camera import belt_view_x_m

    views = []
    for spec in cell.cameras:
        view = belt_view_x_m(
            spec, centre_y_m=cell.belt.centre_y_m, surface_z_m=cell.belt.surface_z_m
        )
        if view is not None:
            views.append(view)
    return tuple(views)


def in_view(
    objects: Sequence[GroundTruth], views: Sequence[tuple[float, float]]
) -> list[TruthPiece]:
    """The pieces a camera should report: on the belt, not held, wholly inside some camera's
    stretch of the belt (centre at least half the piece's length from the view's ends)."""
    out = []
    for obj in objects:
        if not obj.on_belt or obj.held:
            continue
        x_m, y_m, _ = obj.position_m
        half_m = 0.5 * max(obj.top_view.length_m, obj.top_view.width_m)
        if not any(lo + half_m <= x_m <= hi - half_m for lo, hi in views):
            continue
        out.append(
            TruthPiece(
                object_id=obj.id,
                class_name=obj.class_name,
                x_m=x_m,
                y_m=y_m,
                yaw_rad=obj.top_view.yaw_rad,
                length_m=obj.top_view.length_m,
                width_m=obj.top_view.width_m,
            )
        )
    return out


def measure(scenario: Scenario, dataset: Path, cell: Cell) -> FitSample:
    """Run the twin of ``scenario`` alone and pool its frames' matches (see the module)."""
    from twin.camera.schedule import frame_due
    from twin.sim import Twin

    if scenario.perception.source != "camera":
        msg = (
            f"perception.source = {scenario.perception.source!r}: the fit needs the camera "
            "(a scenario with perception.source: camera, such as experiments/scenarios/camera.yaml)"
        )
        raise FitError(msg)
    views = _views(cell)
    truth_at: dict[int, list[TruthPiece]] = {}
    matches: list[FrameMatch] = []
    with Twin(scenario, dataset_dir=dataset, cell=cell) as twin:
        twin.reset(seed=scenario.seed)
        physics_hz = 1.0 / twin.dt_s
        steps = math.ceil(
            (scenario.duration_s + scenario.perception.latency_s + FLUSH_S) / twin.dt_s
        )
        for _ in range(steps):
            twin.advance()
            if frame_due(twin.step_count, scenario.perception.rate_hz, physics_hz):
                truth_at[twin.step_count] = in_view(twin.observe_objects(), views)
            for frame in twin.take_detections():
                step = round(frame.capture_time_s / twin.dt_s)
                truth = truth_at.pop(step, None)
                if truth is not None and frame.capture_time_s <= scenario.duration_s:
                    matches.append(match_frame(frame.detections, truth))
    return FitSample.of(matches)


def fit_header(scenario_path: Path | None, scenario: Scenario, cell: Cell, fit: OracleFit) -> str:
    """``fitted_from``: where the figures come from, on one line."""
    return (
        f"cdw-twin perception fit {scenario_path or 'default scenario'}: cell {cell.name}, "
        f"{len(cell.cameras)} camera(s) at {scenario.perception.rate_hz:g} Hz, seed "
        f"{scenario.seed}, {scenario.duration_s:g} s at {scenario.system.belt_speed_mps:g} m/s, "
        f"twin alone; {fit.frames} frames, {fit.matched} of {fit.truth_in_view} pieces in view "
        f"matched, {fit.yaw_samples} yaw samples"
    )


def fit_yaml(scenario: Scenario, fit: OracleFit, fitted_from: str) -> str:
    """The ``perception:`` block of the fitted oracle, with what it does not model as comments."""
    keys = {
        "source": "oracle",
        "rate_hz": scenario.perception.rate_hz,
        "latency_s": scenario.perception.latency_s,
        **fit.perception_keys(),
        "fitted_from": fitted_from,
    }
    lines = [
        "# The oracle's error model fitted to the camera's errors (cdw-twin perception fit).",
        f"# Not modelled by the oracle: {fit.spurious_per_frame:.2f} spurious detections per frame",
        "# (fragments matching no piece), errors that persist from frame to frame, pieces the arm",
        "# hides (the fit runs the twin without controllers).",
        "perception:",
        *(f"  {key}: {json.dumps(value)}" for key, value in keys.items()),
    ]
    return "\n".join(lines) + "\n"


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the fit's options."""
    parser.add_argument("scenario", type=Path, help="a camera scenario YAML")
    parser.add_argument("--dataset", type=Path, default=None, help="meshgen output folder")
    parser.add_argument("--cell", default=None, metavar="NAME_OR_PATH", help="cell file or name")
    parser.add_argument("--seed", type=int, default=None, help="seed (default: the scenario's)")
    parser.add_argument("--speed", type=float, default=None, help="belt speed, m/s")
    parser.add_argument(
        "--duration", type=float, default=20.0, help="simulated seconds to measure (20)"
    )
    parser.add_argument(
        "--prefill",
        type=float,
        default=None,
        metavar="M",
        help="metres of stream on the belt at the start (default: the scenario's)",
    )
    parser.add_argument("--out", type=Path, default=None, help="write the perception block here")
    parser.add_argument("--json", action="store_true", help="print the fit as JSON")


def run(args: argparse.Namespace) -> int:
    """Measure, fit, print (and write ``--out``)."""
    from twin.cmd_node import build_scenario

    if not (math.isfinite(args.duration) and 1.0 <= args.duration <= 3600.0):
        msg = f"--duration {args.duration}: must be in [1, 3600] s"
        raise FitError(msg)
    scenario, dataset, cell = build_scenario(
        argparse.Namespace(
            scenario=args.scenario,
            cell=args.cell,
            dataset=args.dataset,
            seed=args.seed,
            prefill=args.prefill,
            speed=args.speed,
            duration=args.duration,
            objects=None,
        )
    )
    sample = measure(scenario, dataset, cell)
    try:
        fit = fit_oracle(sample)
    except ValueError as exc:
        raise FitError(f"{args.scenario}: {exc}") from None
    fitted_from = fit_header(args.scenario, scenario, cell, fit)
    if args.out is not None:
        try:
            write_atomic(args.out, fit_yaml(scenario, fit, fitted_from))
        except OSError as exc:
            msg = f"--out {args.out}: cannot write: {exc.strerror}"
            raise FitError(msg) from None
    if args.json:
        print(json.dumps({**dataclasses.asdict(fit), "fitted_from": fitted_from}, indent=2))
    else:
        for key, value in fit.perception_keys().items():
            print(f"{key:>26}: {value}")
        print(f"{'spurious per frame':>26}: {fit.spurious_per_frame:.2f}")
        print(f"{'fitted_from':>26}: {fitted_from}")
    return 0
