"""``cdw-twin fit``: which tools fit a dataset's pieces, judged by the controllers' own rules on
meshgen's real meshes (the built-in sample, hand-made boxes, the shared real sample)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import write_yolo

from experiments.fit import (
    HEIGHT_EDGES_M,
    NARROW_EDGES_M,
    bin_labels,
    bin_of,
    fit_dataset,
    suggest_mix,
)
from experiments.fit_rules import (
    REFUSALS,
    Piece,
    StationSetup,
    catalogue_setups,
    cell_setups,
    default_params,
    flat_pieces,
    line_refusal,
    takeable,
)
from interfaces.catalog import catalog_names
from interfaces.cell import load_cell, resolve_cell_path
from interfaces.materials import shipped_table
from meshgen.config import MeshgenConfig
from meshgen.pipeline import mesh_dataset
from twin.cli import main
from twin.objects import load_dataset

REAL_SAMPLE = Path(__file__).resolve().parents[3] / "shared" / "datasets" / "cdw_stacked_sample"

PX_PER_M = 1000 / 0.6
"""The hand-made images: 1000 px across a 0.6 m belt."""

BOXES: dict[str, tuple[int, float, float]] = {
    # name: (class id in the table below, length m, width m); heights come from the class
    "tile": (3, 0.12, 0.05),  # rubber, 1 cm tall: too flat for any jaws, 5 cm for the cups
    "cube": (2, 0.03, 0.03),  # wood, 4 cm: any jaws; too small for either cup
    "slab": (2, 0.10, 0.10),  # wood, 4 cm: too wide for the Panda hand and the xArm gripper
    "block": (0, 0.10, 0.10),  # concrete, 8 cm: too heavy for either cup (line.yaml densities)
}

EXPECTED: dict[str, dict[str, str | None]] = {
    "tile": {
        "panda_hand": "too_flat",
        "xarm_gripper": "too_flat",
        "wide_gripper": "too_flat",
        "suction_cup": "too_small",
        "suction_cup_25": None,
    },
    "cube": {
        "panda_hand": None,
        "xarm_gripper": None,
        "wide_gripper": None,
        "suction_cup": "too_small",
        "suction_cup_25": "too_small",
    },
    "slab": {
        "panda_hand": "too_wide",
        "xarm_gripper": "too_wide",
        "wide_gripper": None,
        "suction_cup": None,
        "suction_cup_25": None,
    },
    "block": {
        "panda_hand": "too_wide",
        "xarm_gripper": "too_wide",
        "wide_gripper": None,
        "suction_cup": "too_heavy",
        "suction_cup_25": "too_heavy",
    },
}


@pytest.fixture(scope="module")
def builtin_sample(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The built-in sample, 8 images, meshed into this module's own folder."""
    from twin.builtin import builtin_dataset

    return builtin_dataset(tmp_path_factory.mktemp("fit_builtin"), images=8, seed=0)


