"""Where the twin's detection frames come from, stepped with the physics: the oracle or the cameras.

:class:`PerceptionStepper` is owned by :class:`twin.sim.Twin` for its whole life; every
``reset`` starts the scenario's source (``perception.source``) for the episode and every step
lets it capture when a frame is due and release the frames whose latency has passed. It reads
the twin through :class:`twin.sim_view.PerceptionSim` (what it needs of it), not the sim itself:
the sim steps the perception, the perception does not reach back into the sim.

- ``oracle`` (default): :class:`twin.perception.Perception`, the ground truth through the
  scenario's error model (unchanged);
- ``camera``: :class:`CameraSource`. At ``perception.rate_hz`` (:func:`twin.camera.schedule.
  frame_due`: integer steps, nothing accumulated) every camera of the cell (``cameras:``) is
  rendered from one snapshot of the scene (:class:`twin.camera.rig.CameraRig`, depth noise from
  the episode's own child of the seed tree, :func:`camera_seed`), each frame goes through the
  cell's fixed filters (:mod:`twin.camera.filters`: a robot self-filter, the arms' links and
  what their tools hold, known from their poses; and the belt's region of interest, pixels whose
  ray meets the belt plane off the belt, 2 cm margin) and its camera's detector
  (:mod:`twin.camera.detectors`), the cameras' detections are merged (each camera keeps the
  pieces whose centroid lies in its own stretch of the belt, split half-way through its overlap
  with the next, and whose mask does not touch its image's border), and the frame is released
  ``perception.latency_s`` after its exposure, stamped with it, exactly as the oracle's. A frame
  exposed inside a detection-dropout window is never released. Every frame is scored against the
  render's instance ids (:class:`twin.perception_score.EpisodeScorer`).

The step that takes a frame (only steps where one is due) reads the scene and starts drawing
every camera (Mesa's rasteriser threads draw while the twin steps on); the next step reads the
frames back and adds their depth noise (:meth:`CameraSource.finish`). Filtering, detection,
merging and scoring run meanwhile in a process of their own
(:class:`twin.camera.detect_process.DetectionProcess`: beside the step loop, not sharing its
interpreter lock), and the step that releases the frame waits for its result if it is not there
yet: the frames and their order are the same whatever the timing, so an episode stays
deterministic for a seed on one renderer (the detector is; depth noise has its own stream, drawn
in the stepping thread).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Mapping
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from interfaces.camera import RgbdFrame
from interfaces.detections import DetectionFrame
from twin.camera.detect_process import Examples, Shot, camera_stretches
from twin.errors import ConfigError
from twin.perception import Perception
from twin.sim_view import PerceptionSim
from twin.suction_point import SuctionPoints

if TYPE_CHECKING:
    from twin.camera.detect_process import DetectionProcess
    from twin.camera.rig import CameraRig, PendingFrame
    from twin.ground_truth import GroundTruth

__all__ = [
    "CAMERA_SEED_KEY",
    "CameraSource",
    "PerceptionStepper",
    "camera_seed",
]

EXAMPLE_AT = 0.5
"""An episode's example frames are its first at or after this fraction of its duration (the
belt and the arms at work)."""

CAMERA_SEED_KEY = 5
"""The camera's child of the episode's ``SeedSequence(seed)``: children 0-4 are
:func:`twin.scenario.seed_tree`'s, so the camera's noise perturbs none of their streams."""


def camera_seed(seed: int) -> np.random.SeedSequence:
    """The camera's seed sequence of an episode of seed ``seed`` (see :data:`CAMERA_SEED_KEY`)."""
    return np.random.SeedSequence(seed, spawn_key=(CAMERA_SEED_KEY,))


@dataclass(frozen=True, kw_only=True, eq=False)
class _InFlight:
    """A capture being drawn: its time, the ground truth then by object id, every camera's
    frame begun, and the wall time the snapshot and the draws took."""

    time_s: float
    objects: Mapping[int, GroundTruth]
    pending: tuple[PendingFrame, ...]
    begin_s: float


