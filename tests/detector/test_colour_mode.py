"""Colour-only mode: pieces found against a dark belt without depth, and said so."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from detector.colour_segment import segment_colour
from detector.config import ColourConfig, DetectorConfig
from detector.detector import Detector
from detector.score import InstanceSet, PerceptionScorer
from detector.synthetic import Piece, render, scatter

RUBBER = (18, 18, 20)


def test_colour_mode_finds_the_pieces_on_a_dark_belt_without_depth() -> None:
    pieces = scatter(15, seed=5)
    frame = render(pieces, seed=5)
    no_depth = replace(frame, depth_m=np.full_like(frame.depth_m, np.nan))
    output = Detector().detect(no_depth)
    assert output.mode == "colour"
    assert frame.instance_ids is not None
    truth = InstanceSet.from_id_image(frame.instance_ids, dict.fromkeys(range(1, 16), "x"))
    scorer = PerceptionScorer()
    match = scorer.add(output.instance_set(), truth)
    assert match.recall == 1.0
    assert match.precision == 1.0
    assert min(match.ious) > 0.6  # the colour cues spread a pixel or two past the edges
    # metric geometry on the belt plane: centroids near the pieces (their tops project a little
    # outwards), height unknown
    for inst in output.instances:
        d = inst.detection
        assert d is not None
        assert math.isnan(d.height_m)
        assert math.isnan(d.suction_radius_m)
        nearest = min(math.hypot(d.x_m - p.x_m, d.y_m - p.y_m) for p in pieces)
        assert nearest < 0.03


def test_colour_mode_is_chosen_by_configuration_even_with_depth() -> None:
    frame = render(scatter(4, seed=6), seed=6)
    output = Detector(config=DetectorConfig(mode="colour")).detect(frame)
    assert output.mode == "colour"
    assert len(output.instances) == 4


def test_a_dark_piece_on_the_dark_belt_is_found_by_its_texture() -> None:
    """Rubber is as dark as the belt: only its rougher texture gives it away."""
    piece = Piece(
        x_m=0.0,
        y_m=0.0,
        yaw_rad=0.2,
        length_m=0.2,
        width_m=0.08,
        height_m=0.02,
        rgb=RUBBER,
        speckle=12.0,
    )
    frame = render([piece], seed=1)
    labels = segment_colour(frame.rgb, config=ColourConfig(), stride=2)
    assert labels.max() == 1
    assert frame.instance_ids is not None
    truth = frame.instance_ids == 1
    iou = (truth & (labels == 1)).sum() / (truth | (labels == 1)).sum()
    assert iou > 0.7


def test_photos_without_a_camera_get_image_geometry_only() -> None:
    piece = Piece(
        x_m=0.0,
        y_m=0.0,
        yaw_rad=0.0,
        length_m=0.2,
        width_m=0.06,
        height_m=0.03,
        rgb=(175, 80, 50),
    )
    frame = render([piece], seed=2)
    output = Detector(config=DetectorConfig(mode="colour")).detect_image(frame.rgb)
    (inst,) = output.instances
    assert inst.detection is None
    # the default camera: rows along +x, so the piece's length (along x) runs down the image
    assert abs(abs(inst.image.axis_rad) - math.pi / 2) < math.radians(3)
    metres_per_px = 1.2 / (0.5 * 640 / math.tan(math.radians(30)))
    assert inst.image.length_px * metres_per_px == pytest.approx(0.2, rel=0.1)
    assert inst.image.centroid_uv_px == pytest.approx((319.5, 239.5), abs=2.0)
