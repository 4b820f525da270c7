"""Simulated perception: field of view, latency, and noise statistics against the configuration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from interfaces.detections import wrap_half_pi
from twin.ground_truth import GroundTruth
from twin.perception import Perception
from twin.perception_config import PerceptionConfig
from twin.top_view import TopView

CLASSES = ("concrete", "brick", "wood", "rubber")


def _object(
    i: int, x: float, *, on_belt: bool = True, yaw: float = 0.3, z: float = 0.03
) -> GroundTruth:
    return GroundTruth(
        id=i,
        source_id=f"o{i}",
        class_name=CLASSES[i % 4],
        position_m=(x, 0.5, z),
        orientation_xyzw=(0.0, 0.0, 0.0, 1.0),
        linear_velocity_mps=(0.4, 0.0, 0.0),
        angular_velocity_radps=(0.0, 0.0, 0.0),
        top_view=TopView(yaw_rad=yaw, length_m=0.1, width_m=0.05, height_m=0.04, below_m=0.02),
        length_m=0.1,
        width_m=0.05,
        area_m2=0.005,
        volume_m3=0.0002,
        height_m=0.04,
        mass_kg=0.4,
        on_belt=on_belt,
        in_workspace=False,
        held=False,
        in_bin=False,
    )


def test_zero_noise_is_exact_and_immediate_and_respects_the_field_of_view() -> None:
    cfg = PerceptionConfig.zero_noise()
    perception = Perception(cfg, CLASSES, 0.0, 1 / 240, np.random.default_rng(0))
    fov_max = perception.camera.fov_max_x_m
    objects = [_object(1, 0.0), _object(2, fov_max + 0.01), _object(3, -0.5, on_belt=False)]
    frame = perception.capture(1.0, objects)
    assert [(d.x_m, d.y_m, d.yaw_rad, d.class_name) for d in frame.detections] == [
        (0.0, 0.5, 0.3, "brick")
    ]
    assert perception.released(1.0) == [frame]


def test_the_field_of_view_is_the_cells_camera() -> None:
    """A cell's camera (here a two-station line's, seeing 1.5 m further upstream) decides what
    is detected, whatever the error model."""
    from interfaces.cell import load_cell

    camera = load_cell("two_pandas").camera
    rng = np.random.default_rng(0)
    line = Perception(PerceptionConfig.zero_noise(), CLASSES, 0.0, 1 / 240, rng, camera=camera)
    reference = Perception(PerceptionConfig.zero_noise(), CLASSES, 0.0, 1 / 240, rng)
    objects = [_object(1, -2.0), _object(2, 0.0)]
    assert [d.x_m for d in line.capture(1.0, objects).detections] == [-2.0, 0.0]
    assert [d.x_m for d in reference.capture(1.0, objects).detections] == [0.0]


def test_detections_report_the_underside_of_stacked_objects() -> None:
    rng = np.random.default_rng(0)
    perception = Perception(PerceptionConfig.zero_noise(), CLASSES, 0.0, 1 / 240, rng)
    # 4 cm tall: resting on the belt, pressed 1 mm into it, and lying on a 5 cm object
    objects = [_object(1, 0.0, z=0.02), _object(2, 0.1, z=0.019), _object(3, 0.2, z=0.07)]
    frame = perception.capture(1.0, objects)
    assert [d.z_m for d in frame.detections] == pytest.approx([0.0, 0.0, 0.05])


def test_latency_and_rate() -> None:
    cfg = PerceptionConfig(latency_s=0.05, rate_hz=30.0)
    perception = Perception(cfg, CLASSES, 0.0, 1 / 240, np.random.default_rng(0))
    assert perception.every_n_steps == 8
    assert [s for s in range(40) if perception.capture_due(s)] == [0, 8, 16, 24, 32]
    perception.capture(2.0, [_object(1, 0.0)])
    assert perception.released(2.049) == []
    assert len(perception.released(2.05)) == 1


def test_noise_drop_and_confusion_statistics_match_the_configuration() -> None:
    cfg = PerceptionConfig(
        position_noise_m=0.003,
        yaw_noise_rad=0.05,
        drop_rate=0.1,
        misclassification_rate=0.2,
        latency_s=0.0,
    )
    perception = Perception(cfg, CLASSES, 0.0, 1 / 240, np.random.default_rng(42))
    objects = [_object(i, -1.0 + 0.02 * i) for i in range(1, 51)]
    dx, dy, dyaw, kept, confused, total = [], [], [], 0, 0, 0
    for frame_index in range(400):
        frame = perception.capture(frame_index / 30.0, objects)
        total += len(objects)
        for det in frame.detections:
            # nearest true object (noise is far smaller than the 2 cm spacing)
            obj = min(objects, key=lambda o: abs(o.position_m[0] - det.x_m))
            dx.append(det.x_m - obj.position_m[0])
            dy.append(det.y_m - obj.position_m[1])
            dyaw.append(wrap_half_pi(det.yaw_rad - obj.top_view.yaw_rad))
            kept += 1
            confused += det.class_name != obj.class_name
    n = kept
    assert np.std(dx) == pytest.approx(0.003, rel=0.03)
    assert np.std(dy) == pytest.approx(0.003, rel=0.03)
    assert abs(np.mean(dx)) < 4 * 0.003 / math.sqrt(n)
    assert np.std(dyaw) == pytest.approx(0.05, rel=0.03)
    drop = 1 - kept / total
    assert abs(drop - 0.1) < 4 * math.sqrt(0.1 * 0.9 / total)
    assert abs(confused / n - 0.2) < 4 * math.sqrt(0.2 * 0.8 / n)


def test_same_seed_same_detections() -> None:
    def frames(seed: int) -> list[tuple[float, ...]]:
        perception = Perception(
            PerceptionConfig(), CLASSES, 0.0, 1 / 240, np.random.default_rng(seed)
        )
        objs = [_object(i, -1.0 + 0.1 * i) for i in range(1, 10)]
        return [
            (d.x_m, d.y_m, d.yaw_rad)
            for t in range(20)
            for d in perception.capture(t / 30, objs).detections
        ]

    assert frames(1) == frames(1)
    assert frames(1) != frames(2)


def test_dropout_windows_deliver_nothing_and_leave_the_other_frames_unchanged() -> None:
    objects = [_object(i, -0.2 * i) for i in range(5)]

    def frames(windows: tuple[tuple[float, float], ...]) -> tuple[list[float], list[object]]:
        perception = Perception(
            PerceptionConfig(),
            CLASSES,
            0.0,
            1 / 240,
            np.random.default_rng(7),
            dropout_windows_s=windows,
        )
        released = []
        for k in range(30):
            perception.capture(k / 30, objects)
            released += perception.released(k / 30 + 1.0)
        assert perception.dropped_frames == (10 if windows else 0)
        return [f.capture_time_s for f in released], [f.detections for f in released]

    times_all, detections_all = frames(())
    times, detections = frames(((1 / 3, 2 / 3),))
    assert times == [t for t in times_all if not 1 / 3 <= t < 2 / 3]
    assert len(times) == 20
    kept = dict(zip(times_all, detections_all, strict=True))
    assert detections == [kept[t] for t in times]


def test_the_suction_point_moves_with_the_detections_noise() -> None:
    """With a suction-point finder each detection carries its point, shifted by the same
    position noise as the centre (one camera error), its radius and its face's tilt; without
    one, NaN."""
    cfg = PerceptionConfig(position_noise_m=0.003, drop_rate=0.0, latency_s=0.0)
    objects = [_object(i, -1.0 + 0.05 * i) for i in range(1, 9)]

    def finder(obj: GroundTruth) -> tuple[tuple[float, float, float], float, float]:
        x, y, z = obj.position_m
        return (x - 0.02 * obj.id, y + 0.01, z + 0.02), 0.001 * obj.id, 0.05 * obj.id

    found = Perception(cfg, CLASSES, 0.0, 1 / 240, np.random.default_rng(4), suction_points=finder)
    plain = Perception(cfg, CLASSES, 0.0, 1 / 240, np.random.default_rng(4))
    frame, other = found.capture(0.0, objects), plain.capture(0.0, objects)
    assert len(frame.detections) == len(objects)
    for obj, det, same in zip(objects, frame.detections, other.detections, strict=True):
        sx, sy, sz = det.suction_point_m
        assert (sx - det.x_m, sy - det.y_m) == pytest.approx((-0.02 * obj.id, 0.01), abs=1e-12)
        assert sz == pytest.approx(obj.position_m[2] + 0.02)
        assert det.suction_radius_m == pytest.approx(0.001 * obj.id)
        assert det.suction_tilt_rad == pytest.approx(0.05 * obj.id)
        assert (same.x_m, same.y_m) == (det.x_m, det.y_m)  # the same draws
        assert math.isnan(same.suction_radius_m)
        assert math.isnan(same.suction_tilt_rad)
