"""Perception scored against ground truth: instance matching, recall, precision, class and pose.

A frame's predicted and true instances (:class:`InstanceSet`: a label image or a list of masks,
a class per instance, optionally a centroid and a yaw per instance) are matched one to one by
mask IoU, at least ``iou_threshold`` (0.5), with the assignment that maximises the summed IoU
(``scipy.optimize.linear_sum_assignment``). Over matched pairs: class accuracy, the confusion
matrix (rows: true class, columns: predicted class), the centroid error (same units as the
centroids given: metres in the world from the twin, pixels on photos) and the yaw error of the
long axis modulo pi (only where both sides give a finite value: give NaN for a piece whose axis
means nothing, such as a square). Recall is matched / true instances.

Unlabelled ground truth: on real photos annotators left small pieces unlabelled, so a detection
of such a piece is not wrong. With ``labelled_overlap = f`` precision counts only the detections
that are matched or whose area lies at least ``f`` inside the union of the labelled masks; the
others are "unassessed" and reported as a count (``precision_all`` counts every detection as the
plain definition does). With ``labelled_overlap = None`` (ground truth complete: the twin's
renders) every detection counts. The output states the policy in words.

:class:`PerceptionScorer` accumulates frames; :class:`PerceptionScore` is the result, with
``to_data()`` for JSON. Pure numpy/scipy, no ROS.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from detector.errors import DetectorConfigError, FrameError
from interfaces.detections import wrap_half_pi


@dataclass(frozen=True, kw_only=True, eq=False)
class InstanceSet:
    """The instances of one frame, predicted or true.

    Either ``labels`` ``(H, W) int`` (0: none, ``k``: instance ``k``, 1-based, every instance
    disjoint) or ``masks`` (each ``(H, W) bool``, overlaps allowed) describes the pixels;
    ``class_names[k - 1]`` is instance ``k``'s class; ``centroids`` ``(n, 2) float`` and
    ``yaws_rad`` ``(n,) float`` are optional (NaN: unknown). Build it with
    :meth:`from_labels`, :meth:`from_id_image` or :meth:`from_masks`.
    """

    shape: tuple[int, int]
    class_names: tuple[str, ...]
    labels: np.ndarray | None = None
    masks: tuple[np.ndarray, ...] | None = None
    centroids: np.ndarray | None = None
    yaws_rad: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.class_names)
        if (self.labels is None) == (self.masks is None):
            msg = "InstanceSet: give exactly one of labels or masks"
            raise FrameError(msg)
        if self.masks is not None and len(self.masks) != n:
            msg = f"InstanceSet: {len(self.masks)} masks but {n} class names"
            raise FrameError(msg)
        if self.centroids is not None and np.shape(self.centroids) != (n, 2):
            msg = f"InstanceSet.centroids: shape {np.shape(self.centroids)}, expected ({n}, 2)"
            raise FrameError(msg)
        if self.yaws_rad is not None and np.shape(self.yaws_rad) != (n,):
            msg = f"InstanceSet.yaws_rad: shape {np.shape(self.yaws_rad)}, expected ({n},)"
            raise FrameError(msg)

    def __len__(self) -> int:
        return len(self.class_names)

    @classmethod
    def from_labels(
        cls,
        labels: np.ndarray,
        class_names: Sequence[str],
        *,
        centroids: np.ndarray | None = None,
        yaws_rad: np.ndarray | None = None,
    ) -> InstanceSet:
        """Instances ``1..n`` of a label image ``(H, W)``, ``class_names[k - 1]`` for ``k``."""
        labels = np.asarray(labels)
        if labels.ndim != 2 or not np.issubdtype(labels.dtype, np.integer):
            msg = f"labels: expected an (H, W) integer image, got {labels.dtype} {labels.shape}"
            raise FrameError(msg)
        top = int(labels.max(initial=0))
        if top > len(class_names) or int(labels.min(initial=0)) < 0:
            msg = f"labels: ids up to {top} but {len(class_names)} class names"
            raise FrameError(msg)
        return cls(
            shape=(labels.shape[0], labels.shape[1]),
            class_names=tuple(class_names),
            labels=labels,
            centroids=None if centroids is None else np.asarray(centroids, dtype=np.float64),
            yaws_rad=None if yaws_rad is None else np.asarray(yaws_rad, dtype=np.float64),
        )

    @classmethod
    def from_id_image(
        cls,
        ids: np.ndarray,
        classes: Mapping[int, str],
        *,
        centroids: Mapping[int, tuple[float, float]] | None = None,
        yaws_rad: Mapping[int, float] | None = None,
    ) -> InstanceSet:
        """Instances of an id image ``(H, W)`` (each non-zero id one instance, as a renderer's
        ``instance_ids``); ``classes[id]`` its class, ``centroids``/``yaws_rad`` by id."""
        ids = np.asarray(ids)
        if int(ids.min(initial=0)) < 0:
            msg = "ids: negative instance ids"
            raise FrameError(msg)
        present = np.flatnonzero(np.bincount(ids.ravel().astype(np.intp, copy=False)))
        present = present[present != 0]
        missing = [int(i) for i in present if int(i) not in classes]
        if missing:
            msg = f"ids: instance ids {missing[:5]} have no class in the classes given"
            raise FrameError(msg)
        lut = np.zeros(int(present.max(initial=0)) + 1 if present.size else 1, dtype=np.int32)
        lut[present] = np.arange(1, present.size + 1)
        order = [int(i) for i in present]
        return cls.from_labels(
            lut[ids],
            [classes[i] for i in order],
            centroids=None
            if centroids is None
            else np.array([centroids.get(i, (math.nan, math.nan)) for i in order]).reshape(-1, 2),
            yaws_rad=None
            if yaws_rad is None
            else np.array([yaws_rad.get(i, math.nan) for i in order], dtype=np.float64),
        )

    @classmethod
    def from_masks(
        cls,
        masks: Sequence[np.ndarray],
        class_names: Sequence[str],
        *,
        shape: tuple[int, int] | None = None,
        centroids: np.ndarray | None = None,
        yaws_rad: np.ndarray | None = None,
    ) -> InstanceSet:
        """Instances given as masks (each ``(H, W) bool``; ``shape`` needed when empty)."""
        checked = tuple(np.asarray(m, dtype=bool) for m in masks)
        if shape is None:
            if not checked:
                msg = "from_masks: no masks and no shape"
                raise FrameError(msg)
            shape = (checked[0].shape[0], checked[0].shape[1])
        for i, m in enumerate(checked):
            if m.shape != shape:
                msg = f"masks[{i}]: shape {m.shape}, expected {shape}"
                raise FrameError(msg)
        return cls(
            shape=shape,
            class_names=tuple(class_names),
            masks=checked,
            centroids=None if centroids is None else np.asarray(centroids, dtype=np.float64),
            yaws_rad=None if yaws_rad is None else np.asarray(yaws_rad, dtype=np.float64),
        )

    def areas(self) -> np.ndarray:
        """Pixels per instance, ``(n,) int64``."""
        if self.labels is not None:
            return np.bincount(self.labels.ravel(), minlength=len(self) + 1)[1:].astype(np.int64)
        assert self.masks is not None
        return np.array([int(m.sum()) for m in self.masks], dtype=np.int64)

    def union(self) -> np.ndarray:
        """Pixels covered by any instance, ``(H, W) bool``."""
        if self.labels is not None:
            out: np.ndarray = self.labels > 0
            return out
        assert self.masks is not None
        union = np.zeros(self.shape, dtype=bool)
        for m in self.masks:
            union |= m
        return union

    def packed(self) -> np.ndarray:
        """Each instance's mask, bit-packed, ``(n, ceil(H W / 8)) uint8``."""
        if self.masks is not None:
            stack = np.stack(self.masks) if self.masks else np.zeros((0, *self.shape), bool)
        else:
            assert self.labels is not None
            stack = self.labels[None] == np.arange(1, len(self) + 1)[:, None, None]
        out: np.ndarray = np.packbits(stack.reshape(len(self), -1), axis=1)
        return out


