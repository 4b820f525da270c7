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

The step that takes a frame (only steps where one is due) reads the scene and renders every
camera; filtering, detection, merging and scoring run on a worker thread meanwhile (numpy and
scipy let go of the interpreter for their array work), and the step that releases the frame
waits for its result if it is not there yet: the frames and their order are the same whatever
the timing, so an episode stays deterministic for a seed on one renderer (the detector is;
depth noise has its own stream, drawn in the stepping thread).
"""

from __future__ import annotations

import itertools
import math
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from interfaces.camera import RgbdCameraSpec, RgbdFrame, belt_view_x_m
from interfaces.cell import BeltSpec
from interfaces.detections import Detection, DetectionFrame
from twin.camera.filters import belt_plane_depth, filtered_frame
from twin.errors import ConfigError
from twin.perception import Perception
from twin.sim_view import PerceptionSim
from twin.suction_point import SuctionPoints

if TYPE_CHECKING:
    from detector.detector import Detector, DetectorOutput
    from twin.camera.rig import CameraRig
    from twin.ground_truth import GroundTruth
    from twin.perception_score import EpisodeScorer

__all__ = [
    "CAMERA_SEED_KEY",
    "CameraSource",
    "PerceptionStepper",
    "camera_seed",
    "camera_stretches",
]

CAMERA_SEED_KEY = 5
"""The camera's child of the episode's ``SeedSequence(seed)``: children 0-4 are
:func:`twin.scenario.seed_tree`'s, so the camera's noise perturbs none of their streams."""


def camera_seed(seed: int) -> np.random.SeedSequence:
    """The camera's seed sequence of an episode of seed ``seed`` (see :data:`CAMERA_SEED_KEY`)."""
    return np.random.SeedSequence(seed, spawn_key=(CAMERA_SEED_KEY,))


def camera_stretches(
    cameras: tuple[RgbdCameraSpec, ...], belt: BeltSpec
) -> tuple[tuple[float, float], ...]:
    """Each camera's own stretch of the belt, an x interval (same order as ``cameras``): what it
    sees of the centreline, split half-way through each overlap with its neighbours; the most
    upstream and downstream ones open-ended."""
    seen = []
    for spec in cameras:
        view = belt_view_x_m(spec, centre_y_m=belt.centre_y_m, surface_z_m=belt.surface_z_m)
        if view is None:
            msg = f"cameras: {spec.name} sees none of the belt's centreline"
            raise ConfigError(msg)
        seen.append(view)
    order = sorted(range(len(cameras)), key=lambda i: seen[i][0] + seen[i][1])
    bounds = [-math.inf]
    for a, b in itertools.pairwise(order):
        bounds.append(0.5 * (seen[a][1] + seen[b][0]))
    bounds.append(math.inf)
    out: list[tuple[float, float]] = [(0.0, 0.0)] * len(cameras)
    for rank, i in enumerate(order):
        out[i] = (bounds[rank], bounds[rank + 1])
    return tuple(out)


@dataclass(frozen=True, kw_only=True, eq=False)
class _Camera:
    """One camera as the source runs it: its spec, detector, depth-noise generator, stretch of
    the belt, the belt plane's depth per pixel and where the belt is not, ``(H, W)``."""

    spec: RgbdCameraSpec
    detector: Detector
    rng: np.random.Generator
    stretch_x_m: tuple[float, float]
    belt_depth_m: np.ndarray
    off_belt: np.ndarray


