"""The detector's confidence: lower on misclassified detections, from its own random stream."""

from __future__ import annotations

import numpy as np
import pytest

from twin.errors import ConfigError
from twin.ground_truth import GroundTruth
from twin.perception import Perception
from twin.perception_config import PerceptionConfig
from twin.top_view import TopView

CLASSES = ("concrete", "brick", "wood", "rubber")


def _object(i: int, x: float) -> GroundTruth:
    return GroundTruth(
        id=i,
        source_id=f"o{i}",
        class_name=CLASSES[i % 4],
        position_m=(x, 0.5, 0.03),
        orientation_xyzw=(0.0, 0.0, 0.0, 1.0),
        linear_velocity_mps=(0.4, 0.0, 0.0),
        angular_velocity_radps=(0.0, 0.0, 0.0),
        top_view=TopView(yaw_rad=0.3, length_m=0.1, width_m=0.05, height_m=0.04, below_m=0.02),
        length_m=0.1,
        width_m=0.05,
        area_m2=0.005,
        volume_m3=0.0002,
        height_m=0.04,
        mass_kg=0.4,
        on_belt=True,
        in_workspace=False,
        held=False,
        in_bin=False,
    )


OBJECTS = [_object(i, -1.0 + 0.02 * i) for i in range(1, 41)]


def _confidences(cfg: PerceptionConfig, frames: int) -> tuple[list[float], list[float]]:
    """Confidences of correctly and wrongly classified detections over ``frames`` frames."""
    perception = Perception(cfg, CLASSES, 0.0, 1 / 240, np.random.default_rng(5))
    truth = {round(o.position_m[0], 6): o.class_name for o in OBJECTS}
    right: list[float] = []
    wrong: list[float] = []
    for k in range(frames):
        for det in perception.capture(k / 30, OBJECTS).detections:
            (right if truth[round(det.x_m, 6)] == det.class_name else wrong).append(det.confidence)
    return right, wrong


def test_misclassified_detections_are_less_confident_on_average() -> None:
    cfg = PerceptionConfig(misclassification_rate=0.2, position_noise_m=0.0, drop_rate=0.0)
    right, wrong = _confidences(cfg, 100)
    assert len(wrong) > 300
    assert all(0.0 <= c <= 1.0 for c in right + wrong)
    # Beta(18, 2) and Beta(11, 9): means 0.9 and 0.55, standard deviations 0.065 and 0.11
    assert np.mean(right) == pytest.approx(cfg.confidence_correct_mean, abs=0.01)
    assert np.mean(wrong) == pytest.approx(cfg.confidence_wrong_mean, abs=0.02)
    assert np.mean(wrong) < np.mean(right) - 0.3
    assert np.std(right) == pytest.approx(0.065, rel=0.15)


def test_zero_noise_perception_is_fully_confident() -> None:
    right, wrong = _confidences(PerceptionConfig.zero_noise(), 10)
    assert wrong == []
    assert set(right) == {1.0}


def test_confidences_leave_positions_drops_and_classes_as_the_seed_gave_them() -> None:
    """The confidence draws come from a child stream: the same seed gives the same detections
    (all but their confidence) whether confidences are modelled or fixed at 1."""
    noisy = PerceptionConfig(misclassification_rate=0.2, drop_rate=0.1)
    certain = PerceptionConfig(
        misclassification_rate=0.2,
        drop_rate=0.1,
        confidence_correct_mean=1.0,
        confidence_wrong_mean=1.0,
    )

    def frames(cfg: PerceptionConfig) -> list[list[tuple[str, float, float, float]]]:
        perception = Perception(cfg, CLASSES, 0.0, 1 / 240, np.random.default_rng(11))
        return [
            [
                (d.class_name, d.x_m, d.y_m, d.yaw_rad)
                for d in perception.capture(k / 30, OBJECTS).detections
            ]
            for k in range(30)
        ]

    assert frames(noisy) == frames(certain)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("confidence_correct_mean", 0.0),
        ("confidence_wrong_mean", 1.5),
        ("confidence_concentration", 0.0),
    ],
)
def test_bad_confidence_parameters_are_named(field: str, value: float) -> None:
    with pytest.raises(ConfigError, match=rf"perception\.{field} = {value!r}"):
        PerceptionConfig(**{field: value})  # type: ignore[arg-type]