@pytest.fixture(scope="module")
def boxes(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """:data:`BOXES` as axis-aligned rectangles, one image each, meshed with fixed heights
    (rubber 1 cm, wood 4 cm, concrete 8 cm)."""
    root = tmp_path_factory.mktemp("fit_boxes")
    labels = {}
    for name, (class_id, length_m, width_m) in BOXES.items():
        u0, v0 = 300.0, 300.0
        u1, v1 = u0 + width_m * PX_PER_M, v0 + length_m * PX_PER_M
        labels[name] = [(class_id, [(u0, v0), (u1, v0), (u1, v1), (u0, v1)])]
    heights = {"concrete": 0.08, "brick": 0.05, "wood": 0.04, "rubber": 0.01}
    shipped = shipped_table()
    classes = replace(
        shipped,
        classes=tuple(
            replace(spec, height_min_m=heights[spec.name], height_max_m=heights[spec.name])
            for spec in shipped.classes
        ),
    )
    out = root / "meshes"
    config = MeshgenConfig(image_size_px=(1000, 1000), classes=classes, textures=False)
    mesh_dataset(write_yolo(root / "data", labels), out, config)
    return out


def test_hand_made_boxes_are_refused_for_exactly_their_reasons(boxes: Path) -> None:
    layouts = load_dataset(boxes)
    objects = {layout.image: layout.objects[0] for layout in layouts}
    assert sorted(objects) == sorted(BOXES)
    names = list(objects)
    pieces = dict(zip(names, flat_pieces([objects[n] for n in names]), strict=True))
    # the suction disc comes from the mesh: a rectangle's is half its narrow side, level
    for name, piece in pieces.items():
        assert piece.face_radius_m == pytest.approx(piece.narrow_m / 2, abs=1e-3), name
        assert piece.face_tilt_rad == pytest.approx(0.0, abs=1e-9)
    setups = {s.name: s for s in catalogue_setups(shipped_table())}
    assert list(setups) == list(catalog_names()["tools"])
    assert setups["panda_hand"].robot == "panda"
    assert setups["wide_gripper"].robot == "ur10"
    assert setups["suction_cup"].params.name == "line.yaml"
    for name, expected in EXPECTED.items():
        got = {tool: takeable(pieces[name], setups[tool].config) for tool in expected}
        assert got == expected, name

    # the reference cell's Panda takes only the cube; the line every box, some station each
    panda = cell_setups(load_cell("default"), default_params(resolve_cell_path("default")))
    line_cell = load_cell("line")
    line = cell_setups(line_cell, default_params(resolve_cell_path("line")))
    assert line[0].params.name == "line.yaml"
    assert [line_refusal(pieces[n], [s.config for s in panda]) for n in BOXES] == [
        "too_flat",
        None,
        "too_wide",
        "too_wide",
    ]
    assert all(line_refusal(pieces[n], [s.config for s in line]) is None for n in BOXES)
    # the cups of the line alone leave the cube (too small for both) and the block (too heavy)
    cups = [s.config for s in line if s.tool.startswith("suction_cup")]
    assert line_refusal(pieces["cube"], cups) == "too_small"
    assert line_refusal(pieces["block"], cups) == "too_heavy"


def test_takeable_refuses_a_class_without_bin_and_a_tilted_face() -> None:
    line = {
        s.tool: s.config
        for s in cell_setups(load_cell("line"), default_params(resolve_cell_path("line")))
    }
    piece = Piece(class_name="wood", length_m=0.1, width_m=0.08, height_m=0.04)
    assert takeable(piece, line["suction_cup"]) is None  # no disc reported: the narrow side
    assert takeable(replace(piece, class_name="glass"), line["suction_cup"]) == "no_bin"
    propped = replace(piece, face_radius_m=0.04, face_tilt_rad=0.5)
    assert takeable(propped, line["suction_cup"]) == "too_tilted"
    assert takeable(propped, line["wide_gripper"]) is None  # the jaws do not judge the face
    assert set(REFUSALS) == {
        "no_bin",
        "too_wide",
        "too_flat",
        "too_small",
        "too_tilted",
        "too_heavy",
    }


def test_size_bins() -> None:
    assert bin_labels(NARROW_EDGES_M) == ("<3", "3-5", "5-8", ">8")
    assert bin_labels(HEIGHT_EDGES_M) == ("<1", "1-2", "2-4", "4-6", ">6")
    assert [bin_of(v, NARROW_EDGES_M) for v in (0.01, 0.03, 0.049, 0.08, 0.2)] == [0, 1, 1, 3, 3]


def test_suggest_mix_covers_greedily_then_shares_stations_by_load() -> None:
    setups = catalogue_setups(shipped_table())[:3]
    a, b, c = (s.name for s in setups)
    taken = {
        a: [True] * 6 + [False] * 4,  # 0-5
        b: [False] * 4 + [True] * 6,  # 4-9
        c: [True] * 2 + [False] * 8,  # 0-1: nothing a does not take
    }
    mix = suggest_mix(setups, taken, stations=5)
    assert [e.tool for e in mix.entries] == [a, b]  # c adds nothing once a is chosen
    assert [e.adds for e in mix.entries] == [0.6, 0.4]
    assert [e.load for e in mix.entries] == [0.5, 0.5]  # pieces 4 and 5 shared
    assert [e.stations for e in mix.entries] == [3, 2]  # ties go to the first chosen
    assert mix.share == 1.0
    assert suggest_mix(setups, taken, stations=1).entries[0].stations == 1
    nothing = {name: [False] * 10 for name in (a, b, c)}
    assert suggest_mix(setups, nothing, stations=3).entries == ()


def test_builtin_sample_every_tool_takes_some_and_the_line_more(builtin_sample: Path) -> None:
    report = fit_dataset(builtin_sample)
    tools = report["tools"]
    assert list(tools) == list(catalog_names()["tools"])
    for name, tool in tools.items():
        assert 0.0 < tool["share"] <= 1.0, name
        assert tool["takes"] + sum(tool["refused"].values()) == report["pieces"], name
    cell = report["cell"]
    assert (cell["name"], len(cell["stations"])) == ("line", 8)
    assert cell["share"] > max(t["share"] for t in tools.values())
    assert report["mix"]["stations"] == 8
    assert report["mix"]["share"] >= cell["share"] - 1e-9  # the greedy cover of all tools
    assert sum(e["stations"] for e in report["mix"]["tools"]) == 8
    # per station: the catalogue tool's figure (the same tool, parameter file and bins)
    for station in cell["stations"].values():
        assert station["share"] == tools[station["tool"]]["share"]


def test_cli_json_has_the_documented_keys(
    builtin_sample: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["fit", str(builtin_sample), "--cell", "default", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert list(report) == ["dataset", "pieces", "classes", "size_bins", "tools", "cell", "mix"]
    assert list(report["classes"]) == ["concrete", "brick", "wood", "rubber"]  # table order
    assert list(report["size_bins"]) == ["narrow_side_cm", "height_cm"]
    assert sum(report["size_bins"]["height_cm"].values()) == report["pieces"]
    shares = ["share", "takes", "by_class", "by_narrow_side_cm", "by_height_cm"]
    for tool in report["tools"].values():
        assert list(tool) == ["robot", "params", *shares, "refused"]
        assert list(tool["refused"]) == list(REFUSALS)
    cell = report["cell"]
    assert list(cell) == ["name", "file", "params", *shares, "refused", "stations"]
    assert (cell["name"], list(cell["stations"])) == ("reference", ["panda"])
    assert Path(cell["params"]).name == "default.yaml"
    station = cell["stations"]["panda"]
    assert list(station) == ["tool", "robot", "share", "takes", "by_class", "refused"]
    assert cell["share"] == report["tools"]["panda_hand"]["share"]
    mix = report["mix"]
    assert list(mix) == ["stations", "method", "share", "tools"]
    assert (mix["stations"], len(mix["tools"])) == (1, 1)
    assert list(mix["tools"][0]) == ["tool", "robot", "stations", "adds", "load"]

    assert main(["fit", str(builtin_sample), "--stations", "3"]) == 0
    text = capsys.readouterr().out
    assert all(word in text for word in ("suction_cup_25", "any station", "3 stations"))


def test_cli_refuses_a_folder_that_is_no_meshgen_output_and_an_unknown_cell(
    tmp_path: Path, builtin_sample: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "index.csv").write_text("a,b\n", encoding="utf-8")
    for folder in (tmp_path, tmp_path / "missing"):
        assert main(["fit", str(folder)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1, err
        assert str(folder) in err
    assert main(["fit", str(builtin_sample), "--cell", "nowhere"]) == 2
    assert "no shipped cell" in capsys.readouterr().err
    assert main(["fit", str(builtin_sample), "--controller", "nothing"]) == 2
    assert "--controller 'nothing'" in capsys.readouterr().err


@pytest.mark.skipif(not REAL_SAMPLE.is_dir(), reason="needs ../shared/datasets/cdw_stacked_sample")
def test_real_sample_line_takes_more_than_its_cups(tmp_path: Path) -> None:
    out = tmp_path / "real_meshes"
    mesh_dataset(REAL_SAMPLE, out, MeshgenConfig(textures=False))
    report = fit_dataset(out)
    tools, cell = report["tools"], report["cell"]
    assert all(0.0 < t["share"] <= 1.0 for t in tools.values())
    assert cell["share"] > max(tools["suction_cup"]["share"], tools["suction_cup_25"]["share"])
    assert tools["suction_cup"]["refused"]["too_small"] > 0
    assert tools["wide_gripper"]["refused"]["too_flat"] > 0
    assert not math.isnan(report["mix"]["share"])


def test_station_setup_is_the_controllers_configuration() -> None:
    setup: StationSetup = cell_setups(load_cell("line"), default_params(Path("line.yaml")))[3]
    assert (setup.name, setup.tool, setup.robot) == ("s4", "suction_cup_25", "ur10")
    assert setup.config.station.name == "s4"
    assert setup.config.scheduler.check_mass  # line.yaml: the cell's class table's densities
    assert setup.config.cell.materials.material("concrete").density_kg_m3 == 2400.0
