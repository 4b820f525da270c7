"""A line of two stations: each arm grasps in its own pick window, events and scores per station.

The shipped ``two_pandas`` cell: station ``upstream`` (base at x = -1.5 m, window
[-1.85, -1.15] m) and ``downstream`` (base at the origin, window [-0.35, 0.35] m). Two images of
one box each are parked on the stopped belt, one in each window (prefill 3.1 m puts the first
image's box at x = 0; an image gap of 0.9 m puts the second's 1.5 m upstream of it). Both arms
are scripted at once: over the box, down, close, lift, over their own station's bin, open.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pybullet as pb
import pytest
from twin_helpers import box_px, tcp_ik

from interfaces.bins import BinSpec
from interfaces.cell import load_cell
from interfaces.events import EventType
from twin.scenario import Scenario, SystemLevel
from twin.sim import ArmCommand, Twin

TWO_BOXES = {
    "a": [(1, box_px(500, 500, 100, 50))],  # brick, ends up at x = 0 (downstream)
    "b": [(2, box_px(500, 500, 100, 50))],  # wood, ends up at x = -1.5 (upstream)
}
OPEN_M = 0.08


def _hold(
    twin: Twin, targets: dict[int, tuple[tuple[float, float, float], float]], s: float
) -> None:
    """Command every station's TCP position and gripper opening, then step ``s`` seconds."""
    for station, (position, width) in targets.items():
        twin.command(
            ArmCommand(
                tcp_ik(twin, position, station=station), gripper_width_m=width, station=station
            )
        )
    end = twin.time_s + s
    while twin.time_s < end - 1e-9:
        twin.advance()


def test_two_stations_each_pick_in_their_own_window_and_are_scored_apart(
    mesh_polygons: Callable[..., Path],
) -> None:
    meshes = mesh_polygons(TWO_BOXES)
    scenario = Scenario(
        cell="two_pandas",
        duration_s=30.0,
        system=SystemLevel(belt_speed_mps=0.0, prefill_m=3.1, image_gap_m=0.9, repeat_images=False),
    )
    with Twin(scenario, dataset_dir=meshes) as twin:
        obs, _ = twin.reset(seed=0)
        assert [s.name for s in twin.stations] == ["upstream", "downstream"]
        assert len(obs.arms) == 2
        boxes = {("downstream" if o.position_m[0] > -0.75 else "upstream"): o for o in obs.objects}
        assert boxes["downstream"].position_m[0] == pytest.approx(0.0, abs=0.02)
        assert boxes["upstream"].position_m[0] == pytest.approx(-1.5, abs=0.02)
        index = {s.name: s.index for s in twin.stations}
        grasp = {}
        for name, box in boxes.items():
            x, y, z = box.position_m
            grasp[index[name]] = (x, y, z + 0.5 * box.height_m - 0.02)
            twin.announce_target(box.id, grasp[index[name]], "approach", station=index[name])
        bins: dict[int, BinSpec] = {}
        for name, box in boxes.items():
            bin_spec = twin.cell.station(name).bin_for(box.class_name)
            assert bin_spec is not None
            bins[index[name]] = bin_spec

        def each(
            position: Callable[[int], tuple[float, float, float]], width: float
        ) -> dict[int, tuple[tuple[float, float, float], float]]:
            return {i: (position(i), width) for i in grasp}

        _hold(twin, each(lambda i: (*grasp[i][:2], grasp[i][2] + 0.3), OPEN_M), 2.0)
        _hold(twin, each(lambda i: (*grasp[i][:2], grasp[i][2] + 0.1), OPEN_M), 1.0)
        _hold(twin, each(lambda i: grasp[i], OPEN_M), 1.0)
        for i, point in grasp.items():
            twin.announce_target(0, point, "close", station=i)
        _hold(twin, each(lambda i: grasp[i], 0.0), 0.5)
        _hold(twin, each(lambda i: (*grasp[i][:2], 0.3), 0.0), 1.0)
        _hold(twin, each(lambda i: (bins[i].centre_x_m, 0.35, 0.3), 0.0), 1.0)
        _hold(twin, each(lambda i: (bins[i].centre_x_m, bins[i].centre_y_m, 0.2), 0.0), 1.5)
        _hold(twin, each(lambda i: (bins[i].centre_x_m, bins[i].centre_y_m, 0.2), OPEN_M), 1.5)
        events = twin.events
        counts = {name: twin.counts(name) for name in index}
        line = twin.counts()
        tracking = {name: twin.tracking_results(name) for name in index}
    picks = {e.object_id: e.data["station"] for e in events if e.type is EventType.PICK_SUCCESS}
    assert picks == {boxes["upstream"].id: "upstream", boxes["downstream"].id: "downstream"}
    placed = {
        e.object_id: (e.data["bin"], e.data["correct"], e.data["station"])
        for e in events
        if e.type is EventType.PLACED_IN_BIN
    }
    assert placed == {
        boxes["upstream"].id: ("wood", True, "upstream"),
        boxes["downstream"].id: ("brick", True, "downstream"),
    }
    # every event about a robot or a window names its station; each box only its own
    for e in events:
        if e.type in (EventType.SPAWNED, EventType.FELL_OFF):
            assert "station" not in e.data
        else:
            owner = next(name for name, box in boxes.items() if box.id == e.object_id)
            assert e.data["station"] == owner, e
    for name in index:
        assert (counts[name].spawned, counts[name].picked, counts[name].placed_correct) == (1, 1, 1)
        assert counts[name].missed == counts[name].unintended_contacts == 0
        (pursuit,) = tracking[name]
        assert pursuit.object_id == boxes[name].id
    assert (line.spawned, line.picked, line.placed_correct, line.processed) == (2, 2, 2, 2)


def test_the_two_station_cell_loads_each_robot_at_its_base(
    mesh_polygons: Callable[..., Path],
) -> None:
    cell = load_cell("two_pandas")
    scenario = Scenario(system=SystemLevel(belt_speed_mps=0.0, repeat_images=False))
    with Twin(scenario, dataset_dir=mesh_polygons(TWO_BOXES), cell=cell) as twin:
        obs, _ = twin.reset(seed=0)
        first = twin.stations[0]
        for station, arm in zip(twin.stations, obs.arms, strict=True):
            shift = np.subtract(station.spec.base_position_m, first.spec.base_position_m)
            # the body (its base's centre of mass) and the TCP at the home joints are shifted
            # by the difference of the base positions (to PyBullet's float32 frames)
            bodies = [
                pb.getBasePositionAndOrientation(s.robot.body, physicsClientId=twin.client)[0]
                for s in (station, first)
            ]
            assert np.subtract(*bodies) == pytest.approx(shift, abs=1e-6)
            assert np.subtract(arm.tcp_position_m, obs.arms[0].tcp_position_m) == pytest.approx(
                shift, abs=1e-6
            )
            assert arm.gripper_width_m == pytest.approx(0.08, abs=1e-3)
