"""The sample and meshgen commands, the class table and the benchmark command."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from interfaces.materials import dataset_table
from meshgen.classes import DEFAULT_CLASSES, load_class_table
from meshgen.config import MeshgenConfig
from meshgen.errors import ClassTableError, MeshgenError
from twin.cli import main


def test_sample_then_meshgen_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sample", "--out", str(tmp_path / "s"), "--images", "20", "--seed", "1"]) == 0
    assert len(list((tmp_path / "s" / "labels").glob("*.txt"))) == 20
    capsys.readouterr()
    assert main(["meshgen", str(tmp_path / "s"), "--out", str(tmp_path / "o"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("images", "objects", "skipped", "ms_per_image", "ms_per_object", "out"):
        assert key in out
    assert out["images"] == 20
    assert out["skipped"].get("border_truncated", 0) >= 5


def test_class_table_override(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sample", "--out", str(tmp_path / "s"), "--images", "2"]) == 0
    table = tmp_path / "classes.yaml"
    table.write_text(
        "classes:\n"
        "  concrete: {density_kg_m3: 1000, height_min_m: 0.05, height_max_m: 0.05}\n"
        "  brick: {density_kg_m3: 1000, height_min_m: 0.05, height_max_m: 0.05}\n"
    )
    capsys.readouterr()
    code = main(
        [
            "meshgen",
            str(tmp_path / "s"),
            "--out",
            str(tmp_path / "o"),
            "--json",
            "--classes",
            str(table),
        ]
    )
    summary = json.loads(capsys.readouterr().out)
    assert code == 0
    overridden = 0
    for scene in (tmp_path / "o").glob("*/scene.json"):
        for obj in json.loads(scene.read_text())["objects"]:
            shipped = DEFAULT_CLASSES[obj["class_name"]]
            if obj["class_name"] in {"concrete", "brick"}:  # the table's own entries
                overridden += 1
                assert obj["height_m"] == pytest.approx(0.05)
                assert obj["mass_kg"] == pytest.approx(1000 * 0.05 * obj["area_m2"])
            else:  # wood and rubber: the shipped table's, under the given one
                assert shipped.height_min_m <= obj["height_m"] <= shipped.height_max_m
                assert obj["mass_kg"] == pytest.approx(
                    shipped.density_kg_m3 * obj["height_m"] * obj["area_m2"]
                )
    assert overridden >= 1
    recorded = dataset_table(tmp_path / "o")  # classes.yaml: the classes meshed, in order
    assert recorded.names[:2] == ("concrete", "brick")
    assert recorded.material("concrete").density_kg_m3 == 1000
    assert recorded.material("wood") == DEFAULT_CLASSES["wood"]
    assert set(recorded.names) == set(summary["classes"])


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("classes: [1, 2]", "top-level mapping"),
        ("classes:\n  x: {density_kg_m3: -1, height_min_m: 0.1, height_max_m: 0.2}", "must be > 0"),
        ("classes:\n  x: {density_kg_m3: 1, height_min_m: 0.3, height_max_m: 0.2}", "height_min_m"),
        ("classes:\n  x: {density_kg_m3: 1, height_min_m: 0.1}", "missing field 'height_max_m'"),
        (
            "classes:\n  x: {density_kg_m3: abc, height_min_m: 0.1, height_max_m: 0.2}",
            "expected a number",
        ),
        ("classes: {x: [", "not valid YAML"),
    ],
)
def test_bad_class_tables(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ClassTableError, match=match):
        load_class_table(path)


def test_default_table() -> None:
    assert list(DEFAULT_CLASSES) == ["concrete", "brick", "wood", "rubber"]
    assert DEFAULT_CLASSES["concrete"].density_kg_m3 == 2400
    assert DEFAULT_CLASSES["rubber"].height_min_m == 0.005


def test_bench_prints_figures(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sample", "--out", str(tmp_path / "s"), "--images", "2"]) == 0
    capsys.readouterr()
    assert (
        main(
            [
                "bench",
                "meshgen",
                str(tmp_path / "s"),
                "--json",
                "--repeats",
                "1",
                "--tmp-dir",
                str(tmp_path),
            ]
        )
        == 0
    )
    result = json.loads(capsys.readouterr().out)
    for key in (
        "ms_per_image",
        "ms_per_object",
        "baseline_ms_per_image",
        "baseline_ms_per_object",
        "speedup",
        "images",
        "objects",
        "repeats",
    ):
        assert key in result
    assert result["images"] == 2


def test_bench_measures_in_ram_and_on_disk_by_default(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from meshgen.cmd_bench import _ram_dir

    assert main(["sample", "--out", str(tmp_path / "s"), "--images", "2"]) == 0
    capsys.readouterr()
    assert main(["bench", "meshgen", str(tmp_path / "s"), "--json", "--repeats", "1"]) == 0
    result = json.loads(capsys.readouterr().out)
    ram = _ram_dir()
    if ram is None:
        assert "disk" not in result
        return
    assert result["tmp_dir"] == str(ram)
    assert result["file_system"] == "tmpfs"
    disk = result["disk"]
    assert disk["tmp_dir"] != str(ram)
    assert disk["ms_per_object"] > 0
    assert disk["baseline_ms_per_object"] > 0
    assert disk["file_create_us"] > 0


@pytest.mark.parametrize("width", ["inf", "-inf", "nan", "0", "-0.6", "1e200", "1e-300"])
def test_unusable_belt_width_is_refused(
    tmp_path: Path, width: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["sample", "--out", str(tmp_path / "s"), "--images", "2"]) == 0
    capsys.readouterr()
    out = tmp_path / "o"
    assert main(["meshgen", str(tmp_path / "s"), "--out", str(out), f"--belt-width={width}"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("cdw-twin: error: --belt-width must be")
    assert len(err.splitlines()) == 1
    assert not out.exists()
    with pytest.raises(MeshgenError, match="--belt-width"):
        MeshgenConfig(belt_width_m=float(width))


@pytest.mark.parametrize("option", ["simplify_mm", "border_margin_px", "min_area_mm2"])
def test_infinite_options_are_refused(option: str) -> None:
    with pytest.raises(MeshgenError, match="must be finite"):
        MeshgenConfig(**{option: math.inf})
