"""The report's perception section: how well the camera saw, for runs with ``perception.source:
camera`` (none for the oracle's: it has nothing to score).

Per cell and belt speed, over the episodes whose twin scored its camera frames (the summary's
``perception`` block, :mod:`twin.perception_score`, ``docs/metrics.md``):

- recall and precision at mask IoU 0.5 of the pooled counts
  (:data:`interfaces.run_records.PERCEPTION_RATES`: matched / true pieces in view, matched /
  detections) with 95 % Wilson intervals (:func:`experiments.stats.wilson_interval`);
- class accuracy of the pooled class confusion (matched pieces given their true class / matched
  pieces), with its Wilson interval;
- centroid and yaw errors and the detector's latency: the mean over the episodes of each
  episode's median and 90th percentile (percentiles of different episodes do not pool);
- the pooled class confusion (true class in rows, detected class in columns);
- each episode's example frames, the camera's image with its detections drawn
  (``twin/camera_NAME.png``, :func:`interfaces.run_folder.camera_frame_name`), copied next to
  the report.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from experiments import stats
from experiments.report_data import Episode, RunData
from interfaces.run_folder import EpisodeFolder
from interfaces.run_records import PERCEPTION_RATES

Interval = tuple[float, float]
"""A 95 % interval, (low, high)."""

CONFUSION = "confusion/"
"""The prefix of a summary's confusion counts: ``confusion/TRUE/PREDICTED``."""


@dataclass(frozen=True)
class PerceptionLine:
    """The camera's scores of one cell at one belt speed, over its scored episodes."""

    cell: str
    speed_mps: float
    episodes: int
    frames: int
    truth_instances: int
    recall: float | None
    recall_ci95: Interval | None
    precision: float | None
    precision_ci95: Interval | None
    class_accuracy: float | None
    class_accuracy_ci95: Interval | None
    centroid_error_median_mm: float | None
    centroid_error_p90_mm: float | None
    yaw_error_median_deg: float | None
    yaw_error_p90_deg: float | None
    latency_median_ms: float | None


PERCEPTION_COLUMNS: tuple[tuple[str, str], ...] = (
    ("cell", "cell"),
    ("speed_mps", "belt m/s"),
    ("episodes", "episodes"),
    ("frames", "frames"),
    ("truth_instances", "pieces in view"),
    ("recall", "recall (IoU 0.5)"),
    ("recall_ci95", "95 %"),
    ("precision", "precision"),
    ("precision_ci95", "95 %"),
    ("class_accuracy", "class accuracy"),
    ("class_accuracy_ci95", "95 %"),
    ("centroid_error_median_mm", "centroid error mm, median"),
    ("centroid_error_p90_mm", "p90"),
    ("yaw_error_median_deg", "yaw error deg, median"),
    ("yaw_error_p90_deg", "p90"),
    ("latency_median_ms", "detector ms, median"),
)


@dataclass(frozen=True)
class ConfusionLine:
    """One true class of a group: how many of its matched pieces got each detected class."""

    cell: str
    speed_mps: float
    true_class: str
    counts: Mapping[str, int]


def scored(ep: Episode) -> Mapping[str, float] | None:
    """The episode's perception scores (None for an oracle episode or without a summary)."""
    if ep.summary is None or not ep.summary.perception:
        return None
    return {k: float(v) for k, v in ep.summary.perception.items() if v is not None}


def _count(blocks: Sequence[Mapping[str, float]], key: str) -> int:
    return int(sum(b.get(key, 0.0) for b in blocks if math.isfinite(b.get(key, 0.0))))


def _mean(blocks: Sequence[Mapping[str, float]], key: str, scale: float) -> float | None:
    values = [b[key] * scale for b in blocks if key in b and math.isfinite(b[key])]
    return stats.mean_of(values)


def _rate(successes: int, trials: int) -> tuple[float | None, Interval | None]:
    low, high = stats.wilson_interval(successes, trials)
    if low is None or high is None:
        return None, None
    return successes / trials, (low, high)


def confusion(blocks: Sequence[Mapping[str, float]]) -> dict[str, dict[str, int]]:
    """The pooled confusion counts, ``{true: {detected: n}}``, classes in the summaries' order."""
    out: dict[str, dict[str, int]] = {}
    for block in blocks:
        for key, value in block.items():
            if key.startswith(CONFUSION):
                true, predicted = key[len(CONFUSION) :].split("/", 1)
                row = out.setdefault(true, {})
                row[predicted] = row.get(predicted, 0) + int(value)
    return out


def perception_rows(data: RunData) -> list[PerceptionLine]:
    """One row per cell and belt speed with scored episodes (none for oracle runs)."""
    rows = []
    for cell, speed in data.groups():
        blocks = [b for ep in data.in_group(cell, speed) if (b := scored(ep)) is not None]
        if not blocks:
            continue
        (recall, recall_ci), (precision, precision_ci) = (
            _rate(
                _count(blocks, PERCEPTION_RATES[name][0]), _count(blocks, PERCEPTION_RATES[name][1])
            )
            for name in ("recall", "precision")
        )
        table = confusion(blocks)
        right = sum(row.get(true, 0) for true, row in table.items())
        classified = sum(sum(row.values()) for row in table.values())
        accuracy, accuracy_ci = _rate(right, classified)
        rows.append(
            PerceptionLine(
                cell=cell,
                speed_mps=speed,
                episodes=len(blocks),
                frames=_count(blocks, "frames"),
                truth_instances=_count(blocks, "truth_instances"),
                recall=recall,
                recall_ci95=recall_ci,
                precision=precision,
                precision_ci95=precision_ci,
                class_accuracy=accuracy,
                class_accuracy_ci95=accuracy_ci,
                centroid_error_median_mm=_mean(blocks, "centroid_error_median_m", 1000.0),
                centroid_error_p90_mm=_mean(blocks, "centroid_error_p90_m", 1000.0),
                yaw_error_median_deg=_mean(blocks, "yaw_error_median_rad", 180.0 / math.pi),
                yaw_error_p90_deg=_mean(blocks, "yaw_error_p90_rad", 180.0 / math.pi),
                latency_median_ms=_mean(blocks, "latency_median_ms", 1.0),
            )
        )
    return rows


def confusion_table(data: RunData) -> tuple[list[str], list[ConfusionLine]]:
    """The detected classes (columns) and one row per group and true class."""
    columns: list[str] = []
    rows = []
    for cell, speed in data.groups():
        blocks = [b for ep in data.in_group(cell, speed) if (b := scored(ep)) is not None]
        for true, counts in confusion(blocks).items():
            columns += [c for c in counts if c not in columns]
            rows.append(ConfusionLine(cell=cell, speed_mps=speed, true_class=true, counts=counts))
    return columns, rows


def copy_example_frames(episodes: Sequence[Episode], staging: Path) -> list[tuple[str, str]]:
    """Copy every scored episode's example frames into ``staging/frames/``; ``(caption, file
    relative to the report)`` each, in episode order."""
    out = []
    for ep in episodes:
        if scored(ep) is None:
            continue
        for path in EpisodeFolder(ep.folder).camera_frames():
            target = staging / "frames" / f"{ep.run_dir.name}-{ep.folder.name}-{path.name}"
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, target)
            camera = path.stem.removeprefix("camera_")
            out.append((f"{ep.name}, camera {camera}", f"frames/{target.name}"))
    return out


__all__ = [
    "PERCEPTION_COLUMNS",
    "ConfusionLine",
    "PerceptionLine",
    "confusion",
    "confusion_table",
    "copy_example_frames",
    "perception_rows",
    "scored",
]
