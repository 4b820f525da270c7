"""Perception scoring on hand-made masks: matching, precision policies, classes, pose errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from detector.errors import DetectorConfigError, FrameError
from detector.score import InstanceSet, PerceptionScorer, iou_matrix, match_frame


def _box(r0: int, r1: int, c0: int, c1: int, shape: tuple[int, int] = (20, 30)) -> np.ndarray:
    m = np.zeros(shape, dtype=bool)
    m[r0:r1, c0:c1] = True
    return m


def test_iou_of_label_images_and_of_mask_lists_agree() -> None:
    truth = InstanceSet.from_masks([_box(0, 10, 0, 10), _box(10, 20, 10, 30)], ["a", "b"])
    pred = InstanceSet.from_masks([_box(0, 10, 0, 5), _box(10, 20, 10, 25)], ["a", "b"])
    expected = np.array([[0.5, 0.0], [0.0, 0.75]])
    np.testing.assert_allclose(iou_matrix(truth, pred), expected)
    ids = np.zeros((20, 30), np.int32)
    ids[_box(0, 10, 0, 10)] = 7
    ids[_box(10, 20, 10, 30)] = 3
    truth_ids = InstanceSet.from_id_image(ids, {7: "a", 3: "b"})
    pred_labels = np.zeros((20, 30), np.int32)
    pred_labels[_box(0, 10, 0, 5)] = 1
    pred_labels[_box(10, 20, 10, 25)] = 2
    got = iou_matrix(truth_ids, InstanceSet.from_labels(pred_labels, ["a", "b"]))
    # id 3 comes first (ids sorted)
    np.testing.assert_allclose(got, expected[::-1])


def test_matching_is_one_to_one_at_the_threshold() -> None:
    truth = InstanceSet.from_masks([_box(0, 10, 0, 10)], ["a"])
    # two predictions overlap the one truth; only the better matches, the other is a false one
    pred = InstanceSet.from_masks([_box(0, 10, 0, 6), _box(0, 10, 0, 9)], ["a", "a"])
    match = match_frame(truth, pred)
    assert match.pairs == ((0, 1),)
    assert match.recall == 1.0
    assert match.precision == 0.5
    below = InstanceSet.from_masks([_box(0, 10, 0, 4)], ["a"])  # IoU 0.4
    assert match_frame(truth, below).pairs == ()


def test_unlabelled_ground_truth_is_left_out_of_precision_and_said_so() -> None:
    truth = InstanceSet.from_masks([_box(0, 10, 0, 10)], ["brick"])
    pred = InstanceSet.from_masks(
        [
            _box(0, 10, 0, 10),  # matches
            _box(12, 18, 20, 28),  # on the belt, no label near: an unlabelled piece
            _box(0, 4, 6, 12),  # mostly inside the labelled piece: a real false detection
        ],
        ["brick", "wood", "wood"],
    )
    strict = PerceptionScorer()
    strict.add(pred, truth)
    lenient = PerceptionScorer(labelled_overlap=0.5)
    lenient.add(pred, truth)
    assert strict.result().precision == pytest.approx(1 / 3)
    result = lenient.result()
    assert result.precision == pytest.approx(1 / 2)
    assert result.precision_all == pytest.approx(1 / 3)
    assert result.unassessed_predictions == 1
    assert "0.5" in result.precision_policy
    assert "every detection" in strict.result().precision_policy


def test_classes_confusion_and_pose_errors_accumulate_over_frames() -> None:
    scorer = PerceptionScorer(class_names=("brick", "wood"), centroid_unit="m")
    for shift in (0.001, 0.003):
        truth = InstanceSet.from_masks(
            [_box(0, 10, 0, 10), _box(10, 20, 10, 30)],
            ["brick", "wood"],
            centroids=np.array([[0.0, 0.0], [1.0, 1.0]]),
            yaws_rad=np.array([0.1, math.pi / 2 - 0.01]),
        )
        pred = InstanceSet.from_masks(
            [_box(0, 10, 0, 10), _box(10, 20, 10, 30), _box(0, 5, 20, 25)],
            ["brick", "brick", "rubber"],
            centroids=np.array([[shift, 0.0], [1.0, 1.0 + shift], [5.0, 5.0]]),
            yaws_rad=np.array([0.1 + shift, -math.pi / 2 + 0.01, 0.0]),  # same axis, mod pi
        )
        scorer.add(pred, truth)
    result = scorer.result()
    assert result.frames == 2
    assert result.recall == 1.0
    assert result.precision == pytest.approx(4 / 6)
    assert result.class_accuracy == 0.5
    assert result.class_names == ("brick", "wood")  # rubber never matched: not a row
    assert result.confusion == ((2, 0), (2, 0))
    assert result.centroid_error_median == pytest.approx(0.002)
    assert result.centroid_error_p90 == pytest.approx(0.003)
    # errors 0.001, 0.003 and twice 0.02 (the same axis across +-pi/2, not pi - 0.02)
    assert result.yaw_error_median_rad == pytest.approx(0.0115, abs=1e-9)
    data = result.to_data()
    assert json.loads(json.dumps(data)) == data
    assert data["confusion"]["matrix"] == [[2, 0], [2, 0]]  # type: ignore[index]


def test_an_empty_frame_and_bad_inputs() -> None:
    empty = InstanceSet.from_masks([], [], shape=(20, 30))
    truth = InstanceSet.from_masks([_box(0, 10, 0, 10)], ["a"])
    scorer = PerceptionScorer()
    scorer.add(empty, truth)
    result = scorer.result()
    assert result.recall == 0.0
    assert math.isnan(result.precision)
    assert result.to_data()["precision"] is None
    with pytest.raises(FrameError, match="not the same image"):
        match_frame(truth, InstanceSet.from_masks([], [], shape=(5, 5)))
    with pytest.raises(FrameError, match="have no class"):
        InstanceSet.from_id_image(np.ones((3, 3), np.int32), {2: "a"})
    with pytest.raises(FrameError, match="class names"):
        InstanceSet.from_labels(np.full((3, 3), 2, np.int32), ["a"])
    with pytest.raises(DetectorConfigError, match="iou_threshold"):
        PerceptionScorer(iou_threshold=0.0)
