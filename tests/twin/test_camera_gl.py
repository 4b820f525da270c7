"""The OpenGL renderer draws where the camera model projects, in metres, with ids and textures.

Geometry, never bytes: masks against footprints projected with :func:`interfaces.camera.project`
and rasterised here (pixel centres inside the polygon), centroids, depths, quadrants.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest
from matplotlib.path import Path as PolygonPath

from interfaces.camera import Intrinsics, RgbdCameraSpec, project
from tests.gl_support import require_gl
from twin.camera.errors import RenderError
from twin.camera.gl import GlRenderer, projection_matrix
from twin.camera.render_types import CameraView, Instance, MeshData
from twin.scene import box_triangles


@pytest.fixture
def gl() -> Iterator[GlRenderer]:
    """A fresh OpenGL renderer, released after the test."""
    require_gl()
    renderer = GlRenderer()
    try:
        yield renderer
    finally:
        renderer.close()


BOX_HALF_M = (0.06, 0.04, 0.025)
"""A 12 x 8 x 5 cm box."""


def box_mesh(half_m: tuple[float, float, float] = BOX_HALF_M, **kwargs: object) -> MeshData:
    triangles = box_triangles(half_m)
    vertices = triangles.reshape(-1, 3)
    return MeshData(vertices_m=vertices, faces=np.arange(len(vertices)).reshape(-1, 3), **kwargs)  # type: ignore[arg-type]


def pose(x: float, y: float, z: float, yaw_rad: float = 0.0) -> np.ndarray:
    m = np.eye(4)
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    m[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    m[:3, 3] = (x, y, z)
    return m


def hull(points: np.ndarray) -> np.ndarray:
    """Convex hull ``(k, 2)`` of 2D points, counter-clockwise (monotone chain)."""
    pts = sorted(map(tuple, points))

    def half(seq: list[tuple[float, float]]) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        for p in seq:
            while len(out) >= 2:
                (ax, ay), (bx, by) = out[-2], out[-1]
                if (bx - ax) * (p[1] - ay) - (by - ay) * (p[0] - ax) > 0:
                    break
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def polygon_mask(polygon_px: np.ndarray, k: Intrinsics) -> np.ndarray:
    """The pixels whose centres lie inside ``polygon_px`` ``(k, 2)`` (u, v)."""
    v, u = np.mgrid[0 : k.height_px, 0 : k.width_px]
    centres = np.column_stack((u.ravel(), v.ravel()))
    return PolygonPath(polygon_px).contains_points(centres).reshape(k.height_px, k.width_px)


def polygon_centroid(polygon_px: np.ndarray) -> np.ndarray:
    """Area centroid ``(2,)`` of a simple polygon (shoelace)."""
    x, y = polygon_px[:, 0], polygon_px[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = cross.sum() / 2.0
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


CAMERAS = {
    "reference, straight down": RgbdCameraSpec(),
    "tilted and turned": RgbdCameraSpec(position_m=(-0.6, 0.35, 1.0), rpy_rad=(0.1, 1.2, 2.7)),
}


@pytest.mark.parametrize("name", list(CAMERAS))
def test_a_box_is_drawn_where_the_camera_model_projects_it(gl: GlRenderer, name: str) -> None:
    spec = CAMERAS[name]
    k, worldMoptical = spec.intrinsics, spec.worldMoptical()  # noqa: N806 (a pose name)
    # the box's centre where the optical axis meets the belt, moved off the axis a little
    axis = worldMoptical[:3, 2]
    origin = worldMoptical[:3, 3]
    hit = origin + axis * (-origin[2] / axis[2])
    world = pose(hit[0] + 0.07, hit[1] - 0.05, BOX_HALF_M[2], yaw_rad=0.4)
    gl.add_mesh("box", box_mesh(rgb=(0.7, 0.3, 0.2)))
    images = gl.render(
        CameraView.of(spec), [Instance(mesh="box", worldMobject=world, instance_id=7)]
    )
    mask = images.instance_ids == 7
    assert set(np.unique(images.instance_ids)) == {0, 7}

    corners = box_triangles(BOX_HALF_M).reshape(-1, 3) @ world[:3, :3].T + world[:3, 3]
    uv, _ = project(corners, k, worldMoptical)
    footprint = hull(uv)
    expected = polygon_mask(footprint, k)
    assert iou(mask, expected) >= 0.95
    rows, cols = np.nonzero(mask)
    centroid = np.array([cols.mean(), rows.mean()])
    assert np.linalg.norm(centroid - polygon_centroid(footprint)) <= 1.0
    # the colour image shows the box on the cleared background, exactly on its mask
    lit = images.rgb.max(axis=2) > 0
    assert iou(lit, mask) >= 0.99


def test_depth_at_a_box_top_is_the_camera_height_minus_the_top(gl: GlRenderer) -> None:
    spec = RgbdCameraSpec()  # straight down from 1.2 m
    top_m = 2 * BOX_HALF_M[2]
    gl.add_mesh("box", box_mesh())
    world = pose(-0.85, 0.45, BOX_HALF_M[2], yaw_rad=0.3)
    images = gl.render(
        CameraView.of(spec), [Instance(mesh="box", worldMobject=world, instance_id=1)]
    )
    top = np.array(
        [
            [sx * BOX_HALF_M[0], sy * BOX_HALF_M[1], BOX_HALF_M[2]]
            for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))
        ]
    )
    uv, depth = project(top @ world[:3, :3].T + world[:3, 3], spec.intrinsics, spec.worldMoptical())
    np.testing.assert_allclose(depth, spec.position_m[2] - top_m)
    inner = polygon_mask(uv, spec.intrinsics)
    inner[1:-1, 1:-1] &= inner[:-2, 1:-1] & inner[2:, 1:-1] & inner[1:-1, :-2] & inner[1:-1, 2:]
    assert inner.sum() > 500
    seen = images.depth_m[inner]
    assert np.abs(seen - (spec.position_m[2] - top_m)).max() <= 0.001
    assert np.isnan(images.depth_m[images.instance_ids == 0]).all()  # nothing else was drawn


def test_nothing_beyond_far_or_behind_the_camera_is_drawn(gl: GlRenderer) -> None:
    spec = RgbdCameraSpec(depth_max_m=1.0)  # the belt at 1.2 m lies beyond
    gl.add_mesh("box", box_mesh())
    images = gl.render(
        CameraView.of(spec),
        [
            Instance(mesh="box", worldMobject=pose(-0.9, 0.5, 0.0), instance_id=3),
            Instance(mesh="box", worldMobject=pose(-0.9, 0.5, 1.5), instance_id=4),  # behind
        ],
    )
    assert not images.instance_ids.any()
    assert np.isnan(images.depth_m).all()


def test_faces_of_different_normals_differ_in_brightness(gl: GlRenderer) -> None:
    spec = RgbdCameraSpec(position_m=(-0.9, 0.1, 0.9), rpy_rad=(0.0, 0.9, 1.3))  # from aside
    gl.add_mesh("box", box_mesh(rgb=(0.8, 0.8, 0.8)))
    world = pose(-0.9, 0.5, BOX_HALF_M[2])
    images = gl.render(
        CameraView.of(spec), [Instance(mesh="box", worldMobject=world, instance_id=1)]
    )
    grey = images.rgb.astype(float).mean(axis=2)[images.instance_ids == 1]
    levels = np.unique(np.round(grey))
    # the top and at least one side face are seen, each flat-shaded: two well-separated levels
    assert grey.size > 1000
    assert levels.max() - levels.min() > 20


def test_a_texture_shows_its_corner_markers_where_the_photo_has_them(gl: GlRenderer) -> None:
    """meshgen's contract: photo pixel (x, y) at uv (x / W, 1 - y / H); belt frame +x along
    image rows (down), +y along columns (right). The camera's rows run along +x and its
    columns along +y, so the render shows the photo upright: the red marker of its top-left
    corner top-left, the blue of its top-right corner top-right."""
    photo = np.full((64, 96, 3), 128, dtype=np.uint8)
    photo[:16, :24] = (255, 0, 0)
    photo[:16, -24:] = (0, 0, 255)
    gl.add_texture("photo", photo)
    length_m, width_m = 0.3, 0.45  # along x (the photo's height), along y (its width)
    x = np.array([-1, 1, 1, -1]) * 0.5 * length_m
    y = np.array([-1, -1, 1, 1]) * 0.5 * width_m
    vertices = np.column_stack((x, y, np.full(4, 0.01)))
    uv = np.column_stack((y / width_m + 0.5, 0.5 - x / length_m))
    gl.add_mesh(
        "plate",
        MeshData(
            vertices_m=vertices, faces=np.array([[0, 1, 2], [0, 2, 3]]), uv=uv, texture="photo"
        ),
    )
    images = gl.render(
        CameraView.of(RgbdCameraSpec()),
        [Instance(mesh="plate", worldMobject=pose(-0.9, 0.5, 0.0), instance_id=1)],
    )
    plate = images.instance_ids == 1
    rows, cols = np.nonzero(plate)
    centre = np.array([rows.mean(), cols.mean()])
    rgb = images.rgb.astype(int)
    red = plate & (rgb[..., 0] > 150) & (rgb[..., 2] < 60)
    blue = plate & (rgb[..., 2] > 150) & (rgb[..., 0] < 60)
    for marker, side in ((red, -1), (blue, 1)):
        assert marker.sum() > 100
        r, c = np.nonzero(marker)
        assert r.mean() < centre[0] - 20  # the top half
        assert (c.mean() - centre[1]) * side > 20  # left for red, right for blue


def test_a_tipped_pieces_sides_show_its_own_material_not_the_photos_outline(
    gl: GlRenderer,
) -> None:
    """A meshgen prism's vertices carry the photo pixels of its outline, where an annotator's
    polygon meets the belt: drawn as they are, its side walls would show that dark streak.
    Seen from aside, the box's sides show the red inside the outline instead; its top keeps
    the photo exactly (the black ring at its edge stays)."""
    photo = np.full((64, 64, 3), (200, 40, 30), dtype=np.uint8)
    photo[:4], photo[-4:], photo[:, :4], photo[:, -4:] = 0, 0, 0, 0  # the outline's dark ring
    gl.add_texture("piece", photo)
    half = BOX_HALF_M
    triangles = box_triangles(half)
    vertices = triangles.reshape(-1, 3)
    uv = np.column_stack(
        (
            0.5 + 0.5 * np.sign(vertices[:, 1]) * (1 - 0.5 / 64),
            0.5 - 0.5 * np.sign(vertices[:, 0]) * (1 - 0.5 / 64),
        )
    )
    mesh = MeshData(
        vertices_m=vertices, faces=np.arange(len(vertices)).reshape(-1, 3), uv=uv, texture="piece"
    )
    gl.add_mesh("box", mesh)
    spec = RgbdCameraSpec(position_m=(-0.9, 0.1, 0.9), rpy_rad=(0.0, 0.9, 1.3))  # from aside
    images = gl.render(
        CameraView.of(spec),
        [Instance(mesh="box", worldMobject=pose(-0.9, 0.5, half[2]), instance_id=1)],
    )
    seen = images.rgb.astype(int)[images.instance_ids == 1]
    assert len(seen) > 1000
    dark = seen.max(axis=1) < 40
    reddish = (seen[:, 0] > 2 * seen[:, 2]) & (seen[:, 0] > 40)
    # the top's own ring is about a sixth of what is seen; drawn from the outline, the sides
    # made it more than a third
    assert dark.mean() < 0.22, "the sides show the outline's dark ring"
    assert reddish.mean() > 0.75
    side = np.repeat(
        np.abs(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])[:, 2])
        < 1e-12,
        3,
    )
    corner_uv = mesh.corner_texture_coordinates()
    np.testing.assert_array_equal(corner_uv[~side], uv[~side].astype(np.float32))
    assert np.abs(corner_uv[side] - 0.5).max() < 0.4  # inside the ring


def test_an_unknown_mesh_or_texture_is_refused_naming_it(gl: GlRenderer) -> None:
    with pytest.raises(RenderError, match="texture 'missing'"):
        gl.add_mesh("box", box_mesh(texture="missing"))
    with pytest.raises(RenderError, match="mesh 'nothing'"):
        gl.render(
            CameraView.of(RgbdCameraSpec()), [Instance(mesh="nothing", worldMobject=np.eye(4))]
        )
    with pytest.raises(RenderError, match="uint8"):
        gl.add_texture("bad", np.zeros((4, 4, 3), dtype=np.float32))


def test_the_projection_puts_points_at_the_pixels_of_the_camera_model() -> None:
    """No OpenGL needed: the matrix itself, against :func:`interfaces.camera.project`."""
    spec = RgbdCameraSpec(
        width_px=320, height_px=200, position_m=(0.1, 0.4, 1.1), rpy_rad=(0.05, 1.4, 3.0)
    )
    view = CameraView.of(spec)
    rng = np.random.default_rng(2)
    points = np.column_stack(
        (rng.uniform(-0.3, 0.3, 30), 0.4 + rng.uniform(-0.3, 0.3, 30), rng.uniform(0, 0.2, 30))
    )
    uv, z = project(points, spec.intrinsics, spec.worldMoptical())
    clip = (
        projection_matrix(view)
        @ np.linalg.inv(spec.worldMoptical())
        @ np.column_stack((points, np.ones(30))).T
    ).T
    ndc = clip[:, :3] / clip[:, 3:]
    np.testing.assert_allclose(clip[:, 3], z)
    np.testing.assert_allclose((ndc[:, 0] + 1) / 2 * 320 - 0.5, uv[:, 0], atol=1e-9)
    np.testing.assert_allclose((ndc[:, 1] + 1) / 2 * 200 - 0.5, uv[:, 1], atol=1e-9)
    near, far = view.near_m, view.far_m
    depth_ndc = (far + near) / (far - near) - 2 * far * near / ((far - near) * z)
    np.testing.assert_allclose(ndc[:, 2], depth_ndc)