class CameraSource:
    """The cameras of one episode as its perception (see the module)."""

    def __init__(
        self,
        twin: PerceptionSim,
        rig: CameraRig,
        detection: DetectionProcess,
        *,
        seed: int,
        examples: Examples | None = None,
    ) -> None:
        cell = twin.cell
        config = twin.perception_config
        camera_stretches(cell.cameras, cell.belt)  # a camera that sees no belt: said here
        self.twin = twin
        self.rig = rig
        self.specs = cell.cameras
        self.rate_hz = config.rate_hz
        self.latency_s = config.latency_s
        self.dropout_windows_s = tuple(twin.scenario.faults.detection_dropout)
        self.dropped_frames = 0
        self.rngs = [np.random.default_rng(s) for s in camera_seed(seed).spawn(len(cell.cameras))]
        self._detection = detection
        detection.start_episode(self.latency_s, examples)
        self._queue: deque[tuple[float, Future[DetectionFrame]]] = deque()
        self._in_flight: _InFlight | None = None
        self.latest: tuple[RgbdFrame, ...] = ()
        """Every camera's frame of the last capture, as rendered: what the twin node publishes
        on the cameras' topics."""

    def capture(self, time_s: float) -> None:
        """Start rendering every camera now (one snapshot of the scene); :meth:`finish` reads
        the frames back, a step later, and hands them to the detection process."""
        self.finish()
        t0 = time.perf_counter()
        objects = {truth.id: truth for truth in self.twin.observe_objects()}
        snapshot = self.rig.snapshot()
        pending = tuple(self.rig.begin(spec, snapshot, slot=i) for i, spec in enumerate(self.specs))
        self._in_flight = _InFlight(
            time_s=time_s, objects=objects, pending=pending, begin_s=time.perf_counter() - t0
        )

    def finish(self) -> None:
        """Read back the frames in flight (the rasteriser drew them while the twin stepped
        on), add their depth noise and hand them to the detection process (detect, merge,
        score); queue the result for release (not inside a dropout window)."""
        flight, self._in_flight = self._in_flight, None
        if flight is None:
            return
        shots = []
        for index, (pending, rng) in enumerate(zip(flight.pending, self.rngs, strict=True)):
            t0 = time.perf_counter()
            frame, robot = self.rig.finish(pending, rng=rng)
            render_s = time.perf_counter() - t0 + flight.begin_s / len(flight.pending)
            shots.append(Shot(camera=index, frame=frame, robot=robot, render_s=render_s))
        self.latest = tuple(shot.frame for shot in shots)
        time_s = flight.time_s
        future = self._detection.detect(time_s, shots, dict(flight.objects))
        if any(a <= time_s < b for a, b in self.dropout_windows_s):
            self.dropped_frames += 1
        else:
            self._queue.append((time_s + self.latency_s, future))

    def released(self, time_s: float) -> list[DetectionFrame]:
        """Frames whose latency has elapsed by ``time_s``, oldest first (waiting for the
        detection process if one is not ready)."""
        if self._in_flight is not None and self._in_flight.time_s + self.latency_s <= time_s:
            self.finish()
        out = []
        while self._queue and self._queue[0][0] <= time_s + 1e-9:
            out.append(self._queue.popleft()[1].result())
        return out

    def summary(self) -> dict[str, float]:
        """The episode's scores over every frame taken so far (waits for the detections)."""
        self.finish()
        return self._detection.summary()


class PerceptionStepper:
    """The twin's perception over its life: the episode's source, its released frames, its
    scores, and the camera rig and detectors kept across episodes (see the module)."""

    def __init__(self, twin: PerceptionSim) -> None:
        self.twin = twin
        self.oracle: Perception | None = None
        self.camera: CameraSource | None = None
        self._rig: CameraRig | None = None
        self._detection: DetectionProcess | None = None
        self.examples_folder: Path | None = None
        """Where the camera source writes each camera's example frame, one per episode (None:
        nowhere); set before ``reset``."""
        self._released: list[DetectionFrame] = []

    def reset(self, seed: int, rng: np.random.Generator) -> Perception | None:
        """Start the episode's source; ``rng`` is the seed tree's perception stream (the
        oracle's). Returns the oracle (None with the cameras)."""
        twin = self.twin
        self._released = []
        self.oracle = self.camera = None
        if twin.perception_config.source != "camera":
            self.oracle = Perception(
                twin.perception_config,
                twin.classes,
                twin.cell.belt.surface_z_m,
                twin.dt_s,
                rng,
                camera=twin.cell.camera,
                dropout_windows_s=twin.scenario.faults.detection_dropout,
                suction_points=SuctionPoints(lambda object_id: twin.object_mesh(object_id)[0]),
            )
            return self.oracle
        if not twin.cell.cameras:
            msg = (
                f"perception.source = 'camera': the cell {twin.cell.source or twin.cell.name} "
                "declares no cameras (a cameras: list)"
            )
            raise ConfigError(msg)
        from twin.camera.detect_process import DetectionProcess, DetectorSetup
        from twin.camera.rig import CameraRig

        if self._rig is None:
            self._rig = CameraRig(twin)
        if self._detection is None:
            self._detection = DetectionProcess(
                DetectorSetup(
                    dataset_dir=twin.dataset_dir,
                    cameras=twin.cell.cameras,
                    belt=twin.cell.belt,
                    classes=tuple(twin.classes),
                    materials=twin.cell.materials,
                )
            )
        examples = None
        if self.examples_folder is not None:
            examples = Examples(
                folder=self.examples_folder, at_s=EXAMPLE_AT * twin.scenario.duration_s
            )
        self.camera = CameraSource(twin, self._rig, self._detection, seed=seed, examples=examples)
        return None

    def step(self, step: int, time_s: float) -> None:
        """Capture if a frame is due at ``step``; collect the frames released by ``time_s``."""
        if self.oracle is not None:
            if self.oracle.capture_due(step):
                self.oracle.capture(time_s, self.twin.observe_objects())
            self._released.extend(self.oracle.released(time_s))
        elif self.camera is not None:
            from twin.camera.schedule import frame_due

            self.camera.finish()  # the frame begun at the step before, drawn meanwhile
            if frame_due(step, self.camera.rate_hz, 1.0 / self.twin.dt_s):
                self.camera.capture(time_s)
            self._released.extend(self.camera.released(time_s))

    def take(self) -> list[DetectionFrame]:
        """Frames released since the last call."""
        frames, self._released = self._released, []
        return frames

    def latest_frames(self) -> tuple[RgbdFrame, ...]:
        """Every camera's frame of the cameras' last capture (none with the oracle)."""
        return () if self.camera is None else self.camera.latest

    def summary(self) -> dict[str, float] | None:
        """The episode's perception scores (None unless the cameras are the source)."""
        return None if self.camera is None else self.camera.summary()

    def close(self) -> None:
        """Stop the detection process and release the camera rig."""
        if self._detection is not None:
            self._detection.close()
            self._detection = None
        if self._rig is not None:
            self._rig.close()
            self._rig = None
