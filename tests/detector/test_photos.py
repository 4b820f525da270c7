"""Photo datasets: polygons rasterised as ground truth, the detector scored on them, and the
real photos of the shared sample (skipped when ../shared is absent)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageDraw

from detector.bench_photos import bench_photos, split_photos
from detector.cmd import main
from detector.errors import DatasetError
from detector.photos import rasterise, read_photo_dataset

SHARED_SAMPLE = Path(__file__).resolve().parents[3] / "shared" / "datasets" / "cdw_stacked_sample"
COLOURS = {"brick": (180, 80, 50), "concrete": (160, 160, 155), "wood": (190, 150, 100)}


def _dataset(root: Path, photos: int = 6) -> Path:
    """A YOLO dataset of dark photos with coloured quadrilaterals, their polygons, and a height
    image for every photo but the second."""
    rng = np.random.default_rng(0)
    names = list(COLOURS)
    (root / "images").mkdir(parents=True)
    (root / "labels").mkdir()
    (root / "heights").mkdir()
    (root / "data.yaml").write_text(
        "names:\n" + "".join(f"  {i}: {n}\n" for i, n in enumerate(names)), encoding="utf-8"
    )
    w, h = 400, 300
    for k in range(photos):
        image = Image.new("RGB", (w, h), (30, 30, 32))
        heights = Image.new("L", (w, h), 0)
        draw, draw_h = ImageDraw.Draw(image), ImageDraw.Draw(heights)
        lines = []
        for j in range(3):
            cls = (k + j) % 3
            cx, cy = 70 + 130 * j, 150 + 40 * (j % 2)
            a = rng.uniform(0, np.pi)
            corners = [
                (cx + dx * np.cos(a) - dy * np.sin(a), cy + dx * np.sin(a) + dy * np.cos(a))
                for dx, dy in ((-45, -20), (45, -20), (45, 20), (-45, 20))
            ]
            draw.polygon(corners, fill=COLOURS[names[cls]])
            draw_h.polygon(corners, fill=40 + 10 * j)
            lines.append(f"{cls} " + " ".join(f"{x / w:.6f} {y / h:.6f}" for x, y in corners))
        texture = np.where(np.asarray(heights)[..., None] > 0, 14.0, 4.0)  # pieces are rough
        noise = rng.normal(0, 1, (h, w, 1)) * texture
        pixels = np.clip(np.asarray(image, dtype=np.float64) + noise, 0, 255).astype(np.uint8)
        Image.fromarray(pixels).save(root / "images" / f"S_{k:02d}.png")
        (root / "labels" / f"S_{k:02d}.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")
        if k != 1:
            heights.save(root / "heights" / f"S_{k:02d}.png")
    return root


def test_polygons_rasterise_at_the_resized_scale() -> None:
    ids = rasterise([("a", np.array([[0.1, 0.2], [0.5, 0.2], [0.5, 0.6], [0.1, 0.6]]))], (100, 50))
    assert ids.shape == (50, 100)
    assert ids.max() == 1
    assert abs(int(ids.sum()) - 40 * 20) <= 40 + 20 + 1  # the outline pixels are drawn too


def test_a_synthetic_photo_dataset_is_detected_and_scored(tmp_path: Path) -> None:
    root = _dataset(tmp_path / "ds")
    data = read_photo_dataset(root)
    assert data.class_names == ("brick", "concrete", "wood")
    assert sum(p.heights is not None for p in data.photos) == 5
    train, test = split_photos(data.photos, seed=1, train_fraction=0.5)
    assert {p.stem for p in train}.isdisjoint({p.stem for p in test})
    assert len(train) == len(test) == 3
    result, classifier = bench_photos(data, seed=1)
    assert result["split"]["train"] == [p.stem for p in train]  # type: ignore[index]
    colour = result["modes"]["colour"]["all"]  # type: ignore[index]
    depth = result["modes"]["depth"]["all"]  # type: ignore[index]
    assert colour["recall"] == 1.0
    assert depth["recall"] == 1.0
    assert depth["class_accuracy"] == 1.0
    # colour-mode masks reach a pixel or two past the polygons: with nine training pieces the
    # belt's pixels in them may tip one class of three
    assert colour["class_accuracy"] >= 2 / 3
    assert classifier.class_names == data.class_names
    assert json.loads(json.dumps(result)) == result


def test_the_command_line_writes_its_results(tmp_path: Path) -> None:
    root = _dataset(tmp_path / "ds", photos=4)
    out, model = tmp_path / "result.json", tmp_path / "model.json"
    assert main(["photos", str(root), "--out", str(out), "--classifier-out", str(model)]) == 0
    assert json.loads(out.read_text(encoding="utf-8"))["photos"] == 4
    assert json.loads(model.read_text(encoding="utf-8"))["class_names"] == [
        "brick",
        "concrete",
        "wood",
    ]
    trained = tmp_path / "all.json"
    assert main(["train", str(root), "--out", str(trained)]) == 0
    assert len(json.loads(trained.read_text(encoding="utf-8"))["training"]["photos"]) == 4
    assert main(["photos", str(tmp_path / "nowhere")]) == 2


def test_a_bad_label_line_names_the_file_and_line(tmp_path: Path) -> None:
    root = _dataset(tmp_path / "ds", photos=1)
    (root / "labels" / "S_00.txt").write_text("0 0.1 0.1 0.2 0.2 0.3 0.1\n7 0.1 0.1 0.2\n")
    with pytest.raises(DatasetError, match=r"S_00\.txt:2"):
        read_photo_dataset(root)


@pytest.mark.skipif(
    not SHARED_SAMPLE.is_dir(), reason="needs ../shared/datasets/cdw_stacked_sample"
)
def test_the_real_photos_of_the_shared_sample() -> None:
    result, _ = bench_photos(SHARED_SAMPLE, seed=0, comparisons=False)
    modes = result["modes"]
    assert isinstance(modes, dict)
    colour, depth = modes["colour"], modes["depth"]
    assert colour["photos"] == 33  # half of each subset tests, the other half trains
    assert depth["photos"] == 10  # the test photos with a height image
    assert colour["all"]["recall"] >= 0.80
    assert depth["all"]["recall"] >= 0.80
    # class accuracy is reported whatever it is; it must at least beat chance (4 classes)
    assert colour["all"]["class_accuracy"] > 0.4
    assert "unassessed" in colour["all"]["precision_policy"]
