"""The cell's cameras on ROS 2: each camera's colour and depth ``Image`` and its ``CameraInfo``
(topics and QoS: :mod:`interfaces.camera_topics`), a :class:`twin.scene_publisher.StepPublisher`
of the twin node. The cameras' frames go on ``/tf_static`` with the scene's.

Which frames. With ``perception.source: camera``, the frames the camera source rendered for its
detector (:meth:`twin.sim.Twin.camera_frames`: no second render), at ``perception.rate_hz``.
With the oracle, the publisher renders the cameras itself (its own
:class:`twin.camera.rig.CameraRig`, depth noise from the episode's camera seed,
:func:`twin.perception_source.camera_seed`) at each camera's ``rate_hz``, and only at a step
where someone takes the frame: rendering reads the simulation and draws from no stream of it, so
the oracle's episode is the same with or without a viewer, and costs nothing without one.

Who takes them. A matched subscriber gets every frame. The tap (the recording, the live view)
gets one frame in ``rate / record_hz`` (``record_hz`` 0: none): a 640x480 frame is 2.1 MB, and
a minute of them at 15 Hz would be a 1.9 GB recording. A frame sent goes to both. Every message
of a frame is stamped with its exposure (sim time) in ``NAME_optical_frame``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from interfaces.camera import RgbdCameraSpec, RgbdFrame
from interfaces.camera_topics import camera_topics
from twin.camera.ros_images import colour_message, depth_message, info_message
from twin.camera.schedule import frame_due
from twin.perception_source import camera_seed

if TYPE_CHECKING:
    from builtin_interfaces.msg import Time

    from twin.camera.rig import CameraRig
    from twin.sim import Twin
    from twin.tapped_wire import TappedWire

__all__ = ["RECORD_HZ", "CameraPublisher", "record_hz_for"]

RECORD_HZ = 1.0
"""Default rate (sim time) at which the tap takes a camera's frames when the camera source
renders them anyway; with the oracle the default is 0 (nothing rendered for the tap)."""


def record_hz_for(source: str, record_hz: float | None) -> float:
    """The rate the tap takes frames at: ``record_hz`` if given, else :data:`RECORD_HZ` with the
    camera source and 0 with the oracle."""
    if record_hz is not None:
        return record_hz
    return RECORD_HZ if source == "camera" else 0.0


@dataclass(eq=False)
class _Camera:
    """One camera's publishers, its frame rate and how many of its frames were due so far."""

    spec: RgbdCameraSpec
    publishers: tuple[Any, Any, Any]  # colour, depth, info
    rate_hz: float
    tap_every: int  # 0: the tap takes none
    due: int = 0
    sent: int = 0
    rng: np.random.Generator | None = None  # its depth noise, once the publisher renders


class CameraPublisher:
    """Every camera of the twin's cell on its topics (see the module)."""

    def __init__(self, *, record_hz: float = RECORD_HZ) -> None:
        if not (math.isfinite(record_hz) and record_hz >= 0.0):
            msg = f"record_hz = {record_hz!r}: must be >= 0 (0: the tap takes no frame)"
            raise ValueError(msg)
        self.record_hz = record_hz
        self.renders = 0
        """Frames this publisher rendered itself (the oracle's viewers)."""
        self._cameras: tuple[_Camera, ...] = ()
        self._rig: CameraRig | None = None
        self._last_stamp_s = -math.inf

    @property
    def sent(self) -> dict[str, int]:
        """Frames sent so far per camera name."""
        return {c.spec.name: c.sent for c in self._cameras}

    def attach(self, io: TappedWire, twin: Twin) -> None:
        """Create every camera's three publishers on ``io``."""
        self.io, self.twin = io, twin
        self.from_source = twin.perception_config.source == "camera"
        cameras = []
        for spec in twin.cell.cameras:
            rate = twin.perception_config.rate_hz if self.from_source else spec.rate_hz
            tap_every = max(1, round(rate / self.record_hz)) if self.record_hz > 0 else 0
            publishers = tuple(io.publisher(t) for t in camera_topics(spec.name).all)
            cameras.append(
                _Camera(spec, (publishers[0], publishers[1], publishers[2]), rate, tap_every)
            )
        self._cameras = tuple(cameras)

    def publish_step(self, stamp: Time, step: int) -> None:
        """Send the frames due after step ``step`` to whoever takes them."""
        del stamp  # a frame carries its own exposure stamp
        if self.from_source:
            frames = self.twin.camera_frames()
            if not frames or frames[0].stamp_s <= self._last_stamp_s:
                return
            self._last_stamp_s = frames[0].stamp_s
            for camera, frame in zip(self._cameras, frames, strict=True):
                if self._taken(camera):
                    self._send(camera, frame)
            return
        physics_hz = 1.0 / self.twin.dt_s
        due = [c for c in self._cameras if frame_due(step, c.rate_hz, physics_hz)]
        wanted = [c for c in due if self._taken(c)]
        if wanted:
            for camera, frame in zip(wanted, self._render(wanted), strict=True):
                self._send(camera, frame)

    def _taken(self, camera: _Camera) -> bool:
        """Whether someone takes the camera's frame now due (and count it)."""
        index = camera.due
        camera.due += 1
        io = self.io
        if any(io.subscribed(p) for p in camera.publishers):
            return True
        if camera.tap_every == 0 or index % camera.tap_every:
            return False
        return any(io.tapped(p) for p in camera.publishers)

    def _render(self, cameras: list[_Camera]) -> list[RgbdFrame]:
        """The cameras' frames now, from one snapshot of the scene (the oracle's viewers)."""
        if self._rig is None:
            from twin.camera.rig import CameraRig

            self._rig = CameraRig(self.twin)
            seeds = camera_seed(self.twin.scenario.seed).spawn(len(self._cameras))
            for camera, seed in zip(self._cameras, seeds, strict=True):
                camera.rng = np.random.default_rng(seed)
        snapshot = self._rig.snapshot()
        self.renders += len(cameras)
        return [self._rig.capture(c.spec, rng=c.rng, snapshot=snapshot) for c in cameras]

    def _send(self, camera: _Camera, frame: RgbdFrame) -> None:
        colour, depth, info = camera.publishers
        io, spec = self.io, camera.spec
        io.send(colour, colour_message(frame, spec))
        io.send(depth, depth_message(frame, spec))
        io.send(info, info_message(spec, frame.stamp_s))
        camera.sent += 1

    def close(self) -> None:
        """Release the publisher's own camera rig (the oracle's viewers), if it made one."""
        if self._rig is not None:
            self._rig.close()
            self._rig = None
