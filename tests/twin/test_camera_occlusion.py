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


def test_the_example_frame_draws_what_is_not_handed_on_in_grey() -> None:
    from detector.detector import DetectedInstance, DetectorOutput
    from detector.geometry import ImageGeometry
    from interfaces.camera import RgbdCameraSpec, RgbdFrame
    from twin.camera.overlay import BORDER_RGB, overlay_image

    labels, arm = _scene()
    geometry = ImageGeometry(
        centroid_uv_px=(0.0, 0.0), axis_rad=0.0, length_px=1.0, width_px=1.0, area_px=1
    )
    output = DetectorOutput(
        mode="depth",
        labels=labels,
        instances=tuple(
            DetectedInstance(label=k, class_name="wood", score=1.0, image=geometry, detection=None)
            for k in (1, 2, 3)
        ),
    )
    spec = RgbdCameraSpec(width_px=16, height_px=12)
    frame = RgbdFrame(
        camera=spec.name,
        stamp_s=0.0,
        rgb=np.zeros((12, 16, 3), dtype=np.uint8),
        depth_m=np.ones((12, 16), dtype=np.float32),
        intrinsics=spec.intrinsics,
        worldMoptical=spec.worldMoptical(),
    )
    image = np.asarray(
        overlay_image(frame, output, lambda _: (1.0, 0.0, 1.0), occluded_labels(labels, arm))
    )
    grey = np.all(image == BORDER_RGB, axis=-1)
    magenta = np.all(image == (255, 0, 255), axis=-1)
    assert grey[labels == 1].any()
    assert grey[labels == 2].any()
    assert magenta[labels == 3].any()
    assert not grey[labels == 3].any()
