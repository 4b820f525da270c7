"""What an episode of the twin is set up from: the collision cache, the belt drive's parameters,
the classes that can enter the belt.

Pure helpers of :class:`twin.sim.Twin` (which re-exports them), in a module of their own so the
twin's stepping stays short.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from interfaces.cell import Cell, DriveSpec
from twin.builtin import cache_root
from twin.errors import ConfigError
from twin.objects import ImageLayout
from twin.scenario import PerturbationLevel, Scenario

__all__ = [
    "collision_cache_dir",
    "drive_parameters",
    "entering_classes",
    "robot_visuals_wanted",
]


def collision_cache_dir() -> tuple[Path, tempfile.TemporaryDirectory[str] | None]:
    """Where merged collision shapes go: ``<cache root>/collision``, shared by every episode.

    The files are keyed by content (:func:`twin.collision.merged_collision_file`), so one merge
    per mesh per machine serves every later episode. Where the cache root cannot be created
    (a read-only home), a temporary folder of this twin's own, removed on close.
    """
    folder = cache_root() / "collision"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        usable = os.access(folder, os.W_OK | os.X_OK)
    except OSError:
        usable = False
    if not usable:
        temporary = tempfile.TemporaryDirectory(prefix="cdw-twin-shapes-")
        return Path(temporary.name), temporary
    return folder, None


def drive_parameters(
    drive: DriveSpec, perturbation: PerturbationLevel, fmu_seed: int
) -> dict[str, float]:
    """The belt-drive FMU's parameters for an episode: the cell's ``drive.parameters``, and
    the scenario's perturbation (off: force 0) through the drive's perturbation mapping.

    A drive without a perturbation mapping takes none; a scenario that enables one is refused.
    """
    params = dict(drive.parameters)
    names = drive.perturbation
    if names is None:
        if perturbation.enabled:
            msg = (
                f"system.perturbation.enabled: the belt drive {drive.fmu!r} has no perturbation "
                "mapping (drive.perturbation in the cell file)"
            )
            raise ConfigError(msg)
        return params
    params.setdefault(names.force_std, perturbation.force_std_N if perturbation.enabled else 0.0)
    params.setdefault(names.correlation_time, perturbation.correlation_time_s)
    params.setdefault(names.seed, fmu_seed % 2**31)
    return params


def entering_classes(
    layouts: tuple[ImageLayout, ...], scenario: Scenario, cell: Cell
) -> tuple[str, ...]:
    """The classes objects of the dataset can enter the belt with (``objects.classes``, empty:
    all), in the cell's order (its bins'), then any the cell has no bin for."""
    present = {spec.class_name for layout in layouts for spec in layout.objects}
    wanted = scenario.objects.classes
    kept = {name for name in present if not wanted or name in wanted}
    ordered = [name for name in cell.classes if name in kept]
    return (*ordered, *sorted(kept - set(ordered)))


def robot_visuals_wanted(
    cell: Cell, perception_source: str, *, over_ros: bool, recorded: bool, viewed: bool
) -> bool:
    """Whether anything of an episode renders the robots: the camera perception source, or the
    cell's camera topics when anyone could take their frames (a subscriber over ROS 2, a
    recording, the live view; in process with neither, nobody can). PyBullet's window has
    them whatever this says (:attr:`twin.sim.Twin.visual_shapes`)."""
    if perception_source == "camera":
        return True
    return bool(cell.cameras) and (over_ros or recorded or viewed)
