"""The camera's perception scored against the twin's ground truth, frame by frame, per episode.

Every camera frame the twin renders carries the truth: the renderer's instance-id image (which
object each pixel shows). :class:`EpisodeScorer` matches the detector's instances to it with
:mod:`detector.score` (one-to-one by mask IoU >= 0.5) and accumulates, over the episode:

- ``recall``: matched / scored true pieces; ``precision``: matched / scored detections;
- ``class_accuracy`` over matched pairs, and the confusion counts (``confusion/TRUE/PREDICTED``);
- ``centroid_error_median_m`` / ``_p90_m``: the detection's centroid against the piece's true
  centre of mass, in the belt plane (x, y);
- ``yaw_error_median_rad`` / ``_p90_rad``: the long axis modulo pi, only for pieces whose face
  turned up is elongated (length at least :data:`YAW_ELONGATION` times its width: a square's axis
  means nothing);
- ``latency_median_ms`` / ``_p90_ms``: from exposure to detection, the detector's measured
  compute time per frame (wall clock); ``render_median_ms``: the render's;
- ``frames``, ``truth_instances``, ``detections``, ``matched``: the counts behind them.

Which pieces are scored: a piece on the belt, not held by a tool, whose visible mask does not
touch the image's border (partly out of view) and covers at least :data:`MIN_TRUTH_PX` pixels
(mostly hidden under an arm or another piece). A detection lying for the most part
(:data:`IGNORED_OVERLAP`) on a piece left out is left out too: neither a hit nor a false alarm.
Every other detection counts (the twin's truth is complete: nothing is unlabelled).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from detector.detector import DetectorOutput
from detector.score import InstanceSet, PerceptionScorer
from interfaces.camera import RgbdFrame
from twin.monitor import GroundTruth

__all__ = [
    "IGNORED_OVERLAP",
    "MIN_TRUTH_PX",
    "PERCEPTION_METRICS",
    "YAW_ELONGATION",
    "EpisodeScorer",
]

PERCEPTION_METRICS = (
    "frames",
    "recall",
    "precision",
    "class_accuracy",
    "centroid_error_median_m",
    "centroid_error_p90_m",
    "yaw_error_median_rad",
    "yaw_error_p90_rad",
    "latency_median_ms",
    "latency_p90_ms",
    "render_median_ms",
    "truth_instances",
    "detections",
    "matched",
)
"""The keys of :meth:`twin.sim.Twin.perception_summary` (besides the ``confusion/TRUE/PRED``
counts), in this order; ``docs/camera.md`` defines each."""

MIN_TRUTH_PX = 60
"""A true piece showing fewer pixels than this is not scored (mostly hidden)."""

IGNORED_OVERLAP = 0.5
"""A detection with at least this share of its pixels on a piece not scored is not scored."""

YAW_ELONGATION = 1.2
"""A piece's yaw is scored only when its top view is at least this many times longer than wide."""


@dataclass(frozen=True, kw_only=True, eq=False)
class _Truth:
    """One frame's scored truth and the pixels of the pieces left out, ``(H, W) bool``."""

    instances: InstanceSet
    ignored: np.ndarray


def _truth(ids: np.ndarray, objects: Mapping[int, GroundTruth]) -> _Truth:
    """The pieces of id image ``ids`` ``(H, W) int32`` that are scored (see the module)."""
    pixels = np.bincount(ids.ravel())  # ids are small and >= 0: a count per id, no sort
    present = np.flatnonzero(pixels)
    counts = pixels[present]
    edge = set(np.concatenate((ids[0], ids[-1], ids[:, 0], ids[:, -1])).tolist())
    kept: dict[int, str] = {}
    ignored_ids = []
    for object_id, count in zip(present.tolist(), counts.tolist(), strict=True):
        if object_id == 0:
            continue
        truth = objects.get(object_id)
        scored = (
            truth is not None
            and truth.on_belt
            and not truth.held
            and count >= MIN_TRUTH_PX
            and object_id not in edge
        )
        if scored and truth is not None:
            kept[object_id] = truth.class_name
        else:
            ignored_ids.append(object_id)
    if ignored_ids:
        left_out = np.zeros(pixels.size, dtype=bool)
        left_out[ignored_ids] = True
        ignored = left_out[ids]
    else:
        ignored = np.zeros(ids.shape, dtype=bool)
    scored_ids = np.where(ignored, 0, ids)
    centroids = {i: (objects[i].position_m[0], objects[i].position_m[1]) for i in kept}
    yaws = {
        i: objects[i].top_view.yaw_rad
        if objects[i].top_view.length_m >= YAW_ELONGATION * objects[i].top_view.width_m
        else math.nan
        for i in kept
    }
    instances = InstanceSet.from_id_image(scored_ids, kept, centroids=centroids, yaws_rad=yaws)
    return _Truth(instances=instances, ignored=ignored)


