"""Depth mode on synthetic frames with known geometry: every piece found, where and as big as it
is, touching pieces apart, a tilted face's tilt, the suction point on the top face."""

from __future__ import annotations

import math

import numpy as np
import pytest

from detector.detector import Detector, DetectorOutput
from detector.synthetic import Piece, render, scatter
from interfaces.camera import DepthNoise, RgbdFrame
from interfaces.detections import Detection, wrap_half_pi

GREY = (150, 150, 145)
RED = (175, 80, 50)


def _matched(output: DetectorOutput, frame: RgbdFrame) -> dict[int, Detection]:
    """Each true piece's index (0-based) to the detection whose mask mostly covers it."""
    assert frame.instance_ids is not None
    out: dict[int, Detection] = {}
    for inst in output.instances:
        ids = frame.instance_ids[output.labels == inst.label]
        piece = int(np.bincount(ids).argmax())
        assert piece > 0, "a detection on the belt"
        assert inst.detection is not None
        assert piece - 1 not in out, "two detections of one piece"
        out[piece - 1] = inst.detection
    return out


def _elongated(pieces: list[Piece]) -> list[int]:
    return [i for i, p in enumerate(pieces) if p.length_m > 1.3 * p.width_m]


@pytest.mark.parametrize("noise", [None, DepthNoise()], ids=["exact", "noisy"])
def test_every_piece_is_found_where_and_as_big_as_it_is(noise: DepthNoise | None) -> None:
    pieces = scatter(25, seed=3)
    frame = render(pieces, seed=3, noise=noise)
    output = Detector().detect(frame)
    assert output.mode == "depth"
    found = _matched(output, frame)
    assert len(found) == len(pieces)  # recall 1, no piece split or merged
    assert len(output.instances) == len(pieces)  # no fragments
    centroid = [math.hypot(d.x_m - pieces[i].x_m, d.y_m - pieces[i].y_m) for i, d in found.items()]
    length = [found[i].length_m - pieces[i].length_m for i in found]
    width = [found[i].width_m - pieces[i].width_m for i in found]
    height = [found[i].height_m - pieces[i].height_m for i in found]
    yaw = [abs(wrap_half_pi(found[i].yaw_rad - pieces[i].yaw_rad)) for i in _elongated(pieces)]
    # tolerances: a pixel on the belt is 2.2 mm, the depth noise at 1.2 m about 2.7 mm
    assert max(centroid) < 0.003
    assert abs(float(np.median(length))) < 0.002
    assert abs(float(np.median(width))) < 0.002
    assert max(np.abs(length)) < 0.008
    assert max(np.abs(width)) < 0.008
    assert max(np.abs(height)) < 0.002
    assert float(np.median(yaw)) < math.radians(1)
    assert max(yaw) < math.radians(4)
    for d in found.values():
        assert abs(d.z_m) < 0.002  # lying on the belt
        assert -math.pi / 2 < d.yaw_rad <= math.pi / 2


def test_the_footprint_is_not_stretched_by_perspective() -> None:
    """A tall piece far off the optical axis shows a side wall; its footprint stays true."""
    piece = Piece(
        x_m=0.35, y_m=0.45, yaw_rad=0.0, length_m=0.12, width_m=0.05, height_m=0.08, rgb=GREY
    )
    output = Detector().detect(render([piece]))
    (inst,) = output.instances
    d = inst.detection
    assert d is not None
    assert d.length_m == pytest.approx(0.12, abs=0.003)
    assert d.width_m == pytest.approx(0.05, abs=0.003)
    assert math.hypot(d.x_m - 0.35, d.y_m - 0.45) < 0.002
    # the image box of the same mask is longer than the piece would be at the belt (the wall)
    metres_per_px = 1.2 / (0.5 * 640 / math.tan(math.radians(30)))
    assert inst.image.width_px * metres_per_px > 0.05 + 0.01


