"""The detector on a dataset's real photos, scored against their polygons.

For a YOLO-seg dataset with its photos (:mod:`detector.photos`): the photos are split per subset
into a training and a test part (``seed``, ``train_fraction``: the same seed gives the same split;
no photo is on both sides), the colour classifier is trained on the training photos' polygons,
and the detector runs on every test photo:

- in **colour** mode on every photo (most real photos have no depth; the pieces lie on a dark
  belt), and
- in **depth** mode where the dataset has a height image (``heights/``): its 8-bit levels are
  taken as relative heights (no metric scale): foreground above ``min_height_levels``, walls
  where a 3x3 neighbourhood spans more than ``jump_levels``; the colour classifier then labels
  the depth-mode instances.

Each mode is scored (:mod:`detector.score`) over its test photos, overall and per subset, with
the unlabelled-ground-truth policy for precision (annotators left small pieces unlabelled):
matched detections and those at least half inside a labelled region count, the others are
reported as unassessed. Centroid and yaw errors are in the image (pixels of the resized photo,
the long axis's angle). Segmentation has no training, so it is also scored on all photos
(classes not assessed there). Pure logic: the caller prints or writes the returned JSON data.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from detector.baseline import classify
from detector.classifier import DEFAULT_L2, ColourClassifier, fit_classifier
from detector.colour_segment import segment_colour
from detector.config import DetectorConfig
from detector.depth_segment import segment_heights
from detector.errors import DetectorConfigError
from detector.features import FEATURE_NAMES, instance_features
from detector.filters import median3
from detector.geometry import image_geometries
from detector.photos import Photo, PhotoDataset, read_photo_dataset
from detector.score import InstanceSet, PerceptionScorer, match_frame

LABELLED_OVERLAP = 0.5
"""A detection at least this much inside a labelled region counts for precision."""

NOTES: tuple[str, ...] = (
    "modes.*: the test photos only; class accuracy is over matched pairs",
    (
        "colour: every test photo; depth: the test photos with a height image, whose levels "
        "are relative heights (no metric scale); colour_on_height_photos: colour mode on those "
        "same photos, for comparison"
    ),
    (
        "segmentation_all_photos: every photo (segmentation is not trained; classes not "
        "assessed there)"
    ),
    (
        f"precision counts matched detections and those at least {LABELLED_OVERLAP:g} inside "
        "a labelled region (annotators left small pieces unlabelled); the rest are "
        "unassessed_predictions; precision_all counts every detection"
    ),
    (
        "centroid error in pixels of the resized photo; yaw error (long axis, modulo pi) only "
        "for pieces whose labelled outline is at least 1.3 times longer than wide"
    ),
    (
        "subsets whose photos hold one class each and were labelled automatically from the "
        "height images (the shared sample's Aauto, Bauto) make class accuracy there a measure "
        "of that labelling too"
    ),
    (
        "the colour-mode defaults (detector.config.ColourConfig) were tuned on the shared "
        "sample's 60 photos, training and test alike"
    ),
)
"""What the figures of :func:`bench_photos` mean, repeated in its output."""


@dataclass(frozen=True, kw_only=True)
class HeightLevels:
    """Depth-mode settings for a dataset's 8-bit height images (in levels, not metres)."""

    min_height_levels: float = 5.0
    jump_levels: float = 20.0
    min_peak_px: float = 6.0


def split_photos(
    photos: Sequence[Photo], *, seed: int, train_fraction: float
) -> tuple[list[Photo], list[Photo]]:
    """Training and test photos: within each subset, a seeded shuffle, the first
    ``train_fraction`` (rounded; at least one of a subset of two or more) for training."""
    if not 0.0 < train_fraction < 1.0:
        msg = f"train_fraction = {train_fraction!r}: must lie in (0, 1)"
        raise DetectorConfigError(msg)
    rng = np.random.default_rng(seed)
    train: list[Photo] = []
    test: list[Photo] = []
    for subset in sorted({p.subset for p in photos}):
        members = [p for p in photos if p.subset == subset]
        order = rng.permutation(len(members))
        k = round(train_fraction * len(members))
        k = min(max(k, 1 if len(members) > 1 else 0), len(members) - 1)
        train.extend(members[i] for i in order[:k])
        test.extend(members[i] for i in order[k:])
    return train, test


