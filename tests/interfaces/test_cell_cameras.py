"""The cell file's ``cameras:`` list: parsed, checked with errors naming the key, written back."""

from __future__ import annotations

import copy
from typing import Any

import pytest
import yaml

from interfaces.camera import RgbdCameraSpec
from interfaces.cell import CellError, cell_from_data, load_cell


def reference_data() -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load(load_cell("default").to_yaml())
    return data


def test_the_shipped_cells_declare_cameras_that_round_trip() -> None:
    for name in ("default", "line"):
        cell = load_cell(name)
        back = cell_from_data(yaml.safe_load(cell.to_yaml()), "round-trip")
        assert back.cameras == cell.cameras
        assert all(isinstance(c, RgbdCameraSpec) for c in cell.cameras)
    assert [c.name for c in load_cell("line").cameras] == ["cam1", "cam2", "cam3", "cam4"]
    # the oracle's field of view stays beside them
    assert load_cell("default").camera.fov_max_x_m == 0.45


def test_a_cell_without_cameras_has_none() -> None:
    data = reference_data()
    del data["cameras"]
    assert cell_from_data(data, "no-cameras").cameras == ()


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda c: c.update(cameras={"name": "x"}), r"cameras = .*expected a list"),
        (lambda c: c["cameras"][0].update(lens="wide"), r"cameras\[0\].*lens"),
        (lambda c: c["cameras"][0].update(rate_hz=500.0), r"rate_hz = 500\.0"),
        (lambda c: c["cameras"][0].update(name="a b"), r"camera\.name = 'a b'"),
        (
            lambda c: c["cameras"].append(copy.deepcopy(c["cameras"][0])),
            r"cameras = \['camera', 'camera'\]: camera names must differ",
        ),
        (
            lambda c: c["cameras"][0].update(rpy_rad=[0.0, -1.5707963267948966, 0.0]),
            r"cameras\[0\] \(camera\)\.position_m .*sees none of the belt",
        ),
        (
            lambda c: c["cameras"][0].update(position_m=[1.0, 0.5, 1.3]),
            r"no camera sees the belt's centreline at x = -0\.45 m",
        ),
    ],
)
def test_bad_cameras_are_refused_naming_the_key(change: Any, match: str) -> None:
    data = reference_data()
    change(data)
    with pytest.raises(CellError, match=match) as info:
        cell_from_data(data, "cell.yaml")
    assert str(info.value).startswith("cell.yaml")