class CameraSource:
    """The cameras of one episode as its perception (see the module)."""

    def __init__(
        self,
        twin: PerceptionSim,
        rig: CameraRig,
        detectors: tuple[Detector, ...],
        *,
        seed: int,
        scorer: EpisodeScorer,
        worker: ThreadPoolExecutor,
    ) -> None:
        cell = twin.cell
        config = twin.perception_config
        self.twin = twin
        self.rig = rig
        self.rate_hz = config.rate_hz
        self.latency_s = config.latency_s
        self.dropout_windows_s = tuple(twin.scenario.faults.detection_dropout)
        self.dropped_frames = 0
        self.scorer = scorer
        rngs = [np.random.default_rng(s) for s in camera_seed(seed).spawn(len(cell.cameras))]
        stretches = camera_stretches(cell.cameras, cell.belt)
        cameras = []
        for spec, detector, rng, stretch in zip(
            cell.cameras, detectors, rngs, stretches, strict=True
        ):
            depth, off = belt_plane_depth(spec, cell.belt)
            cameras.append(
                _Camera(
                    spec=spec,
                    detector=detector,
                    rng=rng,
                    stretch_x_m=stretch,
                    belt_depth_m=depth,
                    off_belt=off,
                )
            )
        self.cameras = tuple(cameras)
        self._queue: deque[tuple[float, Future[DetectionFrame]]] = deque()
        self._pending: list[Future[DetectionFrame]] = []
        self._worker = worker
        self.latest: tuple[RgbdFrame, ...] = ()
        """Every camera's frame of the last capture, as rendered (read-only: the worker reads
        them too): what the twin node publishes on the cameras' topics."""

    def capture(self, time_s: float) -> None:
        """Render every camera now and hand the frames to the worker (detect, merge, score);
        queue the result for release (not inside a dropout window)."""
        objects = {truth.id: truth for truth in self.twin.observe_objects()}
        t0 = time.perf_counter()
        snapshot = self.rig.snapshot()
        snapshot_s = time.perf_counter() - t0
        shots = []
        for camera in self.cameras:
            t0 = time.perf_counter()
            frame, robot = self.rig.capture_with_robot(
                camera.spec, rng=camera.rng, snapshot=snapshot
            )
            shots.append((camera, frame, robot, time.perf_counter() - t0 + snapshot_s))
        self.latest = tuple(shot[1] for shot in shots)
        future = self._worker.submit(self._detect, time_s, shots, objects)
        self._pending.append(future)
        if any(a <= time_s < b for a, b in self.dropout_windows_s):
            self.dropped_frames += 1
        else:
            self._queue.append((time_s + self.latency_s, future))

    def _detect(
        self,
        time_s: float,
        shots: list[tuple[_Camera, RgbdFrame, np.ndarray, float]],
        objects: dict[int, GroundTruth],
    ) -> DetectionFrame:
        """Every camera's frame through its filters and detector, merged and scored (on the
        worker thread, one frame after the other)."""
        held = [i for i, truth in objects.items() if truth.held]
        detections: list[Detection] = []
        for camera, frame, robot, render_s in shots:
            t0 = time.perf_counter()
            output = camera.detector.detect(self._filtered(camera, frame, robot, held))
            detect_s = time.perf_counter() - t0
            detections.extend(self._kept(camera, output))
            self.scorer.add(frame, output, objects, detect_s=detect_s, render_s=render_s)
        return DetectionFrame(
            capture_time_s=time_s,
            release_time_s=time_s + self.latency_s,
            detections=tuple(detections),
        )

    @staticmethod
    def _filtered(
        camera: _Camera, frame: RgbdFrame, robot: np.ndarray, held: list[int]
    ) -> RgbdFrame:
        """The frame as the detector gets it (:func:`filtered_frame`)."""
        return filtered_frame(
            frame, robot | camera.off_belt, held_ids=held, belt_depth_m=camera.belt_depth_m
        )

    @staticmethod
    def _kept(camera: _Camera, output: DetectorOutput) -> list[Detection]:
        """The camera's detections the merged frame keeps: whole in view, in its stretch."""
        lo, hi = camera.stretch_x_m
        return [
            i.detection
            for i in output.instances
            if i.detection is not None and not i.at_border and lo <= i.detection.x_m < hi
        ]

    def released(self, time_s: float) -> list[DetectionFrame]:
        """Frames whose latency has elapsed by ``time_s``, oldest first (waiting for the
        worker if one is not ready)."""
        out = []
        while self._queue and self._queue[0][0] <= time_s + 1e-9:
            out.append(self._queue.popleft()[1].result())
        self._pending = [f for f in self._pending if not f.done()]
        return out

    def summary(self) -> dict[str, float]:
        """The episode's scores over every frame taken so far (waits for the worker)."""
        for future in self._pending:
            future.result()
        self._pending = []
        return self.scorer.summary()


class PerceptionStepper:
    """The twin's perception over its life: the episode's source, its released frames, its
    scores, and the camera rig and detectors kept across episodes (see the module)."""

    def __init__(self, twin: PerceptionSim) -> None:
        self.twin = twin
        self.oracle: Perception | None = None
        self.camera: CameraSource | None = None
        self._rig: CameraRig | None = None
        self._detectors: tuple[Detector, ...] | None = None
        self._worker: ThreadPoolExecutor | None = None
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
        from twin.camera.detectors import detectors_for
        from twin.camera.rig import CameraRig
        from twin.perception_score import EpisodeScorer

        if self._rig is None:
            self._rig = CameraRig(twin)
        if self._worker is None:
            self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cdw-detector")
        if self._detectors is None:
            self._detectors = detectors_for(
                twin.dataset_dir, belt_z_m=twin.cell.belt.surface_z_m, cameras=twin.cell.cameras
            )
        self.camera = CameraSource(
            twin,
            self._rig,
            self._detectors,
            seed=seed,
            scorer=EpisodeScorer(twin.classes),
            worker=self._worker,
        )
        return None

    def step(self, step: int, time_s: float) -> None:
        """Capture if a frame is due at ``step``; collect the frames released by ``time_s``."""
        if self.oracle is not None:
            if self.oracle.capture_due(step):
                self.oracle.capture(time_s, self.twin.observe_objects())
            self._released.extend(self.oracle.released(time_s))
        elif self.camera is not None:
            from twin.camera.schedule import frame_due

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
        """Stop the worker and release the camera rig."""
        if self._worker is not None:
            self._worker.shutdown(wait=True, cancel_futures=True)
            self._worker = None
        if self._rig is not None:
            self._rig.close()
            self._rig = None