def intersections(truth: InstanceSet, predicted: InstanceSet) -> np.ndarray:
    """Pixels shared by every true and predicted instance, ``(n_truth, n_pred) int64``."""
    if truth.shape != predicted.shape:
        msg = f"truth is {truth.shape}, the prediction {predicted.shape}: not the same image"
        raise FrameError(msg)
    nt, npred = len(truth), len(predicted)
    if nt == 0 or npred == 0:
        return np.zeros((nt, npred), dtype=np.int64)
    if truth.labels is not None and predicted.labels is not None:
        joint = truth.labels.astype(np.int64).ravel() * (npred + 1) + predicted.labels.ravel()
        counts = np.bincount(joint, minlength=(nt + 1) * (npred + 1))
        out: np.ndarray = counts.reshape(nt + 1, npred + 1)[1:, 1:]
        return out
    pt, pp = truth.packed(), predicted.packed()
    return np.stack([np.bitwise_count(pp & row).sum(axis=1, dtype=np.int64) for row in pt])


def iou_matrix(truth: InstanceSet, predicted: InstanceSet) -> np.ndarray:
    """Mask IoU of every true and predicted instance, ``(n_truth, n_pred) float``."""
    inter = intersections(truth, predicted).astype(np.float64)
    union = truth.areas()[:, None] + predicted.areas()[None, :] - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        out: np.ndarray = np.where(union > 0, inter / union, 0.0)
    return out


