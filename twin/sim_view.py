"""What the cameras and the perception read of a running twin: two protocols the sim satisfies.

:class:`twin.sim.Twin` owns the stepping and its :class:`twin.perception_source.PerceptionStepper`;
the stepper, its camera source and the camera rig (:mod:`twin.camera.rig`,
:mod:`twin.camera.twin_scene`) read the twin's state back through these protocols instead of
naming the sim, so the import arrows run one way: the sim above its perception, the perception
above the cameras, all of them above these protocols and the value types they use.

- :class:`CameraSim`: what the rig draws (the PyBullet client, the cell, the sim time, the
  stations' robots, the static scene, and each object's body, mesh spec and sampled height);
- :class:`PerceptionSim`: that, and what the perception source needs to start an episode and
  score its frames (configuration, scenario faults, classes, step, dataset, ground truth and
  object meshes).
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import numpy as np

from interfaces.cell import Cell
from twin.ground_truth import GroundTruth
from twin.objects import ObjectSpec
from twin.perception_config import PerceptionConfig
from twin.scenario import Scenario
from twin.station import Station
from twin.world import World

__all__ = ["CameraSim", "PerceptionSim"]


class CameraSim(Protocol):
    """What the camera rig reads of a running twin (:class:`twin.sim.Twin` is one)."""

    @property
    def client(self) -> int:
        """The PyBullet client the scene lives in."""
        ...

    @property
    def cell(self) -> Cell:
        """The cell: belt, bins, cameras, class table."""
        ...

    @property
    def time_s(self) -> float:
        """Simulated time now, s."""
        ...

    @property
    def stations(self) -> tuple[Station, ...]:
        """The episode's stations (a new tuple at every reset), their robots drawn."""
        ...

    @property
    def world(self) -> World | None:
        """The episode's static scene (None before the first reset)."""
        ...

    def object_shape(self, object_id: int) -> tuple[ObjectSpec, float] | None:
        """The meshgen spec and sampled height of an object of this episode (None: no such
        id yet)."""
        ...

    def body_of(self, object_id: int) -> int | None:
        """The PyBullet body of an object while it is simulated, else None."""
        ...


class PerceptionSim(CameraSim, Protocol):
    """What the perception source reads of a running twin (:class:`twin.sim.Twin` is one)."""

    @property
    def perception_config(self) -> PerceptionConfig:
        """The camera model: the oracle or the rendered cameras, rate, latency, errors."""
        ...

    @property
    def scenario(self) -> Scenario:
        """The episode's scenario (its faults: detection-dropout windows)."""
        ...

    @property
    def classes(self) -> tuple[str, ...]:
        """The classes that can enter the belt: the detector's labels."""
        ...

    @property
    def dt_s(self) -> float:
        """The physics step, s."""
        ...

    @property
    def dataset_dir(self) -> Path:
        """The meshgen output folder (the detectors are built for it)."""
        ...

    def observe_objects(self) -> tuple[GroundTruth, ...]:
        """Ground truth of every object on the belt, held or in a bin."""
        ...

    def object_mesh(self, object_id: int) -> tuple[np.ndarray, str]:
        """An object's mesh triangles ``(t, 3, 3)`` in its own frame, m, and its class."""
        ...
