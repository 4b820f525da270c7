"""A dataset with its own class names runs the default scenario and the line with no file
edited: ``cdw-twin meshgen DATA --out M --classes C.yaml``, then ``cdw-twin run --dataset M``
and ``cdw-twin run experiments/scenarios/line.yaml --dataset M`` (in process, a few seconds
each). The shipped cells' bin slots take ``bricks``, ``concrete`` and ``tiles`` in the class
table's order, the pieces go into their own class's bins, the run's resolved cell carries the
class table (the controllers' densities, the player's colours), and every spawned piece says
whether some station could take it."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from typing import Any

import pytest
from twin_helpers import box_px

from twin.cli import main

ROOT = Path(__file__).resolve().parents[2]
NAMES = ("bricks", "concrete", "tiles")
CLASS_TABLE = """\
classes:
  bricks:   {density_kg_m3: 1900, height_min_m: 0.04, height_max_m: 0.05}
  concrete: {density_kg_m3: 2400, height_min_m: 0.04, height_max_m: 0.05}
  tiles:    {density_kg_m3: 2300, height_min_m: 0.025, height_max_m: 0.03, rgb: [0.2, 0.4, 0.9]}
"""
DEFAULT_SLOTS_X_M = (-0.60, -0.33, 0.33)
"""The reference cell's first three bin slots along x (interfaces/cells/default.yaml)."""


def _needs_ros() -> None:
    for module in ("rclpy", "cdw_interfaces"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed in this venv")


def _json(path: Path) -> Any:
    return json.loads(path.read_text(encoding="utf-8"))


def _events(episode: Path) -> list[dict[str, Any]]:
    text = (episode / "twin" / "events.jsonl").read_text(encoding="utf-8")
    return [json.loads(line) for line in text.splitlines()]


@pytest.fixture(scope="module")
def meshes(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Six 1000 x 1000 px images (0.6 mm per pixel) of three 9 x 6 cm pieces each, one per
    class, meshed through the command line with the class table: pieces the Panda's hand,
    every cup and the wide grippers can take."""
    root = tmp_path_factory.mktemp("any_dataset")
    data = root / "data"
    (data / "labels").mkdir(parents=True)
    listed = "".join(f"  {i}: {name}\n" for i, name in enumerate(NAMES))
    (data / "data.yaml").write_text(f"names:\n{listed}", encoding="utf-8")
    for image in range(6):
        lines = []
        for cls in range(3):
            points = box_px(250 + 250 * cls, 300 + 60 * image, 150, 100)
            lines.append(f"{cls} " + " ".join(f"{u / 1000:.6f} {v / 1000:.6f}" for u, v in points))
        (data / "labels" / f"img{image}.txt").write_text("\n".join(lines) + "\n", "utf-8")
    table = root / "classes.yaml"
    table.write_text(CLASS_TABLE, encoding="utf-8")
    out = root / "meshes"
    args = ["meshgen", str(data), "--out", str(out), "--image-size", "1000x1000"]
    assert main([*args, "--classes", str(table)]) == 0
    return out


def test_meshgen_records_the_class_table_and_its_masses_and_colours_follow_it(
    meshes: Path,
) -> None:
    from interfaces.class_colours import dataset_class_rgb
    from interfaces.materials import dataset_table
    from twin.objects import load_dataset

    table = dataset_table(meshes)
    assert table.names == NAMES
    assert dataset_class_rgb(meshes)["tiles"] == (0.2, 0.4, 0.9)
    for spec in (o for layout in load_dataset(meshes) for o in layout.objects):
        material = table.material(spec.class_name)
        assert material.height_min_m <= spec.height_m <= material.height_max_m
        assert spec.mass_kg == pytest.approx(material.density_kg_m3 * spec.volume_m3, rel=1e-6)


def _run(out: Path, *args: str) -> Path:
    code = main(["run", *args, "--transport", "inproc", "--no-record", "--out", str(out)])
    assert code == 0
    return out


def _check_sorted(episode: Path) -> list[dict[str, Any]]:
    """Every piece a tool let go into a bin went into its own class's bin, and some did."""
    events = _events(episode)
    spawned = [e for e in events if e["type"] == "spawned"]
    assert {e["class_name"] for e in spawned} == set(NAMES)
    assert all(isinstance(e["data"]["takeable"], bool) for e in spawned)
    picked = {e["object_id"] for e in events if e["type"] == "pick_success"}
    placed = [e for e in events if e["type"] == "placed_in_bin" and e["object_id"] in picked]
    assert placed, f"nothing sorted in {episode}"
    for event in placed:
        assert event["data"]["bin"] == event["class_name"], event
        assert event["data"]["correct"] is True
    return events


def test_the_default_scenario_runs_on_it_and_sorts_into_the_slots(
    meshes: Path, tmp_path: Path
) -> None:
    _needs_ros()
    from experiments.player import player_data
    from interfaces.cell import load_cell
    from interfaces.class_colours import rgb_hex

    out = _run(tmp_path / "default", "--dataset", str(meshes), "--duration", "14", "--seed", "1")
    cell = load_cell(out / "cell.yaml")
    bins = [(b.class_name, b.centre_x_m) for b in cell.stations[0].bins]
    assert bins == list(zip(NAMES, DEFAULT_SLOTS_X_M, strict=True))
    assert cell.materials.material("tiles").density_kg_m3 == 2300.0
    events = _check_sorted(out / "ep000")
    placed = {e["data"]["bin"] for e in events if e["type"] == "placed_in_bin"}
    assert placed <= set(NAMES)
    data, _ = player_data(out / "ep000")
    assert data["classes"]["tiles"] == rgb_hex((0.2, 0.4, 0.9))
    row = _json(out / "episodes.json")[0]
    assert 0.0 <= row["recovery_takeable"] <= 1.0
    assert row["entered_takeable"] <= row["entered"]


def test_the_line_runs_on_it_and_its_controllers_take_the_tables_densities(
    meshes: Path, tmp_path: Path
) -> None:
    _needs_ros()
    from control.config import station_configs
    from control.scheduler import class_density_kg_m3
    from interfaces.cell import load_cell

    line = str(ROOT / "experiments" / "scenarios" / "line.yaml")
    out = _run(tmp_path / "line", line, "--dataset", str(meshes), "--duration", "10")
    cell = load_cell(out / "cell.yaml")
    assert len(cell.stations) == 8
    for station in cell.stations:
        assert tuple(b.class_name for b in station.bins) == NAMES
    configs = station_configs(out / "controller.yaml", cell)
    assert all(class_density_kg_m3("tiles", c) == 2300.0 for c in configs)
    _check_sorted(out / "ep000")
    run = _json(out / "run.json")
    assert set(run["mean_by_class"]) <= set(NAMES)
