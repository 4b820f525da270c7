"""The detector the twin runs on its cameras' frames: one per camera, built once per process.

:func:`detectors_for` asks the detector package's factory (:func:`detector.factory.
detector_for`: the baseline detector whose colour classifier is trained on the dataset's own
photos, resized to the cameras' pixel on the belt) for one detector per camera, so each keeps
its own view of the belt (the factory caches them per process).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from interfaces.camera import RgbdCameraSpec

if TYPE_CHECKING:
    from detector.detector import Detector

__all__ = ["detectors_for"]


def detectors_for(
    dataset_dir: Path, *, belt_z_m: float, cameras: Sequence[RgbdCameraSpec]
) -> tuple[Detector, ...]:
    """A detector for each of ``cameras`` (same order) on ``dataset_dir``'s classes."""
    from detector.factory import detector_for

    return tuple(detector_for(dataset_dir, belt_z_m=belt_z_m, cameras=(spec,)) for spec in cameras)