def test_two_touching_pieces_are_split() -> None:
    """Two level boxes side by side with a narrow contact (a neck), and a low box against a
    tall one (a wall between two levels)."""
    pieces = [
        Piece(x_m=-0.2, y_m=0.0, yaw_rad=0.6, length_m=0.08, width_m=0.08, height_m=0.04, rgb=GREY),
        Piece(
            x_m=-0.2 + 0.075,
            y_m=0.075,
            yaw_rad=0.6,
            length_m=0.08,
            width_m=0.08,
            height_m=0.04,
            rgb=GREY,
        ),
        Piece(x_m=0.2, y_m=0.0, yaw_rad=0.0, length_m=0.12, width_m=0.06, height_m=0.02, rgb=RED),
        Piece(x_m=0.2, y_m=0.06, yaw_rad=0.0, length_m=0.12, width_m=0.06, height_m=0.06, rgb=RED),
    ]
    frame = render(pieces)
    output = Detector().detect(frame)
    found = _matched(output, frame)
    assert sorted(found) == [0, 1, 2, 3]
    assert found[2].height_m == pytest.approx(0.02, abs=0.002)
    assert found[3].height_m == pytest.approx(0.06, abs=0.002)


def test_a_piece_lying_on_another_has_its_underside_on_it() -> None:
    below = Piece(
        x_m=0.0, y_m=0.0, yaw_rad=0.0, length_m=0.2, width_m=0.15, height_m=0.03, rgb=GREY
    )
    above = Piece(
        x_m=0.01,
        y_m=0.0,
        yaw_rad=0.5,
        length_m=0.08,
        width_m=0.04,
        height_m=0.02,
        base_z_m=0.03,
        rgb=RED,
    )
    frame = render([below, above])
    found = _matched(Detector().detect(frame), frame)
    assert found[1].z_m == pytest.approx(0.03, abs=0.002)
    assert found[1].height_m == pytest.approx(0.02, abs=0.002)
    assert found[0].z_m == pytest.approx(0.0, abs=0.002)


@pytest.mark.parametrize("tilt_deg", [0.0, 15.0, 30.0])
def test_a_tilted_face_has_its_tilt(tilt_deg: float) -> None:
    piece = Piece(
        x_m=0.05,
        y_m=-0.1,
        yaw_rad=0.3,
        length_m=0.16,
        width_m=0.08,
        height_m=0.02,
        tilt_rad=math.radians(tilt_deg),
        rgb=GREY,
    )
    output = Detector().detect(render([piece], noise=DepthNoise(), seed=4))
    (inst,) = output.instances
    d = inst.detection
    assert d is not None
    assert d.suction_tilt_rad == pytest.approx(math.radians(tilt_deg), abs=math.radians(3))
    assert d.height_m == pytest.approx(piece.top_z_m, abs=0.004)


def test_the_suction_point_lies_on_the_top_face_where_the_largest_disc_fits() -> None:
    piece = Piece(
        x_m=-0.1, y_m=0.2, yaw_rad=-0.4, length_m=0.14, width_m=0.06, height_m=0.05, rgb=RED
    )
    (inst,) = Detector().detect(render([piece])).instances
    d = inst.detection
    assert d is not None
    sx, sy, sz = d.suction_point_m
    c, s = math.cos(piece.yaw_rad), math.sin(piece.yaw_rad)
    along = (sx - piece.x_m) * c + (sy - piece.y_m) * s
    across = -(sx - piece.x_m) * s + (sy - piece.y_m) * c
    assert abs(along) <= piece.length_m / 2 - d.suction_radius_m + 0.003
    assert abs(across) < 0.004  # on the long axis: the widest place
    assert sz == pytest.approx(0.05, abs=0.001)  # on the top face
    assert d.suction_radius_m == pytest.approx(0.03, abs=0.003)  # half the width


def test_the_output_converts_to_the_controllers_frame() -> None:
    frame = render(scatter(3, seed=2), stamp_s=1.5)
    output = Detector().detect(frame)
    message = output.detection_frame(capture_time_s=frame.stamp_s, release_time_s=1.55)
    assert message.capture_time_s == 1.5
    assert len(message.detections) == 3
    assert all(d.class_name == "unknown" and d.confidence == 0.0 for d in message.detections)


def test_a_piece_cut_by_the_image_border_is_flagged() -> None:
    inside = Piece(
        x_m=0.0, y_m=0.0, yaw_rad=0.0, length_m=0.1, width_m=0.05, height_m=0.03, rgb=RED
    )
    cut = Piece(x_m=0.5, y_m=0.0, yaw_rad=0.0, length_m=0.2, width_m=0.05, height_m=0.03, rgb=RED)
    frame = render([inside, cut])  # the image reaches x = +-0.52 m: the second is cut
    output = Detector().detect(frame)
    found = {round(i.detection.x_m, 1): i.at_border for i in output.instances if i.detection}
    assert found == {0.0: False, 0.5: True}
