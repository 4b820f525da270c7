"""The colour classifier: separates classes by colour and texture, round-trips through its file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from detector.classifier import ColourClassifier, fit_classifier
from detector.detector import Detector
from detector.errors import DetectorConfigError, ModelFileError
from detector.features import FEATURE_NAMES, instance_features, srgb_to_lab
from detector.synthetic import Piece, render, scatter

CLASSES = {(150, 150, 145): "concrete", (175, 80, 50): "brick", (190, 150, 105): "wood"}


def _samples(seed: int) -> tuple[np.ndarray, list[str]]:
    pieces = scatter(30, seed=seed)
    frame = render(pieces, seed=seed)
    assert frame.instance_ids is not None
    features = instance_features(frame.rgb, frame.instance_ids, 2)
    return features, [CLASSES[p.rgb] for p in pieces]


def test_lab_of_known_colours() -> None:
    lab = srgb_to_lab(np.array([[255, 255, 255], [0, 0, 0], [255, 0, 0]], dtype=np.uint8))
    np.testing.assert_allclose(lab[0], [100.0, 0.0, 0.0], atol=0.05)
    np.testing.assert_allclose(lab[1], [0.0, 0.0, 0.0], atol=0.05)
    np.testing.assert_allclose(lab[2], [53.24, 80.09, 67.20], atol=0.1)


def test_the_classifier_separates_synthetic_classes_on_unseen_frames() -> None:
    train_x, train_y = _samples(seed=10)
    model = fit_classifier(train_x, train_y, class_names=["brick", "concrete", "wood", "rubber"])
    test_x, test_y = _samples(seed=11)
    names, probs = model.predict(test_x)
    assert names == test_y
    assert (probs > 0.5).all()
    assert model.probabilities(test_x)[:, 3].max() < 0.01  # no rubber sample: never rubber


def test_the_fit_is_deterministic_and_round_trips_through_its_file(tmp_path: Path) -> None:
    x, y = _samples(seed=12)
    model = fit_classifier(x, y, training={"photos": ["a", "b"]})
    again = fit_classifier(x, y, training={"photos": ["a", "b"]})
    np.testing.assert_array_equal(model.weights, again.weights)
    path = tmp_path / "model.json"
    model.save(path)
    loaded = ColourClassifier.load(path)
    assert loaded.class_names == model.class_names == ("brick", "concrete", "wood")
    assert loaded.training["photos"] == ["a", "b"]
    np.testing.assert_allclose(loaded.probabilities(x), model.probabilities(x), atol=1e-12)


def test_a_detector_with_the_classifier_names_each_piece() -> None:
    x, y = _samples(seed=13)
    model = fit_classifier(x, y)
    pieces = [
        Piece(x_m=-0.2, y_m=0.0, yaw_rad=0.0, length_m=0.1, width_m=0.05, height_m=0.03, rgb=rgb)
        for rgb in CLASSES
    ]
    pieces = [
        Piece(
            x_m=-0.25 + 0.25 * i,
            y_m=0.1,
            yaw_rad=0.3,
            length_m=0.1,
            width_m=0.05,
            height_m=0.03,
            rgb=p.rgb,
        )
        for i, p in enumerate(pieces)
    ]
    frame = render(pieces, seed=14)
    output = Detector(classifier=model).detect(frame)
    assert frame.instance_ids is not None
    for inst in output.instances:
        piece = int(np.bincount(frame.instance_ids[output.labels == inst.label]).argmax())
        assert inst.class_name == CLASSES[pieces[piece - 1].rgb]
        assert inst.detection is not None
        assert inst.detection.confidence == inst.score > 0.5


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda d: d.update(format="other"), "not a classifier file"),
        (lambda d: d.update(version=99), "version"),
        (lambda d: d.update(class_names=["a", "a"]), "class_names"),
        (lambda d: d.update(weights=[[1.0]]), "weights"),
        (lambda d: d.update(scale=[0.0] * len(FEATURE_NAMES)), "scale"),
        (lambda d: d.update(feature_names=["x"]), "feature_names"),
    ],
)
def test_a_broken_classifier_file_is_refused_naming_the_field(
    tmp_path: Path, edit: object, match: str
) -> None:
    x, y = _samples(seed=15)
    data = fit_classifier(x, y).to_data()
    edit(data)  # type: ignore[operator]
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data), encoding="utf-8")
    with pytest.raises(ModelFileError, match=match):
        ColourClassifier.load(path)


def test_bad_training_data_is_refused() -> None:
    x, y = _samples(seed=16)
    with pytest.raises(DetectorConfigError, match="not among class_names"):
        fit_classifier(x, y, class_names=["brick"])
    with pytest.raises(DetectorConfigError, match="features"):
        fit_classifier(x[:, :3], y)
