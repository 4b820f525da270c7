"""The oracle's error model fitted to detection errors: matching, the mixture fit, and the fit
recovering the parameters of an oracle whose model is known (its outliers included)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from interfaces.detections import Detection
from twin.ground_truth import GroundTruth
from twin.oracle_fit import (
    FitSample,
    TruthPiece,
    fit_oracle,
    fit_position_mixture,
    match_frame,
)
from twin.perception import Perception
from twin.perception_config import PerceptionConfig
from twin.top_view import TopView

CLASSES = ("concrete", "brick", "wood", "rubber")


def _detection(x_m: float, y_m: float, name: str = "brick", yaw_rad: float = 0.0) -> Detection:
    return Detection(
        class_name=name,
        confidence=0.9,
        x_m=x_m,
        y_m=y_m,
        z_m=0.0,
        yaw_rad=yaw_rad,
        length_m=0.1,
        width_m=0.05,
        height_m=0.03,
    )


def _piece(i: int, x_m: float, y_m: float) -> TruthPiece:
    return TruthPiece(
        object_id=i,
        class_name=CLASSES[i % 4],
        x_m=x_m,
        y_m=y_m,
        yaw_rad=0.3,
        length_m=0.1,
        width_m=0.05,
    )


def test_a_frame_is_matched_nearest_first_one_to_one_within_the_gate() -> None:
    a, b = _piece(1, 0.0, 0.0), _piece(2, 0.05, 0.0)
    far = _piece(3, 1.0, 0.0)
    near_a, near_b = _detection(0.001, 0.0), _detection(0.049, 0.0)
    stray = _detection(0.5, 0.5)
    match = match_frame([near_b, stray, near_a], [a, b, far])
    assert match.pairs == ((near_a, a), (near_b, b))
    assert match.missed == (far,)
    assert match.spurious == (stray,)


def test_the_mixture_fit_recovers_inliers_and_outliers() -> None:
    rng = np.random.default_rng(3)
    n = 6000
    outlier = rng.random(n) < 0.3
    std = np.where(outlier, 0.02, 0.002)
    dx, dy = std * rng.standard_normal(n), std * rng.standard_normal(n)
    fit = fit_position_mixture(dx.tolist(), dy.tolist())
    assert fit.inlier_std_m == pytest.approx(0.002, rel=0.08)
    assert fit.outlier_std_m == pytest.approx(0.02, rel=0.08)
    assert fit.outlier_rate == pytest.approx(0.3, abs=0.03)


def test_one_gaussian_is_fitted_as_one() -> None:
    rng = np.random.default_rng(4)
    dx, dy = 0.003 * rng.standard_normal((2, 4000))
    fit = fit_position_mixture(dx.tolist(), dy.tolist())
    assert fit.inlier_std_m == pytest.approx(0.003, rel=0.08)
    assert fit.outlier_rate < 0.02 or fit.outlier_std_m < 1.6 * fit.inlier_std_m


def test_nothing_matched_is_refused() -> None:
    sample = FitSample.of([match_frame([_detection(5.0, 5.0)], [_piece(1, 0.0, 0.0)])])
    with pytest.raises(ValueError, match="no detection matched a piece in 1 frames"):
        fit_oracle(sample)


def _ground_truth(piece: TruthPiece) -> GroundTruth:
    return GroundTruth(
        id=piece.object_id,
        source_id=f"o{piece.object_id}",
        class_name=piece.class_name,
        position_m=(piece.x_m, piece.y_m, 0.02),
        orientation_xyzw=(0.0, 0.0, 0.0, 1.0),
        linear_velocity_mps=(0.0, 0.0, 0.0),
        angular_velocity_radps=(0.0, 0.0, 0.0),
        top_view=TopView(
            yaw_rad=piece.yaw_rad, length_m=0.1, width_m=0.05, height_m=0.04, below_m=0.02
        ),
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


def test_the_fit_recovers_an_oracle_whose_model_is_known() -> None:
    """Frames of an oracle with outliers, fitted: every parameter comes back."""
    truth = [_piece(i, -1.3 + 0.2 * (i % 7), 0.2 + 0.2 * (i // 7)) for i in range(28)]
    objects = [_ground_truth(p) for p in truth]
    config = PerceptionConfig(
        position_noise_m=0.002,
        position_outlier_rate=0.25,
        position_outlier_noise_m=0.015,
        yaw_noise_rad=0.05,
        drop_rate=0.1,
        misclassification_rate=0.05,
        latency_s=0.0,
    )
    oracle = Perception(config, CLASSES, 0.0, 1 / 240, np.random.default_rng(7))
    frames = [oracle.capture(k / 15.0, objects) for k in range(300)]
    fit = fit_oracle(FitSample.of(match_frame(f.detections, truth) for f in frames))
    assert fit.frames == 300
    assert fit.truth_in_view == 300 * 28
    assert fit.position_noise_m == pytest.approx(0.002, rel=0.1)
    assert fit.position_outlier_noise_m == pytest.approx(0.015, rel=0.1)
    assert fit.position_outlier_rate == pytest.approx(0.25, abs=0.03)
    assert fit.yaw_noise_rad == pytest.approx(0.05, rel=0.1)
    n = fit.truth_in_view
    assert abs(fit.drop_rate - 0.1) < 4 * math.sqrt(0.1 * 0.9 / n)
    assert abs(fit.misclassification_rate - 0.05) < 4 * math.sqrt(0.05 * 0.95 / fit.matched)
    assert fit.spurious_per_frame == 0.0


def test_no_outliers_draw_no_numbers_the_oracle_did_not_draw_before() -> None:
    """An outlier rate of 0 leaves every frame as it was (its stream is never spawned)."""
    objects = [_ground_truth(_piece(i, -1.0 + 0.1 * i, 0.5)) for i in range(8)]
    plain = Perception(PerceptionConfig(), CLASSES, 0.0, 1 / 240, np.random.default_rng(1))
    unused = PerceptionConfig(position_outlier_noise_m=0.05, fitted_from="hand-set")
    same = Perception(unused, CLASSES, 0.0, 1 / 240, np.random.default_rng(1))
    for k in range(20):
        assert plain.capture(k / 30, objects) == same.capture(k / 30, objects)


def test_the_camera_page_states_the_fits_gate_and_elongation() -> None:
    from twin.oracle_fit import MATCH_GATE_M, YAW_ELONGATION

    page = (Path(__file__).resolve().parents[2] / "docs" / "camera.md").read_text(encoding="utf-8")
    section = page.split("## The oracle fitted to the camera", 1)[1].split("\n## ", 1)[0]
    assert f"nearest piece within {MATCH_GATE_M * 100:g} cm" in section
    assert f"at least {YAW_ELONGATION:g} times longer than wide" in section
