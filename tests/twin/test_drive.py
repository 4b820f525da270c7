"""The belt drive is the cell's: an FMU file named in the cell file, with its mapping,
parameters and communication step, runs the twin's belt."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import pytest
from twin_helpers import box_px

from interfaces.cell import Cell, DriveSpec, default_cell
from twin.errors import ConfigError
from twin.scenario import PerturbationLevel, Scenario, SystemLevel
from twin.sim import Twin

ONE_BOX = {"img": [(1, box_px(500, 500, 100, 50))]}


def _cell_with(drive: DriveSpec) -> Cell:
    return replace(default_cell(), drive=drive)


def test_an_fmu_file_named_in_the_cell_drives_the_belt_at_its_step(
    mesh_polygons: Callable[..., Path], built_fmus: tuple[Path, Path]
) -> None:
    """Our FMI 2.0 build given as a file (not ``builtin``), stepped every 5 physics steps,
    with a parameter of the cell file: the belt runs at the setpoint."""
    _, fmi2 = built_fmus
    drive = DriveSpec(
        fmu=str(fmi2), parameters={"drum_radius_m": 0.1}, perturbation=None, step_s=5 / 240
    )
    scenario = Scenario(system=SystemLevel(belt_speed_mps=0.3, repeat_images=False))
    with Twin(scenario, dataset_dir=mesh_polygons(ONE_BOX), cell=_cell_with(drive)) as twin:
        twin.reset(seed=0)
        times = []
        for _ in range(480):
            twin.advance()
            times.append(twin.observe_belt().time_s)
    assert twin.observe_belt().belt_speed_mps == pytest.approx(0.3, abs=0.01)
    # one communication point every 5 steps: the drive's time moves in 5-step strides
    assert sorted(set(times)) == pytest.approx([5 * k / 240 for k in range(1, 97)])


def test_a_perturbation_needs_a_drive_that_maps_one(
    mesh_polygons: Callable[..., Path], built_fmus: tuple[Path, Path]
) -> None:
    _, fmi2 = built_fmus
    cell = _cell_with(DriveSpec(fmu=str(fmi2), perturbation=None))
    scenario = Scenario(
        system=SystemLevel(perturbation=PerturbationLevel(enabled=True), repeat_images=False)
    )
    with pytest.raises(ConfigError, match=r"system\.perturbation\.enabled: the belt drive .*"):
        Twin(scenario, dataset_dir=mesh_polygons(ONE_BOX), cell=cell)
