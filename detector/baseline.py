"""The baseline segmenter: instances from depth (or colour alone), classes from colour features.

Depth mode (the frame has depth): heights above the belt from the camera's
:class:`detector.belt_view.BeltView`, :func:`detector.depth_segment.segment_heights`. Colour mode
(no depth, or ``mode: colour``): :func:`detector.colour_segment.segment_colour`. In either mode
each instance's class and score come from the colour classifier
(:class:`detector.classifier.ColourClassifier`) over its colour and texture features; without a
classifier every instance is ``unknown_class`` with score 0. Built once with its configuration,
classifier and camera; each call is one frame.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from detector.belt_view import BeltView
from detector.classifier import ColourClassifier
from detector.colour_segment import segment_colour
from detector.config import DetectorConfig, Mode
from detector.depth_prep import pixel_area_m2, prepare_depth
from detector.depth_segment import segment_heights
from detector.errors import FrameError
from detector.features import instance_features
from detector.instances import Instance, LabelledInstances, check_image


def classify(
    rgb: np.ndarray,
    labels: np.ndarray,
    *,
    classifier: ColourClassifier | None,
    unknown_class: str,
) -> tuple[tuple[str, ...], tuple[float, ...]]:
    """Class and score of every instance of ``labels`` ``(H, W)`` in ``rgb`` (features on the
    classifier's own pixel step)."""
    n = int(labels.max(initial=0))
    if classifier is None or n == 0:
        return (unknown_class,) * n, (0.0,) * n
    names, probs = classifier.predict(instance_features(rgb, labels, classifier.feature_stride))
    return tuple(names), tuple(float(p) for p in probs)


def has_depth(depth_m: np.ndarray | None, min_valid: float) -> bool:
    """Whether at least ``min_valid`` of the pixels of ``depth_m`` have a finite depth."""
    return depth_m is not None and float(np.isfinite(depth_m).mean()) >= min_valid


class BaselineSegmenter:
    """Depth (or colour) segmentation and a colour classifier (see the module).

    ``view`` is the camera over the belt, needed in depth mode (heights above the belt).
    """

    def __init__(
        self,
        *,
        config: DetectorConfig | None = None,
        classifier: ColourClassifier | None = None,
        view: BeltView | None = None,
    ) -> None:
        self.config = config or DetectorConfig()
        self.classifier = classifier
        self.view = view

    @property
    def mode(self) -> Mode:
        """``colour`` when configured so, else ``depth`` (used when a frame has depth)."""
        return "colour" if self.config.mode == "colour" else "depth"

    def choose_mode(self, depth_m: np.ndarray | None, heights: np.ndarray | None) -> Mode:
        """The mode for one frame: colour when configured so or when it lacks depth."""
        if self.config.mode == "colour":
            return "colour"
        if heights is not None or has_depth(depth_m, self.config.min_valid_depth):
            return "depth"
        if self.config.mode == "depth":
            msg = (
                "depth mode: the frame has depth on fewer than "
                f"{self.config.min_valid_depth:g} of its pixels"
            )
            raise FrameError(msg)
        return "colour"

    def segment_labels(
        self, rgb: np.ndarray, depth_m: np.ndarray | None = None, heights: np.ndarray | None = None
    ) -> LabelledInstances:
        """The instances of one frame as a label image. ``heights``: the height above the belt,
        when the caller has it; ``depth_m`` is then taken as already filtered
        (:func:`detector.depth_prep.prepare_depth` gives both)."""
        check_image(rgb, depth_m)
        cfg = self.config
        mode = self.choose_mode(depth_m, heights)
        if mode == "depth":
            labels = self._depth_labels(rgb, depth_m, heights)
        else:
            labels = segment_colour(rgb, config=cfg.colour, stride=cfg.work_stride)
        names, scores = classify(
            rgb,
            labels,
            classifier=self.classifier,
            unknown_class=cfg.unknown_class,
        )
        return LabelledInstances(labels=labels, class_names=names, scores=scores, mode=mode)

    def segment(self, rgb: np.ndarray, depth_m: np.ndarray | None = None) -> Sequence[Instance]:
        """The instances of one frame as masks (the :class:`detector.instances.Segmenter`
        protocol)."""
        return self.segment_labels(rgb, depth_m).instances()

    def _depth_labels(
        self, rgb: np.ndarray, depth_m: np.ndarray | None, heights: np.ndarray | None
    ) -> np.ndarray:
        view = self.view
        if view is None:
            msg = "depth mode needs the camera's view of the belt (BaselineSegmenter(view=...))"
            raise FrameError(msg)
        if depth_m is None:
            msg = "depth mode needs depth_m"
            raise FrameError(msg)
        if heights is None:
            depth, heights = prepare_depth(depth_m, view)
        else:
            depth = depth_m
        cfg = self.config
        belt_px_m = view.belt_metres_per_px
        if not belt_px_m > 0:
            msg = "depth mode: the camera's central ray does not meet the belt plane"
            raise FrameError(msg)
        return segment_heights(
            np.nan_to_num(heights, nan=0.0),
            min_height=cfg.depth.min_height_m,
            jump=cfg.depth.jump_m,
            min_peak_px=cfg.depth.min_peak_radius_m / (belt_px_m * cfg.work_stride),
            merge_ratio=cfg.depth.split.merge_ratio,
            stride=cfg.work_stride,
            min_area=cfg.depth.min_area_m2,
            pixel_area=pixel_area_m2(depth, view),
        )


__all__ = ["BaselineSegmenter", "classify", "has_depth"]
