"""A piece partly under an arm (or under a held piece) is seen only in part: its detection is
not handed on, as one cut by the image's border is not (twin/camera/filters.py)."""

from __future__ import annotations

import numpy as np

from twin.camera.filters import occluded_labels


def _scene() -> tuple[np.ndarray, np.ndarray]:
    """Three pieces and an arm: piece 1 reaches the arm's pixels, piece 2 touches them only at a
    corner, piece 3 lies two pixels away."""
    labels = np.zeros((12, 16), dtype=np.int32)
    labels[1:4, 1:5] = 1
    labels[7:10, 1:4] = 2
    labels[7:10, 9:12] = 3
    arm = np.zeros(labels.shape, dtype=bool)
    arm[0:6, 5:8] = True  # beside piece 1
    arm[10:12, 4:6] = True  # diagonal to piece 2's corner (9, 3)
    arm[7:10, 13:16] = True  # two pixels beyond piece 3 (columns 9..11, gap 12)
    return labels, arm


def test_pieces_touching_an_occluder_are_marked_and_the_rest_are_not() -> None:
    labels, arm = _scene()
    hidden = occluded_labels(labels, arm)
    assert hidden.tolist() == [False, True, True, False]


def test_nothing_is_hidden_without_an_occluder_or_without_pieces() -> None:
    labels, arm = _scene()
    assert not occluded_labels(labels, np.zeros_like(arm)).any()
    assert occluded_labels(np.zeros_like(labels), arm).tolist() == [False]
