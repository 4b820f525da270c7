"""``cdw-twin picture``: the real twin in PyBullet DIRECT rendered by TinyRenderer, small images."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from matplotlib.image import imread

from experiments.picture import BELT_RGB, Camera, take_picture
from interfaces.cell import load_cell
from twin.cli import main
from twin.scenario import Scenario

WIDTH_PX, HEIGHT_PX = 160, 96


def projected_pixel(camera: Camera, point_m: Sequence[float]) -> tuple[int, int]:
    """Row and column of a world point, projected with the camera's OpenGL matrices
    (column-major, as PyBullet takes them)."""
    view = np.asarray(camera.view_matrix).reshape(4, 4).T
    projection = np.asarray(camera.projection_matrix).reshape(4, 4).T
    clip = projection @ view @ np.array([*point_m, 1.0])
    x_ndc, y_ndc = clip[0] / clip[3], clip[1] / clip[3]
    column = int((x_ndc + 1.0) * 0.5 * camera.width_px)
    row = int((1.0 - y_ndc) * 0.5 * camera.height_px)
    return row, column


def belt_coloured(rgb: npt.NDArray[np.floating]) -> bool:
    """Whether a pixel (RGB in [0, 1]) is the belt's colour under some light: a multiple of
    :data:`BELT_RGB` (shading scales it), every channel within 0.04 of it."""
    belt = np.asarray(BELT_RGB)
    scale = float(rgb @ belt / (belt @ belt))
    return 0.3 < scale < 1.5 and float(np.max(np.abs(rgb - scale * belt))) < 0.04


def test_picture_shows_the_belt_where_the_camera_projects_it(
    tmp_path: Path, builtin_meshes: Path
) -> None:
    out = tmp_path / "cell.png"
    args = ["--cell", "default", "--dataset", str(builtin_meshes), "--prefill", "0"]
    size = ["--time", "0.1", "--width", str(WIDTH_PX), "--height", str(HEIGHT_PX)]
    assert main(["picture", *args, *size, "--out", str(out)]) == 0

    image = imread(out)[:, :, :3]
    assert image.shape == (HEIGHT_PX, WIDTH_PX, 3)
    assert float(image.std(axis=(0, 1)).max()) > 0.05, "the picture is uniform"
    assert not list(tmp_path.glob(".*.tmp")), "a temporary file is left behind"

    # the same twin and camera through the module: the file holds that rendering
    cell = load_cell("default")
    picture = take_picture(
        cell, Scenario(), builtin_meshes, time_s=0.1, width_px=WIDTH_PX, height_px=HEIGHT_PX
    )
    assert np.array_equal(np.round(image * 255).astype(np.uint8), picture.rgb)

    belt = cell.belt
    centre = (0.5 * (belt.start_x_m + belt.end_x_m), belt.centre_y_m, belt.surface_z_m)
    row, column = projected_pixel(picture.camera, centre)
    assert 0 <= row < HEIGHT_PX
    assert 0 <= column < WIDTH_PX
    assert belt_coloured(image[row, column]), image[row, column]
    assert not belt_coloured(image[0, 0]), "the corner (the floor) is belt-coloured"


def test_default_picture_is_the_line_framing_every_station_and_bin(builtin_meshes: Path) -> None:
    cell = load_cell("line")
    picture = take_picture(
        cell, Scenario(), builtin_meshes, time_s=0.0, width_px=WIDTH_PX, height_px=HEIGHT_PX
    )
    assert len(cell.stations) >= 2, "the line has several stations"
    for station in cell.stations:
        points = [station.base_position_m]
        points += [(b.centre_x_m, b.centre_y_m, b.top_z_m) for b in station.bins]
        for point in points:
            row, column = projected_pixel(picture.camera, point)
            assert 0 <= row < HEIGHT_PX, (station.name, point)
            assert 0 <= column < WIDTH_PX, (station.name, point)


def test_unknown_cell_is_refused_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cell.png"
    assert main(["picture", "--cell", "no_such_cell", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("cdw-twin: error:")
    assert "'no_such_cell'" in err
    assert len(err.splitlines()) == 1
    assert not out.exists()


def test_missing_out_folder_is_refused_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "missing"
    assert main(["picture", "--out", str(folder / "cell.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("cdw-twin: error: --out")
    assert str(folder) in err
    assert len(err.splitlines()) == 1
    assert not folder.exists()
