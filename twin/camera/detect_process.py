"""The camera source's detection in a process of its own: filters, detector, merge and score.

The twin's stepping thread renders; everything after the render is numpy, scipy and Python on
the frame, and on a thread of the twin's process that Python shares one interpreter lock with
the physics and the in-process controllers, so the two serialise. In a child process the
detector runs beside the step loop on the machine's other core.

The child (started with ``spawn``: the twin's process holds an OpenGL context, PyBullet and
threads that a ``fork`` would copy half-made) builds the cameras' detectors once
(:func:`twin.camera.detectors.detectors_for`) and keeps one :class:`twin.perception_score.
EpisodeScorer` per episode. Work goes to it in order, one task at a time, so the frames come
back in capture order whatever the timing, and an episode is deterministic for a seed: the
same frames in, the same detections out.

What crosses: each camera's frame (colour, noisy depth, instance ids), the robot pixels and the
ground truth at the exposure; back come the merged :class:`interfaces.detections.
DetectionFrame` and, at the end, the episode's scores.
"""

from __future__ import annotations

import itertools
import math
import multiprocessing
import os
import time
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from interfaces.camera import RgbdCameraSpec, RgbdFrame, belt_view_x_m
from interfaces.cell import BeltSpec
from interfaces.detections import Detection, DetectionFrame
from interfaces.lifecycle import PARENT_PID_VARIABLE, die_with_parent
from interfaces.materials import ClassTable
from twin.camera.filters import (
    belt_plane_depth,
    filtered_frame,
    occluded_labels,
    occluder_mask,
)
from twin.errors import ConfigError

if TYPE_CHECKING:
    from detector.detector import Detector, DetectorOutput
    from twin.ground_truth import GroundTruth
    from twin.perception_score import EpisodeScorer

__all__ = ["DetectionProcess", "DetectorSetup", "Examples", "Shot", "camera_stretches"]


@dataclass(frozen=True, kw_only=True)
class DetectorSetup:
    """What the child builds its cameras' detectors from: the dataset (its photos train the
    classifier), the cell's cameras and belt, the classes in the scorer's order and the class
    table (the example frames' colours)."""

    dataset_dir: Path
    cameras: tuple[RgbdCameraSpec, ...]
    belt: BeltSpec
    classes: tuple[str, ...]
    materials: ClassTable


@dataclass(kw_only=True)
class Examples:
    """Where an episode's example frames go: into ``folder``, one per camera
    (:func:`interfaces.run_folder.camera_frame_name`), the first frame exposed at or after
    ``at_s`` (sim time)."""

    folder: Path
    at_s: float
    written: set[str] = field(default_factory=set)


@dataclass(frozen=True, kw_only=True)
class Shot:
    """One camera's frame of a capture as the child gets it: the camera's index in the cell,
    the frame, where a robot link was drawn ``(H, W) bool``, and the render's wall time."""

    camera: int
    frame: RgbdFrame
    robot: np.ndarray
    render_s: float


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
    """One camera as the child runs it: its detector, stretch of the belt, the belt plane's
    depth per pixel and where the belt is not, ``(H, W)``."""

    detector: Detector
    stretch_x_m: tuple[float, float]
    belt_depth_m: np.ndarray
    off_belt: np.ndarray


