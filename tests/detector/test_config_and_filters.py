"""Configuration errors name the field; the per-frame filters keep real values."""

from __future__ import annotations

import numpy as np
import pytest

from detector.config import ColourConfig, DepthConfig, DetectorConfig, GeometryConfig
from detector.detector import Detector
from detector.errors import DetectorConfigError, FrameError
from detector.filters import fill_small_holes, median3
from interfaces.dataclass_io import from_data, to_data
from interfaces.errors import ConfigError


def test_the_configuration_round_trips_through_plain_data() -> None:
    config = DetectorConfig(mode="colour", depth=DepthConfig(min_height_m=0.004))
    assert from_data(DetectorConfig, to_data(config), "detector.yaml") == config


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: DetectorConfig(mode="lidar"), "detector.mode"),  # type: ignore[arg-type]
        (lambda: DetectorConfig(work_stride=0), "work_stride"),
        (lambda: DepthConfig(min_height_m=-0.001), "depth.min_height_m"),
        (lambda: ColourConfig(smooth_px=0), "colour.smooth_px"),
        (lambda: GeometryConfig(wall_slope_deg=95.0), "geometry.wall_slope_deg"),
        (lambda: GeometryConfig(ring_inner_px=5, ring_outer_px=5), "ring_outer_px"),
    ],
)
def test_a_bad_setting_names_its_field(make: object, match: str) -> None:
    with pytest.raises(DetectorConfigError, match=match) as caught:
        make()  # type: ignore[operator]
    assert isinstance(caught.value, ConfigError)


def test_holes_are_filled_with_a_neighbour_value_never_a_point_in_mid_air() -> None:
    depth = np.full((5, 6), 1.2, dtype=np.float32)
    depth[:, :3] = 1.15  # a piece's top on the left, the belt on the right
    depth[2, 2] = depth[2, 3] = np.nan  # dropouts on the edge
    filled = fill_small_holes(depth)
    assert not np.isnan(filled).any()
    assert set(np.unique(filled).tolist()) <= {np.float32(1.15), np.float32(1.2)}
    wide = np.full((9, 9), np.nan, dtype=np.float32)
    wide[0] = 1.0
    assert np.isnan(fill_small_holes(wide)[8, 4])  # a wide hole keeps its core


def test_the_median_removes_a_spike_and_keeps_an_edge() -> None:
    image = np.zeros((7, 7), dtype=np.float32)
    image[:, 4:] = 1.0
    image[2, 1] = 5.0
    out = median3(image)
    assert out[2, 1] == 0.0
    np.testing.assert_array_equal(out[:, 4:], 1.0)
    np.testing.assert_array_equal(out[:, :3], 0.0)


def test_a_frame_of_the_wrong_shape_is_refused() -> None:
    from interfaces.camera import Intrinsics, RgbdFrame

    k = Intrinsics.from_hfov(64, 48, 60.0)
    frame = RgbdFrame(
        camera="c",
        stamp_s=0.0,
        rgb=np.zeros((48, 64), dtype=np.uint8),
        depth_m=np.ones((48, 64), dtype=np.float32),
        intrinsics=k,
        worldMoptical=np.eye(4),
    )
    with pytest.raises(FrameError, match="rgb"):
        Detector().detect(frame)
