"""The scenario's perception settings: where detections come from and the oracle's error model.

A value type of its own (no behaviour beyond its checks) so the scenario, the twin and the
camera read it without importing the oracle (:mod:`twin.perception`) or each other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.errors import ConfigError

PERCEPTION_SOURCES = ("oracle", "camera")
"""``perception.source`` values: the ground-truth oracle or the rendered cameras."""


@dataclass(frozen=True)
class PerceptionConfig:
    """Camera rate and error model (its field of view is the cell's ``camera``).

    ``source`` says where the controllers' detections come from: ``oracle`` (the default: the
    ground truth through this error model, :class:`twin.perception.Perception`) or ``camera``
    (the cell's rendered RGB-D cameras, its ``cameras:`` list, through a detector:
    :mod:`twin.perception_source`, ``docs/camera.md``); the error-model fields apply to the
    oracle only, ``rate_hz`` and ``latency_s`` to both (every camera is rendered at ``rate_hz``
    and its merged detections released ``latency_s`` after the exposure).

    ``position_outlier_rate`` of the detections get their position noise from a wider Gaussian,
    ``position_outlier_noise_m`` (a detector's fragments and merges; 0: none, and no random
    number is drawn for it). ``fitted_from`` says where the error model's figures come from
    (``cdw-twin perception fit`` writes it; free text, empty for a hand-set model)."""

    source: str = "oracle"
    rate_hz: float = 30.0
    position_noise_m: float = 0.002
    yaw_noise_rad: float = 0.02
    latency_s: float = 0.03
    drop_rate: float = 0.02
    misclassification_rate: float = 0.01
    confidence_correct_mean: float = 0.9
    confidence_wrong_mean: float = 0.55
    confidence_concentration: float = 20.0
    position_outlier_rate: float = 0.0
    position_outlier_noise_m: float = 0.0
    fitted_from: str = ""

    def __post_init__(self) -> None:
        if self.source not in PERCEPTION_SOURCES:
            msg = f"perception.source = {self.source!r}: expected one of {PERCEPTION_SOURCES}"
            raise ConfigError(msg)
        checks = (
            ("confidence_correct_mean", 0 < self.confidence_correct_mean <= 1),
            ("confidence_wrong_mean", 0 < self.confidence_wrong_mean <= 1),
            ("confidence_concentration", self.confidence_concentration > 0),
            ("rate_hz", self.rate_hz > 0),
            ("position_noise_m", self.position_noise_m >= 0),
            ("yaw_noise_rad", self.yaw_noise_rad >= 0),
            ("latency_s", self.latency_s >= 0),
            ("drop_rate", 0 <= self.drop_rate < 1),
            ("misclassification_rate", 0 <= self.misclassification_rate <= 1),
            ("position_outlier_rate", 0 <= self.position_outlier_rate <= 1),
            ("position_outlier_noise_m", self.position_outlier_noise_m >= 0),
        )
        for name, ok in checks:
            if not ok:
                msg = f"perception.{name} = {getattr(self, name)!r} is out of range"
                raise ConfigError(msg)

    @classmethod
    def zero_noise(cls) -> PerceptionConfig:
        """Exact ground truth, no latency, no drops, no confusion; confidence 1."""
        return cls(
            position_noise_m=0.0,
            yaw_noise_rad=0.0,
            latency_s=0.0,
            drop_rate=0.0,
            misclassification_rate=0.0,
            confidence_correct_mean=1.0,
            confidence_wrong_mean=1.0,
        )

    def draw_confidence(self, rng: np.random.Generator, *, correct: bool) -> float:
        """A detection's confidence: Beta with the mean of a correct or a wrong class."""
        mean = self.confidence_correct_mean if correct else self.confidence_wrong_mean
        if mean >= 1.0:
            return 1.0
        k = self.confidence_concentration
        return float(rng.beta(k * mean, k * (1.0 - mean)))
