"""The plug-in point: what any segmenter hands the detector, image in, instances out.

A segmenter turns one image (``rgb`` ``(H, W, 3) uint8``, and ``depth_m`` ``(H, W) float32``
metres along the optical axis with NaN for no return, when the camera has depth) into instances:
a mask ``(H, W) bool``, a class name and a score in [0, 1] each (:class:`Instance`). The baseline
(:class:`detector.baseline.BaselineSegmenter`) and the ONNX adapter
(:class:`detector.onnx_segmenter.OnnxSegmenter`) both implement :class:`Segmenter`; a user's own
model needs only a ``segment`` method of the same signature and a ``mode`` attribute, and
:class:`detector.detector.Detector` derives the world geometry (centroid, yaw, extents, height,
suction point) of its masks exactly as for the baseline's.

A segmenter that already has a label image (one id per pixel) may also implement
:class:`LabelSegmenter`, which the detector prefers: it skips building one mask per instance.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from detector.config import Mode
from detector.errors import FrameError


@dataclass(frozen=True, kw_only=True, eq=False)
class Instance:
    """One instance a segmenter found: ``mask`` ``(H, W) bool``, its class and a score."""

    mask: np.ndarray
    class_name: str
    score: float


@dataclass(frozen=True, kw_only=True, eq=False)
class LabelledInstances:
    """A segmenter's instances as one label image: ``labels`` ``(H, W) int32`` (0: none, ``k``:
    instance ``k``), ``class_names[k - 1]`` and ``scores[k - 1]`` its class and score; ``mode``
    the signal that found them."""

    labels: np.ndarray
    class_names: tuple[str, ...]
    scores: tuple[float, ...]
    mode: Mode

    def instances(self) -> list[Instance]:
        """The same instances as masks."""
        return [
            Instance(mask=self.labels == k, class_name=name, score=score)
            for k, (name, score) in enumerate(zip(self.class_names, self.scores, strict=True), 1)
        ]


@runtime_checkable
class Segmenter(Protocol):
    """Image in, instances out: the interface every segmenter implements.

    ``mode`` says which signal the segmenter uses (``depth`` or ``colour``), for the outputs.
    """

    @property
    def mode(self) -> Mode:
        """``depth`` when the segmenter uses the depth image, else ``colour``."""
        ...

    def segment(self, rgb: np.ndarray, depth_m: np.ndarray | None = None) -> Sequence[Instance]:
        """The instances in one image (``rgb`` ``(H, W, 3) uint8``, ``depth_m`` ``(H, W)``
        float32 m or ``None``)."""
        ...


@runtime_checkable
class LabelSegmenter(Protocol):
    """A segmenter that can hand over a label image directly (cheaper than masks)."""

    def segment_labels(
        self, rgb: np.ndarray, depth_m: np.ndarray | None = None, heights: np.ndarray | None = None
    ) -> LabelledInstances:
        """The instances of one image as a label image; ``heights`` ``(H, W) float32`` is the
        height above the belt when the caller has it (saves computing it twice)."""
        ...


def check_image(rgb: np.ndarray, depth_m: np.ndarray | None) -> None:
    """A :class:`FrameError` naming what is wrong unless ``rgb`` is ``(H, W, 3) uint8`` and
    ``depth_m`` (if given) a float ``(H, W)`` image of the same size."""
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        msg = f"rgb: expected an (H, W, 3) uint8 image, got {rgb.dtype} {rgb.shape}"
        raise FrameError(msg)
    if depth_m is not None and (
        depth_m.shape != rgb.shape[:2] or not np.issubdtype(depth_m.dtype, np.floating)
    ):
        msg = (
            f"depth_m: expected a float (H, W) image of the rgb's size {rgb.shape[:2]}, "
            f"got {depth_m.dtype} {depth_m.shape}"
        )
        raise FrameError(msg)


__all__ = ["Instance", "LabelSegmenter", "LabelledInstances", "Segmenter", "check_image"]