@dataclass(frozen=True, kw_only=True)
class FrameMatch:
    """One frame's matching: pairs ``(truth index, predicted index)`` (0-based) with their IoU,
    and which predictions precision assesses."""

    pairs: tuple[tuple[int, int], ...]
    ious: tuple[float, ...]
    truth_count: int
    predicted_count: int
    assessed: tuple[bool, ...]

    @property
    def recall(self) -> float:
        """Matched / true instances (NaN without any)."""
        return len(self.pairs) / self.truth_count if self.truth_count else math.nan

    @property
    def precision(self) -> float:
        """Matched / assessed predictions (NaN without any)."""
        n = sum(self.assessed)
        return len(self.pairs) / n if n else math.nan


def match_frame(
    truth: InstanceSet,
    predicted: InstanceSet,
    *,
    iou_threshold: float = 0.5,
    labelled_overlap: float | None = None,
) -> FrameMatch:
    """Optimal one-to-one matching at IoU >= ``iou_threshold`` (see the module)."""
    iou = iou_matrix(truth, predicted)
    pairs: list[tuple[int, int]] = []
    ious: list[float] = []
    if iou.size:
        rows, cols = linear_sum_assignment(-iou)
        for r, c in zip(rows, cols, strict=True):
            if iou[r, c] >= iou_threshold:
                pairs.append((int(r), int(c)))
                ious.append(float(iou[r, c]))
    matched = {c for _, c in pairs}
    if labelled_overlap is None:
        assessed = tuple(True for _ in range(len(predicted)))
    else:
        inside = _inside_fraction(predicted, truth.union())
        assessed = tuple(
            j in matched or inside[j] >= labelled_overlap for j in range(len(predicted))
        )
    return FrameMatch(
        pairs=tuple(pairs),
        ious=tuple(ious),
        truth_count=len(truth),
        predicted_count=len(predicted),
        assessed=assessed,
    )


def _inside_fraction(predicted: InstanceSet, labelled: np.ndarray) -> np.ndarray:
    """Share of each predicted instance's pixels inside ``labelled`` ``(H, W) bool``."""
    areas = predicted.areas().astype(np.float64)
    if predicted.labels is not None:
        inside = np.bincount(
            predicted.labels.ravel(), weights=labelled.ravel(), minlength=len(predicted) + 1
        )[1:]
    else:
        assert predicted.masks is not None
        inside = np.array([float((m & labelled).sum()) for m in predicted.masks])
    with np.errstate(invalid="ignore", divide="ignore"):
        out: np.ndarray = np.where(areas > 0, inside / areas, 0.0)
    return out