PHOTO_L2 = 0.1
"""The L2 penalty of the classifier trained on photos with their detected masks (held-out
class accuracy on the shared sample: 0.86 with 0.1, 0.81 with 0.01)."""


def _detected_samples(
    photos: Sequence[Photo], config: DetectorConfig, stride: int
) -> tuple[list[np.ndarray], list[str]]:
    """Features of the colour mode's instances of ``photos`` that match a polygon (IoU >= 0.5),
    with the polygon's class: the masks the classifier will see, not only the annotators'."""
    features: list[np.ndarray] = []
    labels: list[str] = []
    for photo in photos:
        found = segment_colour(photo.rgb, config=config.colour, stride=config.work_stride)
        n = int(found.max(initial=0))
        if n == 0:
            continue
        match = match_frame(_truth(photo), InstanceSet.from_labels(found, ["?"] * n))
        if not match.pairs:
            continue
        table = instance_features(photo.rgb, found, stride)
        features.append(table[[c for _, c in match.pairs]])
        labels.extend(photo.truth_classes[t] for t, _ in match.pairs)
    return features, labels


def train_on_photos(
    photos: Sequence[Photo],
    class_names: Sequence[str],
    *,
    stride: int = 2,
    l2: float = DEFAULT_L2,
    detected: DetectorConfig | None = None,
) -> ColourClassifier:
    """A colour classifier fitted on the polygons of ``photos``; with ``detected`` (the
    detector's configuration) also on the masks its colour mode finds there, matched to the
    polygons (:func:`_detected_samples`)."""
    features = [instance_features(p.rgb, p.truth_ids, stride) for p in photos]
    labels = [name for p in photos for name in p.truth_classes]
    if detected is not None:
        more, more_labels = _detected_samples(photos, detected, stride)
        features += more
        labels += more_labels
    return fit_classifier(
        np.concatenate(features) if features else np.zeros((0, len(FEATURE_NAMES))),
        labels,
        class_names=class_names,
        l2=l2,
        feature_stride=stride,
        training={
            "photos": [p.stem for p in photos],
            "instances": len(labels),
            "masks": "polygons and matched colour-mode masks" if detected else "polygons",
        },
    )


def _truth(photo: Photo) -> InstanceSet:
    geo = image_geometries(photo.truth_ids, len(photo.truth_classes))
    return InstanceSet.from_labels(
        photo.truth_ids,
        photo.truth_classes,
        centroids=np.array([g.centroid_uv_px for g in geo]).reshape(-1, 2),
        yaws_rad=np.array([g.axis_rad if g.length_px > 1.3 * g.width_px else np.nan for g in geo]),
    )


def _predicted(labels: np.ndarray, names: Sequence[str]) -> InstanceSet:
    geo = image_geometries(labels, len(names))
    return InstanceSet.from_labels(
        labels,
        names,
        centroids=np.array([g.centroid_uv_px for g in geo]).reshape(-1, 2),
        yaws_rad=np.array([g.axis_rad for g in geo]),
    )


def _segment(photo: Photo, mode: str, config: DetectorConfig, levels: HeightLevels) -> np.ndarray:
    if mode == "colour":
        return segment_colour(photo.rgb, config=config.colour, stride=config.work_stride)
    assert photo.heights is not None
    return segment_heights(
        median3(photo.heights),
        min_height=levels.min_height_levels,
        jump=levels.jump_levels,
        min_peak_px=levels.min_peak_px,
        merge_ratio=config.depth.split.merge_ratio,
        stride=config.work_stride,
        min_area=config.colour.min_area_px,
        pixel_area=1.0,
    )


