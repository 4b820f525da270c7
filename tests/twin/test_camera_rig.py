"""The camera rig renders a running twin: every object in view has its id mask, the depth lies
on the objects' meshes, and the fallback renderer agrees with the OpenGL one."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pybullet as pb
import pytest
from matplotlib.path import Path as PolygonPath
from PIL import Image

from interfaces.camera import RgbdCameraSpec, RgbdFrame, project, world_points
from tests.gl_support import require_gl
from twin.camera.errors import RenderError
from twin.camera.rig import CameraRig
from twin.objects import ObjectSpec
from twin.scenario import Scenario, SystemLevel
from twin.sim import Twin

SPEC = RgbdCameraSpec()
"""The reference camera: straight down from 1.2 m over x = -0.9 m, seeing x in about
[-1.42, -0.38] m and y in [-0.19, 1.19] m."""


@pytest.fixture(scope="module")
def sample_twin(builtin_meshes: Path) -> Iterator[Twin]:
    """The reference cell after reset, its belt prefilled with the built-in sample up to the
    pick window."""
    scenario = Scenario(
        name="camera", duration_s=5.0, system=SystemLevel(belt_speed_mps=0.2, prefill_m=1.75)
    )
    with Twin(scenario, dataset_dir=builtin_meshes, perception_enabled=False) as twin:
        twin.reset(seed=3)
        yield twin


def in_view(twin: Twin, margin_px: float = 10.0) -> set[int]:
    """The objects on the belt whose centre of mass projects inside the image, ``margin_px``
    from its border."""
    k = SPEC.intrinsics
    seen = set()
    for truth in twin.observe_objects():
        if not truth.on_belt:
            continue
        uv, z = project(np.array([truth.position_m]), k, SPEC.worldMoptical())
        u, v = uv[0]
        if (
            z[0] > 0
            and margin_px <= u < k.width_px - margin_px
            and margin_px <= v < k.height_px - margin_px
        ):
            seen.add(truth.id)
    return seen


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


@pytest.fixture(scope="module")
def gl_frame(sample_twin: Twin) -> RgbdFrame:
    require_gl()
    with CameraRig(sample_twin, renderer="gl") as rig:
        return rig.capture(SPEC)


def test_every_object_in_view_has_an_id_mask(sample_twin: Twin, gl_frame: RgbdFrame) -> None:
    expected = in_view(sample_twin)
    assert len(expected) >= 8  # the prefilled belt under the camera
    ids = gl_frame.instance_ids
    assert ids is not None
    assert ids.dtype == np.int32
    drawn = set(np.unique(ids).tolist()) - {0}
    assert expected <= drawn
    live = {t.id for t in sample_twin.observe_objects()}
    assert drawn <= live
    for object_id in expected:
        assert (ids == object_id).sum() >= 30  # at least a small piece's top: 30 px


def test_the_depth_of_an_objects_pixels_lies_on_its_mesh(
    sample_twin: Twin, gl_frame: RgbdFrame
) -> None:
    assert gl_frame.stamp_s == sample_twin.time_s
    assert gl_frame.camera == SPEC.name
    points = world_points(gl_frame)
    ids = gl_frame.instance_ids
    assert ids is not None
    truths = {t.id: t for t in sample_twin.observe_objects()}
    checked = 0
    for object_id in sorted(in_view(sample_twin)):
        truth = truths[object_id]
        triangles, _ = sample_twin.object_mesh(object_id)
        rotation = np.array(pb.getMatrixFromQuaternion(truth.orientation_xyzw)).reshape(3, 3)
        local = (points[ids == object_id] - np.array(truth.position_m)) @ rotation
        local = local[np.isfinite(local).all(axis=1)]
        lo, hi = triangles.reshape(-1, 3).min(axis=0), triangles.reshape(-1, 3).max(axis=0)
        # within the mesh's bounds, to a pixel's footprint at 1.2 m (2 mm) and a little
        assert (local >= lo - 0.004).all()
        assert (local <= hi + 0.004).all()
        checked += 1
    assert checked >= 8
    belt = (ids == 0) & np.isfinite(gl_frame.depth_m)
    belt_z = points[belt][:, 2]
    # the belt's surface, the floor 0.8 m below it and the bins between
    assert np.isclose(belt_z, 0.0, atol=0.002).mean() > 0.3


def test_the_fallback_renderer_agrees_with_opengl(sample_twin: Twin, gl_frame: RgbdFrame) -> None:
    with CameraRig(sample_twin, renderer="tiny") as rig:
        assert rig.renderer == "tiny"
        tiny = rig.capture(SPEC)
    assert tiny.instance_ids is not None
    assert gl_frame.instance_ids is not None
    objects_gl, objects_tiny = gl_frame.instance_ids > 0, tiny.instance_ids > 0
    assert iou(objects_gl, objects_tiny) >= 0.9
    for object_id in in_view(sample_twin):
        a, b = gl_frame.instance_ids == object_id, tiny.instance_ids == object_id
        if a.sum() >= 300:
            assert iou(a, b) >= 0.9, object_id
    both = np.isfinite(gl_frame.depth_m) & np.isfinite(tiny.depth_m) & objects_gl & objects_tiny
    assert np.median(np.abs(gl_frame.depth_m[both] - tiny.depth_m[both])) < 0.002


def test_the_fallback_alone_shows_every_object_in_view(sample_twin: Twin) -> None:
    """What a machine without EGL renders: every object in view has its id mask, and the
    depth of the belt's pixels is the camera's height above it."""
    with CameraRig(sample_twin, renderer="tiny") as rig:
        frame = rig.capture(SPEC)
    assert frame.instance_ids is not None
    drawn = set(np.unique(frame.instance_ids).tolist()) - {0}
    assert in_view(sample_twin) <= drawn
    z = world_points(frame)[..., 2][(frame.instance_ids == 0) & np.isfinite(frame.depth_m)]
    assert np.isclose(z, 0.0, atol=0.003).mean() > 0.3


def test_pieces_show_the_colours_of_their_photo(sample_twin: Twin, gl_frame: RgbdFrame) -> None:
    """With meshgen's textures (``texture_path`` in ``scene.csv``, ``vt`` in the OBJ) each
    piece is drawn with its photo's pixels: its rendered colour is one shading factor times
    the photo's colour under its polygon (sampled elsewhere, e.g. with v unflipped, it would
    show the belt or another piece)."""
    if "texture_path" not in {f.name for f in dataclasses.fields(ObjectSpec)}:
        pytest.skip("meshgen's texture contract (ObjectSpec.texture_path) has not landed")
    specs = {spec.object_id: spec for layout in sample_twin.layouts for spec in layout.objects}
    ids = gl_frame.instance_ids
    assert ids is not None
    checked = 0
    for truth in sample_twin.observe_objects():
        mask = ids == truth.id
        spec = specs[truth.source_id]
        texture_path = getattr(spec, "texture_path", None)
        if texture_path is None or mask.sum() < 200:
            continue
        scene = json.loads((spec.mesh_path.parent / "scene.json").read_text(encoding="utf-8"))
        (polygon,) = [o["polygon_px"] for o in scene["objects"] if o["object_id"] == spec.object_id]
        photo = np.asarray(Image.open(texture_path).convert("RGB"), dtype=float)
        rows, cols = np.mgrid[0 : photo.shape[0], 0 : photo.shape[1]]
        centres = np.column_stack((cols.ravel() + 0.5, rows.ravel() + 0.5))
        inside = PolygonPath(np.asarray(polygon)).contains_points(centres)
        expected = photo.reshape(-1, 3)[inside].mean(axis=0)
        seen = gl_frame.rgb[mask].astype(float).mean(axis=0)
        shade = float(seen @ expected / (expected @ expected))
        assert 0.5 <= shade <= 1.05, (truth.id, seen, expected)
        assert np.abs(seen - shade * expected).max() <= 12.0, (truth.id, seen, expected)
        checked += 1
    if not checked:
        pytest.skip("the built-in sample has no textures")
    assert checked >= 5


def test_noise_comes_from_the_generator_passed_in(sample_twin: Twin) -> None:
    require_gl()
    with CameraRig(sample_twin, renderer="gl") as rig:
        clean = rig.capture(SPEC)
        a = rig.capture(SPEC, rng=np.random.default_rng(1))
        b = rig.capture(SPEC, rng=np.random.default_rng(1))
    np.testing.assert_array_equal(a.depth_m, b.depth_m)
    np.testing.assert_array_equal(a.rgb, clean.rgb)
    both = np.isfinite(a.depth_m) & np.isfinite(clean.depth_m)
    error = a.depth_m[both] - clean.depth_m[both]
    assert 0.001 < float(np.std(error)) < 0.01  # 0.5 mm + 1.5 mm/m^2 at 1.2 to 2 m
    assert np.isnan(a.depth_m).sum() > np.isnan(clean.depth_m).sum()


def test_a_new_episode_is_followed(builtin_meshes: Path) -> None:
    """After ``reset`` the objects are new bodies with ids from 1 again: the rig sees them."""
    require_gl()
    scenario = Scenario(
        name="camera", duration_s=5.0, system=SystemLevel(belt_speed_mps=0.4, prefill_m=1.2)
    )
    with Twin(scenario, dataset_dir=builtin_meshes, perception_enabled=False) as twin:
        twin.reset(seed=1)
        with CameraRig(twin) as rig:
            rig.capture(SPEC)
            for _ in range(240):  # 1 s: the belt moves the pieces about 0.4 m on
                twin.advance()
            moved = rig.capture(SPEC)
            twin.reset(seed=2)
            again = rig.capture(SPEC)
            expected = in_view(twin)
            live = {t.id for t in twin.observe_objects()}
    assert again.instance_ids is not None
    assert moved.instance_ids is not None
    drawn = set(np.unique(again.instance_ids).tolist()) - {0}
    assert len(expected) >= 5
    assert expected <= drawn <= live
    assert iou(again.instance_ids > 0, moved.instance_ids > 0) < 0.5


def test_without_egl_the_camera_falls_back_and_says_so_once() -> None:
    """A process whose EGL finds no driver (no vendor file) renders with TinyRenderer and
    says so in one line on stderr, however often it asks."""
    env = {**os.environ, "__EGL_VENDOR_LIBRARY_FILENAMES": "/nonexistent/egl_vendor.json"}
    code = (
        "from twin.camera.choose import choose_renderer\n"
        "print(choose_renderer('auto'), choose_renderer('auto'), choose_renderer('tiny'))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    assert done.stdout.split() == ["tiny", "tiny", "tiny"]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "TinyRenderer" in lines[0]
    assert "libegl1" in lines[0]


def test_an_unknown_renderer_or_a_closed_rig_is_refused(sample_twin: Twin) -> None:
    with pytest.raises(RenderError, match="renderer = 'vulkan'"):
        CameraRig(sample_twin, renderer="vulkan")
    rig = CameraRig(sample_twin, renderer="tiny")
    rig.close()
    with pytest.raises(RenderError, match="closed"):
        rig.capture(SPEC)
