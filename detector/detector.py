"""The detector: one RGB-D frame in, the detections the controllers read out.

Constructed once with its segmenter (the baseline's by default, or any
:class:`detector.instances.Segmenter`: a user's model), configuration and the belt's height; each
:meth:`Detector.detect` is one frame: the depth is filtered and turned into heights above the belt
once, the segmenter finds the instances (a label image, or masks), and every instance's world
geometry is derived from its mask, the depth and the camera (:mod:`detector.world_geometry`),
the same for the baseline's masks and a plug-in's. The output says which mode (depth or colour)
found the instances, keeps the label image for scoring and converts to the
:class:`interfaces.detections.DetectionFrame` the controllers consume.

Colour mode (a frame without depth, or ``mode: colour``) projects each mask onto the belt plane:
centroid, yaw and extents in metres, height and suction point NaN (a colour image does not show
them). :meth:`Detector.detect_image` runs on a bare image without a camera (photos): image-plane
geometry only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage as ndi

from detector.baseline import BaselineSegmenter, has_depth
from detector.belt_view import BeltView
from detector.classifier import ColourClassifier
from detector.config import DetectorConfig, Mode
from detector.depth_prep import prepare_depth
from detector.errors import DetectorConfigError
from detector.geometry import ImageGeometry, belt_plane_geometry, image_geometries
from detector.instances import LabelledInstances, LabelSegmenter, Segmenter, check_image
from detector.labels import masks_to_labels, relabel
from detector.score import InstanceSet
from detector.world_geometry import DepthImages, frame_detections
from interfaces.camera import RgbdFrame
from interfaces.detections import Detection, DetectionFrame


@dataclass(frozen=True, kw_only=True, eq=False)
class DetectedInstance:
    """One instance of a frame: its ``label`` in the output's label image, class, score,
    image geometry and world detection (``None`` without a camera or without depth on it);
    ``at_border``: its mask touches the image's border, so the piece may be only partly in
    view (its centroid and extents are those of the visible part)."""

    label: int
    class_name: str
    score: float
    image: ImageGeometry
    detection: Detection | None
    at_border: bool = False


@dataclass(frozen=True, kw_only=True, eq=False)
class DetectorOutput:
    """One frame's result: the ``mode`` that produced it, the instances' ``labels`` ``(H, W)
    int32`` (0: none, ``k``: ``instances[k - 1]``) and the instances."""

    mode: Mode
    labels: np.ndarray
    instances: tuple[DetectedInstance, ...]

    def detections(self) -> tuple[Detection, ...]:
        """The world detections (instances without one left out)."""
        return tuple(i.detection for i in self.instances if i.detection is not None)

    def detection_frame(self, *, capture_time_s: float, release_time_s: float) -> DetectionFrame:
        """The frame as the controllers receive it."""
        return DetectionFrame(
            capture_time_s=capture_time_s,
            release_time_s=release_time_s,
            detections=self.detections(),
        )

    def mask(self, label: int) -> np.ndarray:
        """Instance ``label``'s mask, ``(H, W) bool``."""
        out: np.ndarray = self.labels == label
        return out

    def instance_set(self, *, world: bool = True) -> InstanceSet:
        """The instances for :mod:`detector.score`: with ``world``, the detections' centroids
        (x, y, m) and yaws (NaN where none), else the image centroids (u, v, px) and axes."""
        if world:
            dets = [i.detection for i in self.instances]
            centroids = np.array(
                [(d.x_m, d.y_m) if d else (np.nan, np.nan) for d in dets], dtype=np.float64
            ).reshape(-1, 2)
            yaws = np.array([d.yaw_rad if d else np.nan for d in dets], dtype=np.float64)
        else:
            centroids = np.array(
                [i.image.centroid_uv_px for i in self.instances], dtype=np.float64
            ).reshape(-1, 2)
            yaws = np.array([i.image.axis_rad for i in self.instances], dtype=np.float64)
        return InstanceSet.from_labels(
            self.labels,
            [i.class_name for i in self.instances],
            centroids=centroids,
            yaws_rad=yaws,
        )


def _at_border(labels: np.ndarray, n: int) -> np.ndarray:
    """Which labels ``0..n`` touch the image's border, ``(n + 1,) bool``."""
    edge = np.concatenate((labels[0], labels[-1], labels[:, 0], labels[:, -1]))
    out = np.zeros(n + 1, dtype=bool)
    out[edge] = True
    return out


