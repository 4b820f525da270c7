"""``cdw-twin photo``: the render of a photo's pieces lies where the pieces lie in the photo,
turned as the photo is (geometry, not bytes: pixels differ between Mesa versions)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from experiments.photo_render import GAP_PX, PhotoError, photo_and_render
from twin.cli import main


def _pieces_mask(rgb: np.ndarray) -> np.ndarray:
    """Pixels brighter than the dark belt (the sample's pieces are lighter; rubber is not)."""
    return np.asarray(rgb, dtype=float).max(axis=2) > 80


def test_the_render_covers_the_pieces_of_its_photo(builtin_meshes: Path, tmp_path: Path) -> None:
    folder = max(
        (p.parent for p in builtin_meshes.glob("*/scene.json")),
        key=lambda p: len(json.loads((p / "scene.json").read_text(encoding="utf-8"))["objects"]),
    )
    out = tmp_path / "pair.png"
    assert main(["photo", str(builtin_meshes), "--image", folder.name, "--out", str(out)]) == 0
    pair = np.asarray(Image.open(out).convert("RGB"))
    scene = json.loads((folder / "scene.json").read_text(encoding="utf-8"))
    height, width = int(scene["height_px"]), int(scene["width_px"])
    assert pair.shape[0] == height
    photo = pair[:, :width]
    render = np.asarray(
        Image.fromarray(pair[:, width + GAP_PX :]).resize((width, height), Image.Resampling.NEAREST)
    )
    seen, drawn = _pieces_mask(photo), _pieces_mask(render)
    iou = (seen & drawn).sum() / (seen | drawn).sum()
    assert seen.sum() > 0.02 * seen.size  # the photo shows pieces to compare
    assert iou > 0.6  # a turned or shifted render overlaps far less


def test_a_folder_that_is_not_meshgens_is_named(tmp_path: Path) -> None:
    with pytest.raises(PhotoError, match=r"no scene\.json"):
        photo_and_render(tmp_path)
