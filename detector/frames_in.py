"""What the detector node does between messages and the detector, free of ROS.

- :func:`image_array`: the pixels of a ``sensor_msgs/Image`` (its plain fields) as numpy:
  ``rgb8`` / ``bgr8`` to ``(H, W, 3) uint8`` RGB, ``32FC1`` to ``(H, W) float32`` metres,
  ``16UC1`` millimetres to metres (0: no return, NaN);
- :func:`intrinsics_from_info`: a ``CameraInfo``'s ``K`` and size as
  :class:`interfaces.camera.Intrinsics`;
- :class:`FramePairer`: a camera's colour and depth images paired by stamp (the depth is
  registered to the colour image and carries its stamp); unmatched images older than a pair are
  dropped, at most ``max_pending`` kept a side;
- :func:`detection_values`: a :class:`interfaces.detections.Detection` as the fields of one
  ``cdw_interfaces/Detection`` (:class:`interfaces.cdr.DetectionValues`).

Every error is a :class:`detector.errors.FrameError` naming the topic and the field.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from detector.errors import FrameError
from interfaces.camera import Intrinsics
from interfaces.cdr import DetectionValues
from interfaces.detections import Detection
from interfaces.errors import ConfigError

__all__ = [
    "ENCODINGS",
    "FramePair",
    "FramePairer",
    "detection_values",
    "image_array",
    "intrinsics_from_info",
]

ENCODINGS: dict[str, tuple[str, int]] = {
    "rgb8": ("u1", 3),
    "bgr8": ("u1", 3),
    "32FC1": ("f4", 1),
    "16UC1": ("u2", 1),
}
"""The image encodings read: numpy base type and channels."""


def image_array(
    *,
    encoding: str,
    height: int,
    width: int,
    step: int,
    is_bigendian: int,
    data: bytes | bytearray | memoryview | Sequence[int],
    where: str,
) -> np.ndarray:
    """The pixels of an image message (its fields): colour ``(H, W, 3) uint8`` RGB, depth
    ``(H, W) float32`` metres with NaN where there is none. ``where`` names the topic in errors.
    """
    if encoding not in ENCODINGS:
        msg = f"{where}: encoding = {encoding!r}; the detector reads {sorted(ENCODINGS)}"
        raise FrameError(msg)
    base, channels = ENCODINGS[encoding]
    dtype = np.dtype((">" if is_bigendian else "<") + base)
    row_bytes = width * channels * dtype.itemsize
    if height <= 0 or width <= 0 or step < row_bytes:
        msg = (
            f"{where}: height = {height}, width = {width}, step = {step}: "
            f"a {encoding} row needs at least {row_bytes} bytes"
        )
        raise FrameError(msg)
    try:
        buffer = np.frombuffer(memoryview(data), dtype=np.uint8)  # type: ignore[arg-type]
    except TypeError:  # a plain sequence of byte values
        buffer = np.frombuffer(bytes(data), dtype=np.uint8)
    if buffer.size < step * height:
        msg = f"{where}: data holds {buffer.size} bytes, step * height = {step * height}"
        raise FrameError(msg)
    rows = buffer[: step * height].reshape(height, step)[:, :row_bytes]
    pixels = np.ascontiguousarray(rows).view(dtype).reshape(height, width, channels)
    if encoding == "rgb8":
        return pixels
    if encoding == "bgr8":
        return np.ascontiguousarray(pixels[..., ::-1])
    plane = pixels[..., 0]
    if encoding == "16UC1":
        metres = plane.astype(np.float32) * np.float32(0.001)
        metres[plane == 0] = np.nan
        return metres
    return plane.astype(np.float32)


def intrinsics_from_info(*, width: int, height: int, k: Sequence[float], where: str) -> Intrinsics:
    """The pinhole model of a ``CameraInfo`` (``K`` row-major, 9 values; distortion ignored:
    the twin's and the shipped cameras' is zero)."""
    values = [float(v) for v in k]
    if len(values) != 9:
        msg = f"{where}: k has {len(values)} values, expected 9"
        raise FrameError(msg)
    try:
        return Intrinsics(
            width_px=int(width),
            height_px=int(height),
            fx_px=values[0],
            fy_px=values[4],
            cx_px=values[2],
            cy_px=values[5],
        )
    except ConfigError as exc:
        msg = f"{where}: {exc}"
        raise FrameError(msg) from None


@dataclass(frozen=True, kw_only=True, eq=False)
class FramePair:
    """A colour image and its depth (``None``: a colour-only camera) of one stamp (ns)."""

    stamp_ns: int
    rgb: np.ndarray
    depth_m: np.ndarray | None


class FramePairer:
    """One camera's colour and depth images paired by stamp (see the module).

    ``with_depth`` ``False``: every colour image is a pair on its own (no depth awaited).
    """

    def __init__(self, *, with_depth: bool = True, max_pending: int = 4) -> None:
        if max_pending < 1:
            msg = f"max_pending = {max_pending}: must be >= 1"
            raise FrameError(msg)
        self.with_depth = with_depth
        self.max_pending = max_pending
        self._colour: OrderedDict[int, np.ndarray] = OrderedDict()
        self._depth: OrderedDict[int, np.ndarray] = OrderedDict()
        self.dropped = 0
        """Images dropped unpaired (a newer pair came first, or too many waited)."""

    def add_colour(self, stamp_ns: int, rgb: np.ndarray) -> FramePair | None:
        """Take a colour image; the pair it completes, if any."""
        if not self.with_depth:
            return FramePair(stamp_ns=stamp_ns, rgb=rgb, depth_m=None)
        depth = self._depth.pop(stamp_ns, None)
        if depth is None:
            self._keep(self._colour, stamp_ns, rgb)
            return None
        return self._paired(stamp_ns, rgb, depth)

    def add_depth(self, stamp_ns: int, depth_m: np.ndarray) -> FramePair | None:
        """Take a depth image; the pair it completes, if any."""
        if not self.with_depth:
            return None
        rgb = self._colour.pop(stamp_ns, None)
        if rgb is None:
            self._keep(self._depth, stamp_ns, depth_m)
            return None
        return self._paired(stamp_ns, rgb, depth_m)

    def _keep(
        self, pending: OrderedDict[int, np.ndarray], stamp_ns: int, image: np.ndarray
    ) -> None:
        pending[stamp_ns] = image
        while len(pending) > self.max_pending:
            pending.popitem(last=False)
            self.dropped += 1

    def _paired(self, stamp_ns: int, rgb: np.ndarray, depth: np.ndarray) -> FramePair:
        if rgb.shape[:2] != depth.shape:
            msg = (
                f"stamp {stamp_ns} ns: colour {rgb.shape[1]}x{rgb.shape[0]} and depth "
                f"{depth.shape[1]}x{depth.shape[0]} differ (the depth must be registered to "
                "the colour image)"
            )
            raise FrameError(msg)
        for pending in (self._colour, self._depth):
            for old in [s for s in pending if s < stamp_ns]:
                del pending[old]
                self.dropped += 1
        return FramePair(stamp_ns=stamp_ns, rgb=rgb, depth_m=depth)


def detection_values(d: Detection) -> DetectionValues:
    """The fields of one ``cdw_interfaces/Detection`` of ``d`` (a detection without a suction
    point keeps its NaN radius: the message's "none")."""
    return DetectionValues(
        class_name=d.class_name,
        confidence=d.confidence,
        position_m=(d.x_m, d.y_m, d.z_m),
        yaw_rad=d.yaw_rad,
        length_m=d.length_m,
        width_m=d.width_m,
        height_m=d.height_m,
        suction_point_m=d.suction_point_m,
        suction_radius_m=d.suction_radius_m,
        suction_tilt_rad=d.suction_tilt_rad,
    )
