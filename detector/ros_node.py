"""The detector as a ROS 2 node: camera images in, ``cdw_interfaces/DetectionArray`` out.

A thin shell (:mod:`detector.frames_in` holds the logic): for every camera of the cell it
subscribes to the colour and depth images and the camera info
(:func:`interfaces.camera_topics.camera_topics`, QoS :data:`interfaces.camera_topics.IMAGES`),
pairs colour and depth by stamp, runs that camera's :class:`detector.detector.Detector` on the
pair (intrinsics from the latest ``CameraInfo``, else the cell's; the pose from the cell) and
publishes the frame's detections on ``/objects/detections``
(:data:`interfaces.contract.DETECTIONS`, with its QoS), stamped with the frame's capture stamp
in ``world``. It runs on :class:`rclpy.experimental.EventsExecutor` (``cdw-twin
detector-node``, :mod:`detector.cmd_node`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from rclpy.node import Node

from detector.detector import Detector
from detector.errors import DetectorError
from detector.frames_in import (
    FramePair,
    FramePairer,
    detection_values,
    image_array,
    intrinsics_from_info,
)
from interfaces.camera import Intrinsics, RgbdCameraSpec, RgbdFrame
from interfaces.camera_topics import camera_topics
from interfaces.contract import DETECTIONS, stamp_ns
from interfaces.ros import RosWire, message_class, qos_profile

__all__ = ["DetectorNode", "NodeCounters"]

NODE_NAME = "cdw_detector"
WORLD = "world"


@dataclass(kw_only=True)
class NodeCounters:
    """What the node did: frames detected, detections published, images dropped or refused,
    and the time each detection took (ms, wall clock)."""

    frames: int = 0
    detections: int = 0
    refused: int = 0
    detect_ms: list[float] = field(default_factory=list)

    def summary(self, dropped: int) -> dict[str, object]:
        """Plain data for the node's log and ``--stats-out``."""
        ms = np.array(self.detect_ms) if self.detect_ms else np.zeros(0)
        return {
            "frames": self.frames,
            "detections": self.detections,
            "images_refused": self.refused,
            "images_dropped_unpaired": dropped,
            "detect_ms_median": round(float(np.median(ms)), 2) if ms.size else None,
            "detect_ms_p90": round(float(np.percentile(ms, 90)), 2) if ms.size else None,
        }


class _Camera:
    """One camera's state: its spec, detector, pairer and the intrinsics last announced."""

    def __init__(self, spec: RgbdCameraSpec, detector: Detector, *, with_depth: bool) -> None:
        self.spec = spec
        self.detector = detector
        self.pairer = FramePairer(with_depth=with_depth)
        self.intrinsics: Intrinsics = spec.intrinsics
        self.worldMoptical = spec.worldMoptical()


