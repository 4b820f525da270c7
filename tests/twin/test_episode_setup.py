"""Which episodes load the robots with their visual meshes (issue 37: a robot without them
loads in milliseconds; ``tests/twin/test_robot_load.py`` shows it moves the same)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from interfaces.cell import Cell, load_cell
from twin.episode_setup import robot_visuals_wanted

LINE = load_cell("interfaces/cells/line.yaml")
NO_CAMERA = replace(LINE, cameras=())


@pytest.mark.parametrize(
    ("cell", "source", "over_ros", "recorded", "viewed", "wanted"),
    [
        (LINE, "oracle", False, False, False, False),  # in process, nobody takes a frame
        (LINE, "oracle", True, False, False, True),  # a ROS 2 client may subscribe
        (LINE, "oracle", False, True, False, True),  # the recording takes the frames
        (LINE, "oracle", False, False, True, True),  # the live view may subscribe
        (LINE, "camera", False, False, False, True),  # the detector renders every frame
        (NO_CAMERA, "oracle", True, True, True, False),  # no camera: nothing renders
    ],
)
def test_the_robots_visual_meshes_are_loaded_only_when_something_renders_them(
    cell: Cell, source: str, over_ros: bool, recorded: bool, viewed: bool, wanted: bool
) -> None:
    got = robot_visuals_wanted(cell, source, over_ros=over_ros, recorded=recorded, viewed=viewed)
    assert got is wanted