def _predicted(output: DetectorOutput, ignored: np.ndarray) -> InstanceSet:
    """The detector's instances, less those lying mostly on pieces not scored."""
    labels = output.labels
    n = len(output.instances)
    area = np.bincount(labels.ravel(), minlength=n + 1).astype(np.float64)
    inside = np.bincount(labels.ravel(), weights=ignored.ravel(), minlength=n + 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(area > 0, inside / area, 0.0)
    keep = share < IGNORED_OVERLAP
    keep[0] = False
    lut = np.zeros(n + 1, dtype=np.int32)
    lut[keep] = np.arange(1, int(keep.sum()) + 1)
    kept = [i for i in output.instances if keep[i.label]]
    dets = [i.detection for i in kept]
    return InstanceSet.from_labels(
        lut[labels],
        [i.class_name for i in kept],
        centroids=np.array(
            [(d.x_m, d.y_m) if d else (math.nan, math.nan) for d in dets], dtype=np.float64
        ).reshape(-1, 2),
        yaws_rad=np.array([d.yaw_rad if d else math.nan for d in dets], dtype=np.float64),
    )


def _percentile(values: Sequence[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else math.nan


class EpisodeScorer:
    """Accumulates one episode's camera frames (see the module); ``classes`` are listed first in
    the confusion counts."""

    def __init__(self, classes: Sequence[str] = ()) -> None:
        self._scorer = PerceptionScorer(class_names=tuple(classes), centroid_unit="m")
        self._latency_ms: list[float] = []
        self._render_ms: list[float] = []

    def add(
        self,
        frame: RgbdFrame,
        output: DetectorOutput,
        objects: Mapping[int, GroundTruth],
        *,
        detect_s: float,
        render_s: float,
    ) -> None:
        """Score one frame: ``output`` is the detector's on ``frame`` (whose ``instance_ids``
        are the truth), ``objects`` the ground truth at its exposure by object id, ``detect_s``
        and ``render_s`` the measured compute times."""
        self._latency_ms.append(1000.0 * detect_s)
        self._render_ms.append(1000.0 * render_s)
        if frame.instance_ids is None:
            return
        truth = _truth(frame.instance_ids, objects)
        self._scorer.add(_predicted(output, truth.ignored), truth.instances)

    def summary(self) -> dict[str, float]:
        """The episode's figures, flat (keys :data:`PERCEPTION_METRICS`, NaN where undefined,
        and ``confusion/TRUE/PREDICTED`` counts of every pair of classes)."""
        score = self._scorer.result()
        out: dict[str, float] = {
            "frames": float(score.frames),
            "recall": score.recall,
            "precision": score.precision,
            "class_accuracy": score.class_accuracy,
            "centroid_error_median_m": score.centroid_error_median,
            "centroid_error_p90_m": score.centroid_error_p90,
            "yaw_error_median_rad": score.yaw_error_median_rad,
            "yaw_error_p90_rad": score.yaw_error_p90_rad,
            "latency_median_ms": _percentile(self._latency_ms, 50),
            "latency_p90_ms": _percentile(self._latency_ms, 90),
            "render_median_ms": _percentile(self._render_ms, 50),
            "truth_instances": float(score.truth_instances),
            "detections": float(score.predicted_instances),
            "matched": float(score.matched),
        }
        for i, true_name in enumerate(score.class_names):
            for j, predicted_name in enumerate(score.class_names):
                out[f"confusion/{true_name}/{predicted_name}"] = float(score.confusion[i][j])
        return out