class _Child:
    """The child's state: the cameras, and the episode's scorer, latency and where its example
    frames go."""

    def __init__(self, setup: DetectorSetup) -> None:
        from twin.camera.detectors import detectors_for

        cameras, belt = setup.cameras, setup.belt
        detectors = detectors_for(setup.dataset_dir, belt_z_m=belt.surface_z_m, cameras=cameras)
        stretches = camera_stretches(cameras, belt)
        made = []
        for spec, detector, stretch in zip(cameras, detectors, stretches, strict=True):
            depth, off = belt_plane_depth(spec, belt)
            made.append(
                _Camera(detector=detector, stretch_x_m=stretch, belt_depth_m=depth, off_belt=off)
            )
        self.cameras = tuple(made)
        self.names = tuple(spec.name for spec in cameras)
        self.classes = setup.classes
        self.materials = setup.materials
        self.scorer: EpisodeScorer | None = None
        self.latency_s = 0.0
        self.examples: Examples | None = None

    def start(self, latency_s: float, examples: Examples | None) -> None:
        from twin.perception_score import EpisodeScorer

        self.scorer = EpisodeScorer(self.classes)
        self.latency_s = latency_s
        self.examples = examples

    def _example(
        self, time_s: float, shot: Shot, output: DetectorOutput, hidden: np.ndarray
    ) -> None:
        """Write the camera's example frame when this is the first frame at or after the
        examples' time (once per camera and episode; what is not handed on, grey)."""
        examples = self.examples
        if examples is None or time_s < examples.at_s:
            return
        from interfaces.class_colours import class_colour
        from interfaces.run_folder import camera_frame_name
        from twin.camera.overlay import write_overlay

        name = self.names[shot.camera]
        if name in examples.written:
            return
        examples.written.add(name)
        colours = class_colour(self.materials)
        path = examples.folder / camera_frame_name(name)
        write_overlay(path, shot.frame, output, colours, hidden)

    def detect(
        self, time_s: float, shots: list[Shot], objects: dict[int, GroundTruth]
    ) -> DetectionFrame:
        assert self.scorer is not None, "detect before start"
        held = [i for i, truth in objects.items() if truth.held]
        detections: list[Detection] = []
        for shot in shots:
            camera = self.cameras[shot.camera]
            occluder = occluder_mask(shot.frame, shot.robot, held_ids=held)
            frame = filtered_frame(
                shot.frame, occluder | camera.off_belt, belt_depth_m=camera.belt_depth_m
            )
            t0 = time.perf_counter()
            output = camera.detector.detect(frame)
            detect_s = time.perf_counter() - t0
            hidden = occluded_labels(output.labels, occluder)
            detections.extend(_kept(camera, output, hidden))
            self._example(time_s, shot, output, hidden)
            self.scorer.add(shot.frame, output, objects, detect_s=detect_s, render_s=shot.render_s)
        return DetectionFrame(
            capture_time_s=time_s,
            release_time_s=time_s + self.latency_s,
            detections=tuple(detections),
        )

    def summary(self) -> dict[str, float]:
        assert self.scorer is not None, "summary before start"
        return self.scorer.summary()


def _kept(camera: _Camera, output: DetectorOutput, hidden: np.ndarray) -> list[Detection]:
    """The camera's detections the merged frame keeps: whole in view (not cut by the image's
    border, not touching a robot or a held object: ``hidden[label]``), in its stretch."""
    lo, hi = camera.stretch_x_m
    return [
        i.detection
        for i in output.instances
        if i.detection is not None
        and not i.at_border
        and not hidden[i.label]
        and lo <= i.detection.x_m < hi
    ]


_CHILD: _Child | None = None


def _init(setup: DetectorSetup, parent_pid: int) -> None:
    global _CHILD  # noqa: PLW0603 (the child process's one state)
    os.environ[PARENT_PID_VARIABLE] = str(parent_pid)
    die_with_parent()  # a twin killed outright takes its detector with it
    _CHILD = _Child(setup)


def _child() -> _Child:
    assert _CHILD is not None, "the detection process was not initialised"
    return _CHILD


def _start(latency_s: float, examples: Examples | None) -> None:
    _child().start(latency_s, examples)


def _detect(time_s: float, shots: list[Shot], objects: dict[int, GroundTruth]) -> DetectionFrame:
    return _child().detect(time_s, shots, objects)


def _summary() -> dict[str, float]:
    return _child().summary()


class DetectionProcess:
    """The child process of one twin's cameras, across its episodes (see the module)."""

    def __init__(self, setup: DetectorSetup) -> None:
        self._pool = ProcessPoolExecutor(
            max_workers=1,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init,
            initargs=(setup, os.getpid()),
        )

    def start_episode(self, latency_s: float, examples: Examples | None = None) -> None:
        """A new episode: a fresh scorer, detections released ``latency_s`` after exposure,
        and (``examples``) one frame per camera written with its detections drawn."""
        self._pool.submit(_start, latency_s, examples)

    def detect(
        self, time_s: float, shots: list[Shot], objects: dict[int, GroundTruth]
    ) -> Future[DetectionFrame]:
        """The merged detections of one capture at ``time_s`` (scored in the child)."""
        return self._pool.submit(_detect, time_s, shots, objects)

    def summary(self) -> dict[str, float]:
        """The episode's scores over every capture handed over so far."""
        return self._pool.submit(_summary).result()

    def close(self) -> None:
        """Stop the child (what is queued is dropped)."""
        self._pool.shutdown(wait=True, cancel_futures=True)
