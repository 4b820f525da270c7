"""The twin's perception score: matches by mask IoU against the render's ids, and leaves out the
pieces it must (cut by the border, held, off the belt, mostly hidden)."""

from __future__ import annotations

import math

import numpy as np

from detector.detector import DetectedInstance, DetectorOutput
from detector.geometry import ImageGeometry
from interfaces.camera import Intrinsics, RgbdFrame
from interfaces.detections import Detection
from twin.monitor import GroundTruth
from twin.perception_score import PERCEPTION_METRICS, EpisodeScorer
from twin.top_view import TopView

K = Intrinsics(width_px=64, height_px=48, fx_px=50.0, fy_px=50.0, cx_px=31.5, cy_px=23.5)


def _truth(
    object_id: int,
    class_name: str,
    xyz: tuple[float, float, float],
    view: tuple[float, float, float],
    *,
    on_belt: bool = True,
    held: bool = False,
) -> GroundTruth:
    """A piece's ground truth: ``view`` is its top view's yaw, length and width."""
    yaw, length, width = view
    return GroundTruth(
        id=object_id,
        source_id="s",
        class_name=class_name,
        position_m=xyz,
        orientation_xyzw=(0.0, 0.0, 0.0, 1.0),
        linear_velocity_mps=(0.0, 0.0, 0.0),
        angular_velocity_radps=(0.0, 0.0, 0.0),
        top_view=TopView(yaw_rad=yaw, length_m=length, width_m=width, height_m=0.02, below_m=0.01),
        length_m=length,
        width_m=width,
        area_m2=length * width,
        volume_m3=length * width * 0.02,
        height_m=0.02,
        mass_kg=0.1,
        on_belt=on_belt,
        in_workspace=False,
        held=held,
        in_bin=False,
    )


def frame(ids: np.ndarray) -> RgbdFrame:
    return RgbdFrame(
        camera="cam",
        stamp_s=0.0,
        rgb=np.zeros((48, 64, 3), np.uint8),
        depth_m=np.ones((48, 64), np.float32),
        intrinsics=K,
        worldMoptical=np.eye(4),
        instance_ids=ids,
    )


def output(labels: np.ndarray, names: list[str], xy: list[tuple[float, float]]) -> DetectorOutput:
    geometry = ImageGeometry(
        centroid_uv_px=(0.0, 0.0), axis_rad=0.0, length_px=1.0, width_px=1.0, area_px=1
    )
    instances = tuple(
        DetectedInstance(
            label=k,
            class_name=name,
            score=0.9,
            image=geometry,
            detection=Detection(
                class_name=name,
                confidence=0.9,
                x_m=x,
                y_m=y,
                z_m=0.0,
                yaw_rad=0.1,
                length_m=0.1,
                width_m=0.05,
                height_m=0.02,
            ),
        )
        for k, (name, (x, y)) in enumerate(zip(names, xy, strict=True), start=1)
    )
    return DetectorOutput(mode="depth", labels=labels, instances=instances)


def test_a_perfect_frame_scores_one_and_errors_are_in_the_belt_plane() -> None:
    ids = np.zeros((48, 64), np.int32)
    ids[10:20, 10:30] = 7
    ids[25:40, 35:45] = 9
    truth = {
        7: _truth(7, "wood", (1.0, 0.5, 0.02), (0.0, 0.2, 0.1)),
        9: _truth(9, "brick", (1.2, 0.4, 0.02), (0.3, 0.1, 0.1)),  # square: no yaw
    }
    labels = np.where(ids == 7, 1, np.where(ids == 9, 2, 0)).astype(np.int32)
    scorer = EpisodeScorer(("wood", "brick"))
    scorer.add(
        frame(ids),
        output(labels, ["wood", "brick"], [(1.003, 0.504), (1.2, 0.4)]),
        truth,
        detect_s=0.02,
        render_s=0.01,
    )
    s = scorer.summary()
    assert set(PERCEPTION_METRICS) <= set(s)
    assert (s["recall"], s["precision"], s["class_accuracy"]) == (1.0, 1.0, 1.0)
    assert math.isclose(s["centroid_error_p90_m"], 0.9 * 0.005, rel_tol=1e-6)
    assert math.isclose(s["yaw_error_median_rad"], 0.1)  # only the elongated piece
    assert math.isclose(s["latency_median_ms"], 20.0)
    assert s["confusion/wood/wood"] == 1.0
    assert s["confusion/brick/brick"] == 1.0


def test_pieces_out_of_scoring_count_neither_way_and_misses_count() -> None:
    ids = np.zeros((48, 64), np.int32)
    ids[0:10, 0:10] = 1  # cut by the image border
    ids[20:30, 20:30] = 2  # held by a tool
    ids[35:45, 50:60] = 3  # on the belt, missed
    ids[35:45, 5:15] = 4  # on the belt, found but called wood
    truth = {
        1: _truth(1, "brick", (0.0, 0.0, 0.0), (0.0, 0.1, 0.1)),
        2: _truth(2, "brick", (0.0, 0.0, 0.3), (0.0, 0.1, 0.1), held=True, on_belt=False),
        3: _truth(3, "brick", (0.0, 0.0, 0.0), (0.0, 0.1, 0.1)),
        4: _truth(4, "brick", (0.0, 0.0, 0.0), (0.0, 0.1, 0.1)),
    }
    labels = np.zeros((48, 64), np.int32)
    labels[0:10, 0:10] = 1  # the border piece, detected: not scored
    labels[20:30, 20:30] = 2  # the held piece, detected: not scored
    labels[35:45, 5:15] = 3
    labels[2:8, 40:46] = 4  # nothing there: a false alarm
    scorer = EpisodeScorer(("brick", "wood"))
    scorer.add(
        frame(ids),
        output(labels, ["brick", "brick", "wood", "wood"], [(0.0, 0.0)] * 4),
        truth,
        detect_s=0.0,
        render_s=0.0,
    )
    s = scorer.summary()
    assert s["truth_instances"] == 2.0  # pieces 3 and 4
    assert s["detections"] == 2.0  # the match and the false alarm
    assert s["recall"] == 0.5
    assert s["precision"] == 0.5
    assert s["class_accuracy"] == 0.0
    assert s["confusion/brick/wood"] == 1.0
