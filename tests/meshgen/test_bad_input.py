"""Malformed annotations: each bad object or file is skipped with file, line and reason."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest

from meshgen.annotations import SKIP_REASONS
from meshgen.config import MeshgenConfig
from meshgen.pipeline import mesh_dataset
from meshgen.sample import png_bytes
from twin.cli import main

GOOD = "0 0.40 0.40 0.60 0.40 0.60 0.60 0.40 0.60"


def _yolo(root: Path, labels: dict[str, str], images: tuple[str, ...] = ()) -> Path:
    (root / "labels").mkdir(parents=True)
    (root / "images").mkdir()
    (root / "data.yaml").write_text("names: [concrete, brick, wood, rubber, plaster]\n")
    for stem, text in labels.items():
        (root / "labels" / f"{stem}.txt").write_bytes(text.encode("latin-1"))
    for stem in images:
        (root / "images" / f"{stem}.png").write_bytes(png_bytes(200, 100))
    return root


BAD_LINES = {
    "odd_coordinates": "0 0.4 0.4 0.6 0.4 0.6",
    "not_a_number": "0 0.4 0.4 0.6 zero 0.6 0.6",
    "bad_class_id": "x 0.4 0.4 0.6 0.4 0.6 0.6",
    "unknown_class_id": "9 0.4 0.4 0.6 0.4 0.6 0.6",
    "too_few_points": "0 0.4 0.4 0.6 0.4",
    "out_of_range": "0 0.4 0.4 3.6 0.4 0.6 0.6",
    "border_truncated": "0 0.0 0.4 0.6 0.4 0.6 0.6",
    "degenerate": "0 0.4 0.4 0.5 0.5 0.6 0.6",
    "below_min_area": "0 0.50 0.50 0.501 0.50 0.501 0.501",
}


def test_each_bad_line_is_skipped_and_good_lines_kept(tmp_path: Path) -> None:
    text = "\n".join([GOOD, *BAD_LINES.values(), GOOD]) + "\n"
    data = _yolo(tmp_path / "data", {"img": text}, images=("img",))
    summary = mesh_dataset(data, tmp_path / "out", MeshgenConfig())
    assert summary.objects == 2
    assert summary.skipped == dict(sorted(dict.fromkeys(BAD_LINES, 1).items()))
    by_reason = {s.reason: s for s in summary.skips}
    for lineno, reason in enumerate(BAD_LINES, start=2):
        skip = by_reason[reason]
        assert skip.file == "labels/img.txt"
        assert skip.where == f"line {lineno}"
        assert reason in SKIP_REASONS
        assert "labels/img.txt:line" in skip.message()
    ids = (tmp_path / "out" / "img" / "scene.csv").read_text()
    assert "img_000" in ids
    assert f"img_{len(BAD_LINES) + 1:03d}" in ids


def test_a_class_the_table_does_not_name_is_meshed_with_its_default_and_warned(
    tmp_path: Path,
) -> None:
    """``plaster`` (class 4 of data.yaml) is in no class table: its piece takes the shipped
    default's density and height range, is listed after the table's classes in the output's
    ``classes.yaml``, and a ``default_material`` warning names the class once."""
    from interfaces.materials import dataset_table, shipped_table

    text = f"{GOOD}\n4 0.30 0.30 0.50 0.30 0.50 0.50 0.30 0.50\n"
    data = _yolo(tmp_path / "data", {"img": text}, images=("img",))
    summary = mesh_dataset(data, tmp_path / "out", MeshgenConfig())
    assert summary.objects == 2
    assert summary.skipped == {}
    (notice,) = summary.notices
    assert (notice.reason, notice.file) == ("default_material", "class 'plaster'")
    default = shipped_table().default
    with (tmp_path / "out" / "img" / "scene.csv").open(encoding="utf-8") as handle:
        rows = {r["class_name"]: r for r in csv.DictReader(handle)}
    plaster = rows["plaster"]
    assert plaster["class_id"] == "-1"
    assert default.height_min_m <= float(plaster["height_m"]) <= default.height_max_m
    assert float(plaster["mass_kg"]) == pytest.approx(
        default.density_kg_m3 * float(plaster["volume_m3"]), rel=1e-6
    )
    table = dataset_table(tmp_path / "out")
    assert table.names == ("concrete", "plaster")
    assert table.material("plaster").density_kg_m3 == default.density_kg_m3


def test_bad_files_are_reported_and_others_go_on(tmp_path: Path) -> None:
    labels = {"empty": "", "binary": "\xff\xfe\x00garbage", "nosize": GOOD, "ok": GOOD}
    data = _yolo(tmp_path / "data", labels, images=("empty", "binary", "ok"))
    summary = mesh_dataset(data, tmp_path / "out", MeshgenConfig())
    assert summary.images == 1
    assert summary.objects == 1
    assert summary.skipped == {"empty_file": 1, "missing_image_size": 1, "unreadable_file": 1}
    # --image-size supplies the missing size
    sized = mesh_dataset(data, tmp_path / "out2", MeshgenConfig(image_size_px=(200, 100)))
    assert sized.objects == 2


def test_labelme_bad_shapes(tmp_path: Path) -> None:
    data = tmp_path / "data"
    data.mkdir()
    shapes = [
        {
            "label": "brick",
            "points": [[80, 40], [120, 40], [120, 60], [80, 60]],
            "shape_type": "polygon",
        },
        {"label": "brick", "points": [[80, 40], [120, "a"], [120, 60]], "shape_type": "polygon"},
        {"label": "brick", "points": [[80, 40], [120]], "shape_type": "polygon"},
        {"label": "brick", "points": [[1, 1], [5, 5]], "shape_type": "rectangle"},
        {"label": "plaster", "points": [[80, 40], [120, 40], [120, 60]], "shape_type": "polygon"},
    ]
    doc = {"shapes": shapes, "imageWidth": 200, "imageHeight": 100, "imagePath": "x.png"}
    (data / "a.json").write_text(json.dumps(doc))
    (data / "b.json").write_text('{"shapes": [')
    del doc["imageWidth"]
    (data / "c.json").write_text(json.dumps(doc))
    summary = mesh_dataset(data, tmp_path / "out", MeshgenConfig(fmt="labelme"))
    assert summary.objects == 2  # the brick and the plaster (the table's default)
    assert summary.skipped == {
        "missing_image_size": 1,
        "not_a_number": 1,
        "not_a_polygon": 1,
        "odd_coordinates": 1,
        "unreadable_file": 1,
    }
    assert summary.warned["default_material"] == 1


def test_exit_status(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = _yolo(tmp_path / "good", {"img": GOOD + "\n"}, images=("img",))
    mixed = _yolo(tmp_path / "mixed", {"img": GOOD + "\n9 0 0\n"}, images=("img",))
    bad = _yolo(tmp_path / "bad", {"img": "9 0 0\n"}, images=("img",))
    assert main(["meshgen", str(good), "--out", str(tmp_path / "o1")]) == 0
    assert main(["meshgen", str(mixed), "--out", str(tmp_path / "o2")]) == 0
    assert main(["meshgen", str(mixed), "--out", str(tmp_path / "o3"), "--strict"]) == 1
    assert main(["meshgen", str(bad), "--out", str(tmp_path / "o4"), "--json"]) == 1
    captured = capsys.readouterr()
    summary = json.loads(captured.out.strip().splitlines()[-1])
    assert summary["objects"] == 0
    assert summary["skipped"] == {"unknown_class_id": 1}
    assert "labels/img.txt:line 1: skipped (unknown_class_id)" in captured.err
    assert main(["meshgen", str(tmp_path / "missing"), "--out", str(tmp_path / "o5")]) == 2


COLLINEAR_PX = [
    [[296.1, 134.3], [318.1, 113.3], [384.1, 50.3]],
    [[186.1, 57.3], [213.1, 77.3], [294.1, 137.3]],
    [[149.1, 247.3], [89.1, 190.3], [129.1, 228.3]],
    [[187.1, 188.3], [168.1, 208.3], [130.1, 248.3]],
    [[300.0, 700.0], [350.0, 750.0], [400.0, 800.0], [350.0, 750.0]],
]
"""Collinear in pixels; in metres some are not quite (shoelace area 0 or ~1e-20 m^2)."""
BOW_TIES_PX = [
    ([[100.0, 500.0], [200.0, 600.0], [200.0, 500.0], [100.0, 600.0]], 0.5),
    ([[500.0, 500.0], [600.0, 600.0], [600.0, 500.0], [500.0, 600.0000001]], 0.5),
    ([[700.0, 700.0], [900.0, 800.0], [900.0, 700.0], [700.0, 750.0]], 0.8),
]
"""Self-intersecting outlines and the share of the enclosed area their largest loop holds."""


def _degenerate_labelme(root: Path) -> Path:
    shapes = [{"label": "brick", "points": pts} for pts in COLLINEAR_PX]
    shapes += [{"label": "brick", "points": pts} for pts, _ in BOW_TIES_PX]
    root.mkdir()
    doc = {"shapes": shapes, "imageWidth": 1000, "imageHeight": 1000}
    (root / "img.json").write_text(json.dumps(doc))
    return root


def test_degenerate_outlines_are_skipped_and_bow_ties_get_a_meaningful_ratio(
    tmp_path: Path,
) -> None:
    data = _degenerate_labelme(tmp_path / "data")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        summary = mesh_dataset(data, tmp_path / "out", MeshgenConfig())
    assert summary.skipped == {"degenerate": len(COLLINEAR_PX)}
    assert [s.where for s in summary.skips] == [f"shape {i}" for i in range(len(COLLINEAR_PX))]
    scene = json.loads((tmp_path / "out" / "img" / "scene.json").read_text())
    assert len(scene["objects"]) == len(BOW_TIES_PX)
    with (tmp_path / "out" / "img" / "scene.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    for obj, row, (_, expected) in zip(scene["objects"], rows, BOW_TIES_PX, strict=True):
        (entry,) = [r for r in obj["repairs"] if r.startswith("self_intersection_repaired")]
        assert entry in row["repairs"].split(";")
        ratio = float(entry.split("kept_area_ratio=")[1])
        assert ratio == pytest.approx(expected, abs=1e-3)


def _overflowing_yolo(root: Path) -> Path:
    text = "0 1e308 0.4 0.6 0.4 0.6 0.6\n0 0.4 -1e300 0.6 0.4 0.6 0.6\n" + GOOD + "\n"
    return _yolo(root, {"img": text}, images=("img",))


@pytest.mark.parametrize("make", [_degenerate_labelme, _overflowing_yolo])
def test_no_runtime_warning_reaches_the_terminal(
    tmp_path: Path, make: Callable[[Path], Path]
) -> None:
    data = make(tmp_path / "data")
    command = [sys.executable, "-m", "twin.cli", "meshgen", str(data), "--out", str(tmp_path / "o")]
    done = subprocess.run(command, capture_output=True, text=True, check=False, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "Warning" not in done.stderr
    assert all(line.startswith("warning: ") for line in done.stderr.splitlines())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        summary = mesh_dataset(data, tmp_path / "o2", MeshgenConfig())
    if make is _overflowing_yolo:
        assert summary.skipped == {"out_of_range": 2}
        assert summary.objects == 1