class Detector:
    """Frames to detections (see the module).

    ``segmenter``: default the baseline (:class:`detector.baseline.BaselineSegmenter` with
    ``config`` and ``classifier``); ``belt_z_m``: world height of the belt surface.
    """

    def __init__(
        self,
        *,
        config: DetectorConfig | None = None,
        classifier: ColourClassifier | None = None,
        segmenter: Segmenter | None = None,
        belt_z_m: float = 0.0,
    ) -> None:
        if segmenter is not None and classifier is not None:
            msg = "Detector: give a classifier (for the baseline) or a segmenter, not both"
            raise DetectorConfigError(msg)
        self.config = config or DetectorConfig()
        self.segmenter: Segmenter = segmenter or BaselineSegmenter(
            config=self.config, classifier=classifier
        )
        self.belt_z_m = float(belt_z_m)
        self._view: BeltView | None = None

    def view_for(self, frame: RgbdFrame) -> BeltView:
        """The camera's view of the belt for ``frame`` (built once per camera)."""
        view = self._view
        if view is None or not view.matches(frame.intrinsics, frame.worldMoptical):
            view = BeltView(
                intrinsics=frame.intrinsics,
                worldMoptical=frame.worldMoptical,
                belt_z_m=self.belt_z_m,
            )
            self._view = view
            if isinstance(self.segmenter, BaselineSegmenter):
                self.segmenter.view = view
        return view

    def detect(self, frame: RgbdFrame) -> DetectorOutput:
        """The instances and world detections of one frame."""
        check_image(frame.rgb, frame.depth_m)
        view = self.view_for(frame)
        use_depth = self.config.mode != "colour" and has_depth(
            frame.depth_m, self.config.min_valid_depth
        )
        depth = heights = None
        if use_depth:
            depth, heights = prepare_depth(frame.depth_m, view)
        found = self._segment(frame.rgb, depth, heights, frame.depth_m if use_depth else None)
        n = len(found.class_names)
        world: list[Detection | None] = []
        if heights is not None and depth is not None:
            images = DepthImages(view=view, depth_m=depth, heights_m=heights, labels=found.labels)
            world = frame_detections(
                images,
                class_names=found.class_names,
                scores=found.scores,
                config=self.config.geometry,
            )
        geometries = image_geometries(found.labels, n, self.config.work_stride)
        border = _at_border(found.labels, n)
        boxes = ndi.find_objects(found.labels, max_label=n) if heights is None else []
        out = []
        for k in range(1, n + 1):
            image = geometries[k - 1]
            name, score = found.class_names[k - 1], found.scores[k - 1]
            if heights is not None:
                det = world[k - 1]
            else:
                box = boxes[k - 1]
                rows, cols = np.nonzero(found.labels[box] == k)
                det = belt_plane_geometry(
                    view=view,
                    rows=rows + box[0].start,
                    cols=cols + box[1].start,
                    class_name=name,
                    score=score,
                )
            out.append(
                DetectedInstance(
                    label=k,
                    class_name=name,
                    score=score,
                    image=image,
                    detection=det,
                    at_border=bool(border[k]),
                )
            )
        return DetectorOutput(mode=found.mode, labels=found.labels, instances=tuple(out))

    def detect_image(self, rgb: np.ndarray, depth_m: np.ndarray | None = None) -> DetectorOutput:
        """The instances of a bare image (no camera pose: image geometry only; depth mode needs
        a segmenter that works without one, as a plug-in model may)."""
        check_image(rgb, depth_m)
        found = self._segment(rgb, None, None, depth_m)
        n = len(found.class_names)
        geometries = image_geometries(found.labels, n, self.config.work_stride)
        border = _at_border(found.labels, n)
        out = [
            DetectedInstance(
                label=k,
                class_name=found.class_names[k - 1],
                score=found.scores[k - 1],
                image=image,
                detection=None,
                at_border=bool(border[k]),
            )
            for k, image in enumerate(geometries, start=1)
        ]
        return DetectorOutput(mode=found.mode, labels=found.labels, instances=tuple(out))

    def _segment(
        self,
        rgb: np.ndarray,
        depth: np.ndarray | None,
        heights: np.ndarray | None,
        raw_depth: np.ndarray | None,
    ) -> LabelledInstances:
        """The segmenter's instances as a label image (its own, or built from its masks)."""
        seg = self.segmenter
        if isinstance(seg, LabelSegmenter):
            if heights is not None:
                return seg.segment_labels(rgb, depth, heights)
            return seg.segment_labels(rgb, raw_depth)
        instances = list(seg.segment(rgb, raw_depth))
        scores = tuple(float(i.score) for i in instances)
        labels = masks_to_labels([i.mask for i in instances], rgb.shape[:2], scores)
        keep = np.zeros(len(instances) + 1, dtype=bool)
        keep[np.unique(labels)] = True
        kept = [i for k, i in enumerate(instances, start=1) if keep[k]]
        return LabelledInstances(
            labels=relabel(labels, keep),
            class_names=tuple(i.class_name for i in kept),
            scores=tuple(float(i.score) for i in kept),
            mode=seg.mode,
        )


__all__ = ["DetectedInstance", "Detector", "DetectorOutput"]