def _run_mode(
    photos: Sequence[Photo],
    mode: str,
    *,
    classifier: ColourClassifier | None,
    config: DetectorConfig,
    levels: HeightLevels,
    class_names: Sequence[str],
) -> dict[str, object]:
    """Score one mode over ``photos`` (all, and per subset) and time it."""
    overall = PerceptionScorer(
        labelled_overlap=LABELLED_OVERLAP, class_names=tuple(class_names), centroid_unit="px"
    )
    by_subset: dict[str, PerceptionScorer] = {}
    seconds = []
    for photo in photos:
        start = time.perf_counter()
        labels = _segment(photo, mode, config, levels)
        names, _ = classify(
            photo.rgb,
            labels,
            classifier=classifier,
            unknown_class=config.unknown_class,
        )
        seconds.append(time.perf_counter() - start)
        predicted, truth = _predicted(labels, names), _truth(photo)
        overall.add(predicted, truth)
        scorer = by_subset.setdefault(
            photo.subset,
            PerceptionScorer(
                labelled_overlap=LABELLED_OVERLAP,
                class_names=tuple(class_names),
                centroid_unit="px",
            ),
        )
        scorer.add(predicted, truth)

    def data(scorer: PerceptionScorer) -> dict[str, object]:
        out = scorer.result().to_data()
        if classifier is None:  # segmentation only: classes are not assessed
            out["class_accuracy"] = None
            out["confusion"] = None
        return out

    return {
        "photos": len(photos),
        "all": data(overall),
        "by_subset": {k: data(v) for k, v in sorted(by_subset.items())},
        "median_ms_per_photo": round(float(np.median(seconds)) * 1e3, 1) if seconds else None,
    }


def bench_photos(
    dataset: Path | PhotoDataset,
    *,
    seed: int = 0,
    train_fraction: float = 0.5,
    max_size_px: tuple[int, int] = (640, 480),
    config: DetectorConfig | None = None,
    levels: HeightLevels | None = None,
    comparisons: bool = True,
) -> tuple[dict[str, object], ColourClassifier]:
    """Run and score the detector on a dataset's photos (see the module): the JSON data and
    the classifier trained on the training photos. ``comparisons``: also segmentation on all
    photos and colour mode on the photos with heights (doubles the time)."""
    data = (
        dataset
        if isinstance(dataset, PhotoDataset)
        else read_photo_dataset(Path(dataset), max_size_px=max_size_px)
    )
    cfg = config or DetectorConfig()
    lv = levels or HeightLevels()
    train, test = split_photos(data.photos, seed=seed, train_fraction=train_fraction)
    classifier = train_on_photos(
        train, data.class_names, stride=cfg.work_stride, l2=PHOTO_L2, detected=cfg
    )

    def run(photos: Sequence[Photo], mode: str, trained: ColourClassifier | None) -> object:
        return _run_mode(
            photos,
            mode,
            classifier=trained,
            config=cfg,
            levels=lv,
            class_names=data.class_names,
        )

    with_heights = [p for p in data.photos if p.heights is not None]
    with_heights_test = [p for p in test if p.heights is not None]
    modes: dict[str, object] = {"colour": run(test, "colour", classifier)}
    segmentation: dict[str, object] = {}
    if with_heights_test:
        modes["depth"] = run(with_heights_test, "depth", classifier)
    if comparisons:
        segmentation["colour"] = run(data.photos, "colour", None)
        if with_heights_test:
            modes["colour_on_height_photos"] = run(with_heights_test, "colour", classifier)
        if with_heights:
            segmentation["depth"] = run(with_heights, "depth", None)
    result: dict[str, object] = {
        "dataset": str(data.root),
        "class_names": list(data.class_names),
        "photos": len(data.photos),
        "photo_size": f"fit within {max_size_px[0]}x{max_size_px[1]}, aspect kept",
        "split": {
            "seed": seed,
            "train_fraction": train_fraction,
            "by": "photo, within each subset",
            "train": [p.stem for p in train],
            "test": [p.stem for p in test],
        },
        "classifier": {
            "trained_on_photos": len(train),
            "samples_per_class": classifier.training.get("samples_per_class"),
            "l2": classifier.l2,
        },
        "modes": modes,
        "segmentation_all_photos": segmentation,
        "notes": list(NOTES),
    }
    return result, classifier


__all__ = [
    "LABELLED_OVERLAP",
    "NOTES",
    "PHOTO_L2",
    "HeightLevels",
    "bench_photos",
    "split_photos",
    "train_on_photos",
]