def _percentile(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else math.nan


@dataclass(frozen=True, kw_only=True)
class PerceptionScore:
    """Scores over all frames added to a :class:`PerceptionScorer` (NaN where undefined)."""

    frames: int
    truth_instances: int
    predicted_instances: int
    assessed_predictions: int
    unassessed_predictions: int
    matched: int
    recall: float
    precision: float
    precision_all: float
    mean_matched_iou: float
    class_accuracy: float
    class_names: tuple[str, ...]
    confusion: tuple[tuple[int, ...], ...]
    centroid_error_median: float
    centroid_error_p90: float
    centroid_unit: str
    yaw_error_median_rad: float
    yaw_error_p90_rad: float
    iou_threshold: float
    labelled_overlap: float | None
    precision_policy: str

    def to_data(self) -> dict[str, object]:
        """Plain JSON data (NaN as ``null``; the confusion matrix with its class order)."""

        def clean(value: float) -> float | None:
            return None if math.isnan(value) else round(float(value), 6)

        return {
            "frames": int(self.frames),
            "truth_instances": int(self.truth_instances),
            "predicted_instances": int(self.predicted_instances),
            "assessed_predictions": int(self.assessed_predictions),
            "unassessed_predictions": int(self.unassessed_predictions),
            "matched": int(self.matched),
            "recall": clean(self.recall),
            "precision": clean(self.precision),
            "precision_all": clean(self.precision_all),
            "mean_matched_iou": clean(self.mean_matched_iou),
            "class_accuracy": clean(self.class_accuracy),
            "confusion": {
                "rows": "true class",
                "columns": "predicted class",
                "classes": list(self.class_names),
                "matrix": [list(row) for row in self.confusion],
            },
            "centroid_error": {
                "unit": self.centroid_unit,
                "median": clean(self.centroid_error_median),
                "p90": clean(self.centroid_error_p90),
            },
            "yaw_error_rad": {
                "median": clean(self.yaw_error_median_rad),
                "p90": clean(self.yaw_error_p90_rad),
            },
            "iou_threshold": self.iou_threshold,
            "labelled_overlap": self.labelled_overlap,
            "precision_policy": self.precision_policy,
        }


@dataclass(kw_only=True)
class PerceptionScorer:
    """Accumulates matched frames into a :class:`PerceptionScore`.

    ``class_names``: the classes listed first in the confusion matrix (others are appended as
    they appear); ``centroid_unit``: what the centroids given are in (``m``, ``px``).
    """

    iou_threshold: float = 0.5
    labelled_overlap: float | None = None
    class_names: tuple[str, ...] = ()
    centroid_unit: str = "m"
    _frames: int = 0
    _truth: int = 0
    _predicted: int = 0
    _assessed: int = 0
    _matched: int = 0
    _ious: list[float] = field(default_factory=list)
    _pairs: list[tuple[str, str]] = field(default_factory=list)
    _centroid_errors: list[float] = field(default_factory=list)
    _yaw_errors: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not 0.0 < self.iou_threshold <= 1.0:
            msg = f"iou_threshold = {self.iou_threshold!r}: must lie in (0, 1]"
            raise DetectorConfigError(msg)
        if self.labelled_overlap is not None and not 0.0 <= self.labelled_overlap <= 1.0:
            msg = f"labelled_overlap = {self.labelled_overlap!r}: must lie in [0, 1] or be None"
            raise DetectorConfigError(msg)

    def add(self, predicted: InstanceSet, truth: InstanceSet) -> FrameMatch:
        """Match one frame and add it to the totals; its own matching is returned."""
        match = match_frame(
            truth,
            predicted,
            iou_threshold=self.iou_threshold,
            labelled_overlap=self.labelled_overlap,
        )
        self._frames += 1
        self._truth += match.truth_count
        self._predicted += match.predicted_count
        self._assessed += int(sum(match.assessed))
        self._matched += len(match.pairs)
        self._ious.extend(match.ious)
        for t, p in match.pairs:
            self._pairs.append((truth.class_names[t], predicted.class_names[p]))
            if truth.centroids is not None and predicted.centroids is not None:
                err = float(np.hypot(*(predicted.centroids[p] - truth.centroids[t])))
                if math.isfinite(err):
                    self._centroid_errors.append(err)
            if truth.yaws_rad is not None and predicted.yaws_rad is not None:
                a, b = float(predicted.yaws_rad[p]), float(truth.yaws_rad[t])
                if math.isfinite(a) and math.isfinite(b):
                    self._yaw_errors.append(abs(wrap_half_pi(a - b)))
        return match

    def result(self) -> PerceptionScore:
        """The scores so far."""
        names = list(self.class_names)
        for t, p in self._pairs:
            for name in (t, p):
                if name not in names:
                    names.append(name)
        index = {n: i for i, n in enumerate(names)}
        confusion = np.zeros((len(names), len(names)), dtype=np.int64)
        for t, p in self._pairs:
            confusion[index[t], index[p]] += 1
        correct = sum(t == p for t, p in self._pairs)
        if self.labelled_overlap is None:
            policy = "every detection counts (ground truth taken as complete)"
        else:
            policy = (
                "precision counts matched detections and those with at least "
                f"{self.labelled_overlap:g} of their area inside a labelled region; the others "
                "(likely unlabelled pieces) are unassessed; precision_all counts every detection"
            )
        return PerceptionScore(
            frames=self._frames,
            truth_instances=self._truth,
            predicted_instances=self._predicted,
            assessed_predictions=self._assessed,
            unassessed_predictions=self._predicted - self._assessed,
            matched=self._matched,
            recall=self._matched / self._truth if self._truth else math.nan,
            precision=self._matched / self._assessed if self._assessed else math.nan,
            precision_all=self._matched / self._predicted if self._predicted else math.nan,
            mean_matched_iou=float(np.mean(self._ious)) if self._ious else math.nan,
            class_accuracy=correct / len(self._pairs) if self._pairs else math.nan,
            class_names=tuple(names),
            confusion=tuple(tuple(int(v) for v in row) for row in confusion),
            centroid_error_median=_percentile(self._centroid_errors, 50),
            centroid_error_p90=_percentile(self._centroid_errors, 90),
            centroid_unit=self.centroid_unit,
            yaw_error_median_rad=_percentile(self._yaw_errors, 50),
            yaw_error_p90_rad=_percentile(self._yaw_errors, 90),
            iou_threshold=self.iou_threshold,
            labelled_overlap=self.labelled_overlap,
            precision_policy=policy,
        )


__all__ = [
    "FrameMatch",
    "InstanceSet",
    "PerceptionScore",
    "PerceptionScorer",
    "intersections",
    "iou_matrix",
    "match_frame",
]
