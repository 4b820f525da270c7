"""The camera model: frames, orientation convention, projection and deprojection agree."""

from __future__ import annotations

import math

import numpy as np
import pytest

from interfaces.camera import Intrinsics, RgbdCameraSpec, RgbdFrame, project, world_points
from interfaces.errors import ConfigError


def test_the_default_camera_looks_down_with_rows_along_the_belt_and_columns_along_y() -> None:
    spec = RgbdCameraSpec()
    m = spec.worldMoptical()
    np.testing.assert_allclose(m[:3, 2], [0.0, 0.0, -1.0], atol=1e-12)  # view along -z
    np.testing.assert_allclose(m[:3, 1], [1.0, 0.0, 0.0], atol=1e-12)  # image down: +x
    np.testing.assert_allclose(m[:3, 0], [0.0, 1.0, 0.0], atol=1e-12)  # image right: +y
    assert spec.optical_frame == "camera_optical_frame"
    assert spec.link_frame == "camera_link"


def test_a_point_projected_and_deprojected_comes_back() -> None:
    spec = RgbdCameraSpec(position_m=(0.1, 0.4, 1.1), rpy_rad=(0.05, 1.4, 3.0))
    k = spec.intrinsics
    rng = np.random.default_rng(1)
    pts = np.column_stack(
        (rng.uniform(-0.3, 0.3, 50), 0.4 + rng.uniform(-0.3, 0.3, 50), rng.uniform(0, 0.1, 50))
    )
    uv, z = project(pts, k, spec.worldMoptical())
    assert (z > 0).all()
    depth = np.full((k.height_px, k.width_px), np.nan, dtype=np.float32)
    # put each point's depth at its (rounded) pixel and read it back through deprojection
    cols, rows = np.round(uv).astype(int).T
    inside = (cols >= 0) & (cols < k.width_px) & (rows >= 0) & (rows < k.height_px)
    assert inside.sum() > 40
    depth[rows[inside], cols[inside]] = z[inside]
    frame = RgbdFrame(
        camera="c",
        stamp_s=0.0,
        rgb=np.zeros((k.height_px, k.width_px, 3), np.uint8),
        depth_m=depth,
        intrinsics=k,
        worldMoptical=spec.worldMoptical(),
    )
    back = world_points(frame)[rows[inside], cols[inside]]
    # a pixel is about z / f wide: rounding to it moves the point at most that far
    assert np.abs(back - pts[inside]).max() < 1.2 / k.fx_px * 1.2


def test_camera_info_is_plumb_bob_with_the_focal_length_of_the_field_of_view() -> None:
    k = Intrinsics.from_hfov(640, 480, 60.0)
    info = k.camera_info()
    assert info["distortion_model"] == "plumb_bob"
    assert k.fx_px == pytest.approx(320 / math.tan(math.radians(30)))
    assert info["p"][3] == 0.0


@pytest.mark.parametrize(
    ("field", "value"),
    [("hfov_deg", 180.0), ("rate_hz", 0.0), ("depth_min_m", 5.0), ("name", "a b")],
)
def test_a_bad_camera_is_refused_naming_its_key(field: str, value: object) -> None:
    with pytest.raises(ConfigError, match=field.split("_", maxsplit=1)[0]):
        RgbdCameraSpec(**{field: value})  # type: ignore[arg-type]
