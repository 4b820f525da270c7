"""The twin marks every spawned piece with whether some station of the cell could take it, by
the controllers' own rules, from the piece's true shape as it spawns; the same judgement
``cdw-twin fit`` gives the dataset's pieces."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import pytest
from twin_helpers import box_px

from control.fit import line_refusal
from experiments.fit_rules import flat_pieces
from interfaces.cell import default_cell
from interfaces.events import EventType
from twin.cmd_node import spawn_judge
from twin.objects import load_dataset
from twin.scenario import Scenario, SystemLevel
from twin.sim import Twin

PIECES = {
    "img": [
        (1, box_px(200, 300, 100, 60)),  # brick, 60 x 36 mm: the Panda's hand takes it
        (1, box_px(500, 300, 220, 200)),  # brick, 132 x 120 mm: wider than its 80 mm hand
    ]
}


def _judged(twin: Twin) -> dict[str, dict[str, object]]:
    return {str(e.data["source_id"]): e.data for e in twin.events if e.type is EventType.SPAWNED}


def test_spawned_events_say_whether_some_station_could_take_the_piece(
    mesh_polygons: Callable[..., Path],
) -> None:
    meshes = mesh_polygons(PIECES)
    scenario = Scenario(system=SystemLevel(belt_speed_mps=0.0, repeat_images=False))
    cell = default_cell()
    args = argparse.Namespace(scenario=None, params_file=None)  # the scenario's: default
    judge = spawn_judge(args, scenario, cell)
    with Twin(scenario, dataset_dir=meshes, cell=cell) as twin:
        twin.spawn_judge = judge
        twin.reset(seed=0)
        twin.advance()
        judged = _judged(twin)
    assert judged["img_000"]["takeable"] is True
    assert "refusal" not in judged["img_000"]
    assert (judged["img_001"]["takeable"], judged["img_001"]["refusal"]) == (False, "too_wide")
    # the same judgement as cdw-twin fit's, which judges the dataset's pieces lying flat
    from control.config import DEFAULT_PARAMS, station_configs

    configs = station_configs(DEFAULT_PARAMS, cell)
    objects = [o for layout in load_dataset(meshes) for o in layout.objects]
    for spec, piece in zip(objects, flat_pieces(objects), strict=True):
        refusal = line_refusal(piece, configs)
        assert judged[spec.object_id]["takeable"] is (refusal is None)
        assert judged[spec.object_id].get("refusal") == refusal


def test_without_a_judge_the_events_carry_no_mark(mesh_polygons: Callable[..., Path]) -> None:
    meshes = mesh_polygons(PIECES)
    scenario = Scenario(system=SystemLevel(belt_speed_mps=0.0, repeat_images=False))
    with Twin(scenario, dataset_dir=meshes, cell=default_cell()) as twin:
        twin.reset(seed=0)
        twin.advance()  # the spawned events are logged with the first step
        judged = _judged(twin)
    assert set(judged) == {"img_000", "img_001"}
    assert all("takeable" not in data for data in judged.values())


def test_a_parameter_file_that_does_not_fit_the_cell_is_refused(tmp_path: Path) -> None:
    from interfaces.errors import CdwTwinError

    params = tmp_path / "params.yaml"
    params.write_text(
        "controller:\n  ros__parameters:\n    scheduler: {class_priorities: {glass: 2.0}}\n",
        encoding="utf-8",
    )
    args = argparse.Namespace(scenario=None, params_file=params)
    with pytest.raises(CdwTwinError, match=r"class_priorities\.glass = 2\.0: not a class"):
        spawn_judge(args, Scenario(), default_cell())