class DetectorNode(Node):
    """Subscribes to ``cameras``' images, publishes their detections (see the module).

    ``detector_of(spec)`` gives each camera's detector; ``with_depth`` ``False`` detects on the
    colour images alone (no depth subscription).
    """

    def __init__(
        self,
        *,
        cameras: Sequence[RgbdCameraSpec],
        detector_of: Callable[[RgbdCameraSpec], Detector],
        with_depth: bool = True,
    ) -> None:
        super().__init__(NODE_NAME)
        from sensor_msgs.msg import CameraInfo, Image

        self.log: Any = self.get_logger()  # type: ignore[no-untyped-call]
        wire = RosWire(self)
        array_type = message_class(DETECTIONS)
        self._array_type = array_type
        self._publisher = wire.create_publisher(array_type, DETECTIONS.name, DETECTIONS.qos)
        self.counters = NodeCounters()
        self._cameras: list[_Camera] = []
        self._camera_subs: list[Any] = []
        for spec in cameras:
            camera = _Camera(spec, detector_of(spec), with_depth=with_depth)
            self._cameras.append(camera)
            topics = camera_topics(spec.name)
            qos = qos_profile(topics.colour.qos)
            self._camera_subs.append(
                self.create_subscription(
                    Image, topics.colour.name, self._on_colour(camera, topics.colour.name), qos
                )
            )
            if with_depth:
                self._camera_subs.append(
                    self.create_subscription(
                        Image, topics.depth.name, self._on_depth(camera, topics.depth.name), qos
                    )
                )
            self._camera_subs.append(
                self.create_subscription(
                    CameraInfo, topics.info.name, self._on_info(camera, topics.info.name), qos
                )
            )

    def dropped(self) -> int:
        """Images dropped unpaired, over every camera."""
        return sum(c.pairer.dropped for c in self._cameras)

    def _on_colour(self, camera: _Camera, topic: str) -> Callable[[Any], None]:
        def callback(msg: Any) -> None:
            pixels = self._pixels(msg, topic)
            if pixels is not None:
                self._detect(camera, camera.pairer.add_colour(self._stamp(msg), pixels), msg)

        return callback

    def _on_depth(self, camera: _Camera, topic: str) -> Callable[[Any], None]:
        def callback(msg: Any) -> None:
            pixels = self._pixels(msg, topic)
            if pixels is not None:
                self._detect(camera, camera.pairer.add_depth(self._stamp(msg), pixels), msg)

        return callback

    def _on_info(self, camera: _Camera, topic: str) -> Callable[[Any], None]:
        def callback(msg: Any) -> None:
            try:
                camera.intrinsics = intrinsics_from_info(
                    width=msg.width, height=msg.height, k=msg.k, where=topic
                )
            except DetectorError as exc:
                self.counters.refused += 1
                self.log.warning(str(exc), throttle_duration_sec=5.0)

        return callback

    @staticmethod
    def _stamp(msg: Any) -> int:
        return stamp_ns(msg.header.stamp.sec, msg.header.stamp.nanosec)

    def _pixels(self, msg: Any, topic: str) -> np.ndarray | None:
        try:
            return image_array(
                encoding=msg.encoding,
                height=msg.height,
                width=msg.width,
                step=msg.step,
                is_bigendian=msg.is_bigendian,
                data=msg.data,
                where=topic,
            )
        except DetectorError as exc:
            self.counters.refused += 1
            self.log.warning(str(exc), throttle_duration_sec=5.0)
            return None

    def _detect(self, camera: _Camera, pair: FramePair | None, msg: Any) -> None:
        if pair is None:
            return
        rgb = pair.rgb
        depth = pair.depth_m if pair.depth_m is not None else np.full(rgb.shape[:2], np.nan)
        k = camera.intrinsics
        if (k.height_px, k.width_px) != rgb.shape[:2]:
            self.counters.refused += 1
            self.log.warning(
                f"camera {camera.spec.name}: image {rgb.shape[1]}x{rgb.shape[0]} but its "
                f"camera info says {k.width_px}x{k.height_px}",
                throttle_duration_sec=5.0,
            )
            return
        frame = RgbdFrame(
            camera=camera.spec.name,
            stamp_s=pair.stamp_ns * 1e-9,
            rgb=rgb,
            depth_m=depth.astype(np.float32, copy=False),
            intrinsics=k,
            worldMoptical=camera.worldMoptical,
        )
        start = time.perf_counter()
        try:
            output = camera.detector.detect(frame)
        except DetectorError as exc:
            self.counters.refused += 1
            self.log.warning(f"camera {camera.spec.name}: {exc}")
            return
        self.counters.detect_ms.append((time.perf_counter() - start) * 1e3)
        detections = output.detections()
        self._publisher.publish(self._message(msg.header.stamp, detections))
        self.counters.frames += 1
        self.counters.detections += len(detections)

    def _message(self, stamp: Any, detections: Sequence[Any]) -> Any:
        from cdw_interfaces.msg import Detection as DetectionMsg

        out = self._array_type()
        out.header.stamp = stamp
        out.header.frame_id = WORLD
        for d in detections:
            v = detection_values(d)
            det = DetectionMsg(
                class_name=v.class_name,
                confidence=float(v.confidence),
                yaw_rad=v.yaw_rad,
                length_m=v.length_m,
                width_m=v.width_m,
                height_m=v.height_m,
                suction_radius_m=v.suction_radius_m,
                suction_tilt_rad=v.suction_tilt_rad,
            )
            det.position.x, det.position.y, det.position.z = v.position_m
            det.suction_point.x, det.suction_point.y, det.suction_point.z = v.suction_point_m
            out.detections.append(det)
        return out
