"""The camera rig: renders a running twin's cameras into :class:`interfaces.camera.RgbdFrame`.

The twin is read through :class:`twin.sim_view.CameraSim` (what the rig needs of it; a
:class:`twin.sim.Twin` is one), so the cameras do not depend on the sim that steps them.

Usage (the twin's stepping loop captures each camera at its rate)::

    rig = CameraRig(twin)                      # after twin.reset(); renderer "auto"
    frame = rig.capture(spec, rng=generator)   # RgbdFrame at twin.time_s, noisy depth
    rig.close()

With the OpenGL renderer (:mod:`twin.camera.gl`) the rig uploads, once each: the belt (near-black
rubber with a faint grain), the floor, the bins (their class's colour), every robot link's
visual (:func:`twin.link_visuals.link_visuals` of its URDF) and every object's mesh when it
first appears (per mesh file and sampled height: the mesh is stretched along z by
``height_m / spec.height_m``, as :meth:`twin.sim.Twin.object_mesh` does). A mesh with texture
coordinates (meshgen's OBJ ``vt``, :attr:`meshgen.objfile.ObjMesh.uv`) and a photo
(``texture_path`` of its ``scene.csv`` row, :attr:`twin.objects.ObjectSpec.texture_path`) shows
its photo (one texture per photo, shared by its pieces); any other is drawn in its class's
colour (the class table's, the episode cell's ``materials``: :mod:`interfaces.materials`) with
a procedural grain. Per frame only poses change: one PyBullet query per object, one
``getLinkStates`` per robot, then one draw call per instance.

With the fallback (:mod:`twin.camera.tiny`) PyBullet draws its own scene: the rig paints the
belt, floor, bins and every object (on first sight) in the same colours, and maps PyBullet's
body ids to object ids.

A new episode (``twin.reset()``) is noticed at the next capture; uploaded meshes and textures
are kept across episodes (keyed by file).
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

import numpy as np
import pybullet as pb

from interfaces.camera import RgbdCameraSpec, RgbdFrame
from interfaces.class_colours import RGB, class_colour
from twin.camera.choose import Renderer, choose_renderer
from twin.camera.depth_noise import noisy_depth
from twin.camera.errors import RenderError
from twin.camera.gl import GlRenderer, PendingImages
from twin.camera.render_types import CameraView, Instance, MeshData, RenderedImages
from twin.camera.textures import GRAIN_PERIOD_M, grain_texture, read_rgb_image
from twin.camera.tiny import TinyRenderer
from twin.camera.twin_scene import (
    RobotLinks,
    SceneObject,
    TwinObjects,
    belt_triangles,
    bins_triangles,
    floor_triangles,
    world_bodies,
)
from twin.objects import read_mesh
from twin.sim_view import CameraSim

if TYPE_CHECKING:
    from twin.robot import Robot

__all__ = ["BELT_RGB", "FLOOR_RGB", "ROBOT_ID", "CameraRig", "PendingFrame", "Snapshot"]

BELT_RGB: RGB = (0.07, 0.07, 0.075)
"""The belt's colour: near-black rubber, as a real conveyor belt."""

FLOOR_RGB: RGB = (0.42, 0.42, 0.40)
"""The floor's colour: a mid grey concrete."""

ROBOT_ID = -1
"""The id the renderers write for a robot link (:meth:`CameraRig.capture_with_robot` turns it
into the robot's mask; the frame's ``instance_ids`` say 0 there)."""


def _triangle_mesh(
    triangles: np.ndarray, *, texture: Hashable | None = None, rgb: RGB = (1.0, 1.0, 1.0)
) -> MeshData:
    """Unshared vertices of ``triangles`` ``(t, 3, 3)`` as a mesh (planar uv if textured)."""
    vertices = np.asarray(triangles, dtype=float).reshape(-1, 3)
    faces = np.arange(len(vertices)).reshape(-1, 3)
    return MeshData(
        vertices_m=vertices,
        faces=faces,
        texture=texture,
        rgb=rgb,
        planar_period_m=GRAIN_PERIOD_M,
    )


@dataclass(frozen=True, kw_only=True, eq=False)
class Snapshot:
    """The scene at ``stamp_s`` (sim time) as a renderer needs it: with OpenGL every instance
    to draw (meshes uploaded, poses read); with TinyRenderer the PyBullet body of every
    object with its id, and every object's class."""

    stamp_s: float
    instances: tuple[Instance, ...] = ()
    bodies: dict[int, int] = field(default_factory=dict)
    classes: dict[int, str] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True, eq=False)
class PendingFrame:
    """A camera's frame begun (:meth:`CameraRig.begin`): OpenGL's draw in flight, or
    TinyRenderer's images already drawn; stamped with the snapshot's time."""

    spec: RgbdCameraSpec
    stamp_s: float
    drawing: PendingImages | None = None
    drawn: RenderedImages | None = None


class CameraRig:
    """Renders the cameras of one running twin (a :class:`twin.sim_view.CameraSim`, after its
    ``reset``).

    ``renderer`` is ``auto`` (OpenGL when an EGL context can be created, else PyBullet's
    TinyRenderer, said once per process), ``gl`` or ``tiny``.
    """

    def __init__(self, twin: CameraSim, *, renderer: str = "auto") -> None:
        self.twin = twin
        self.renderer: Renderer = choose_renderer(renderer)
        self._gl: GlRenderer | None = GlRenderer() if self.renderer == "gl" else None
        self._tiny: TinyRenderer | None = None
        self._colours = class_colour(twin.cell.materials)
        self._episode: object = None
        self._objects = TwinObjects(twin)
        self._static: list[Instance] = []
        self._robots: list[tuple[RobotLinks, list[Hashable]]] = []
        self._painted: set[int] = set()
        self._obj_files: dict[Path, tuple[np.ndarray, np.ndarray, np.ndarray | None]] = {}
        self._closed = False

    def __enter__(self) -> CameraRig:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Release the renderer's GPU objects; the rig draws nothing more."""
        if self._gl is not None:
            self._gl.close()
            self._gl = None
        self._closed = True

    def _open(self) -> None:
        if self._closed:
            msg = f"the camera rig ({self.renderer}) was closed: make a new one"
            raise RenderError(msg)

    # -- capturing --------------------------------------------------------------------------
    def capture(
        self,
        spec: RgbdCameraSpec,
        *,
        rng: np.random.Generator | None = None,
        snapshot: Snapshot | None = None,
    ) -> RgbdFrame:
        """The frame of camera ``spec`` now (or of ``snapshot``, taken earlier at this step:
        several cameras share one), stamped with its time: colour, depth with the camera's
        noise drawn from ``rng`` (None: no noise, the rendered depth with NaN outside
        ``[depth_min_m, depth_max_m]``), and the object id of every pixel (0 elsewhere)."""
        return self.capture_with_robot(spec, rng=rng, snapshot=snapshot)[0]

    def capture_with_robot(
        self,
        spec: RgbdCameraSpec,
        *,
        rng: np.random.Generator | None = None,
        snapshot: Snapshot | None = None,
    ) -> tuple[RgbdFrame, np.ndarray]:
        """:meth:`capture`, and where a robot link was drawn, ``(H, W) bool``: what a robot
        self-filter (the arm's known pose) removes before detection."""
        taken = snapshot if snapshot is not None else self.snapshot()
        return self.finish(self.begin(spec, taken), rng=rng)

    def begin(self, spec: RgbdCameraSpec, snapshot: Snapshot, *, slot: int = 0) -> PendingFrame:
        """Start drawing camera ``spec``'s frame of ``snapshot`` and return at once (with
        OpenGL: the rasteriser draws while the caller steps on; TinyRenderer draws it here);
        :meth:`finish` makes the frame. Frames in flight together need their own ``slot``."""
        self._open()
        if self._gl is not None:
            pending = self._gl.draw(CameraView.of(spec), snapshot.instances, slot=slot)
            return PendingFrame(spec=spec, stamp_s=snapshot.stamp_s, drawing=pending)
        return PendingFrame(spec=spec, stamp_s=snapshot.stamp_s, drawn=self.draw(spec, snapshot))

    def finish(
        self, pending: PendingFrame, *, rng: np.random.Generator | None = None
    ) -> tuple[RgbdFrame, np.ndarray]:
        """The frame of a :meth:`begin` and its robot pixels (see :meth:`capture_with_robot`),
        its depth noise drawn from ``rng`` now."""
        spec = pending.spec
        if pending.drawing is not None:
            images = GlRenderer.read(pending.drawing)
        else:
            assert pending.drawn is not None
            images = pending.drawn
        robot = images.instance_ids == ROBOT_ID
        images.instance_ids[robot] = 0
        if rng is not None:
            depth = noisy_depth(
                images.depth_m,
                spec.noise,
                rng,
                depth_min_m=spec.depth_min_m,
                depth_max_m=spec.depth_max_m,
            )
        else:
            depth = images.depth_m
            with np.errstate(invalid="ignore"):
                depth[(depth < spec.depth_min_m) | (depth > spec.depth_max_m)] = np.nan
        frame = RgbdFrame(
            camera=spec.name,
            stamp_s=pending.stamp_s,
            rgb=images.rgb,
            depth_m=depth,
            intrinsics=spec.intrinsics,
            worldMoptical=spec.worldMoptical(),
            instance_ids=images.instance_ids,
        )
        return frame, robot

    def render(self, spec: RgbdCameraSpec) -> RenderedImages:
        """The clean images of camera ``spec`` now (no sensor noise; depth NaN only where
        nothing was drawn)."""
        return self.draw(spec, self.snapshot())

    def snapshot(self) -> Snapshot:
        """The scene now: every pose read from PyBullet (one query per object, one per robot)
        and the meshes of new objects uploaded.

        With OpenGL the snapshot holds everything the draw needs, so it may be drawn later
        (off the physics step); TinyRenderer draws PyBullet's scene as it is at the draw."""
        self._open()
        self._follow_episode()
        objects = self._objects.live()
        stamp_s = self.twin.time_s
        if self._gl is None:
            bodies = {s.robot.body: ROBOT_ID for s in self.twin.stations}
            bodies.update({o.body: o.object_id for o in objects})
            return Snapshot(
                stamp_s=stamp_s,
                bodies=bodies,
                classes={o.object_id: o.spec.class_name for o in objects},
            )
        gl = self._gl
        instances: list[Instance] = []  # nearest first: the depth test spares hidden shading
        poses = self._objects.poses(objects)
        for obj, pose in zip(objects, poses, strict=True):
            key = self._object_mesh(gl, obj)
            instances.append(Instance(mesh=key, worldMobject=pose, instance_id=obj.object_id))
        for links, keys in self._robots:
            for key, pose in zip(keys, links.poses(), strict=True):
                instances.append(Instance(mesh=key, worldMobject=pose, instance_id=ROBOT_ID))
        instances.extend(self._static)
        return Snapshot(stamp_s=stamp_s, instances=tuple(instances))

    def draw(self, spec: RgbdCameraSpec, snapshot: Snapshot) -> RenderedImages:
        """The clean images of camera ``spec`` of ``snapshot``."""
        self._open()
        view = CameraView.of(spec)
        if self._gl is not None:
            return self._gl.render(view, snapshot.instances)
        if self._tiny is None:
            self._tiny = TinyRenderer(self.twin.client)
        for body in snapshot.bodies:
            if body not in self._painted and snapshot.bodies[body] != ROBOT_ID:
                class_name = snapshot.classes[snapshot.bodies[body]]
                self._paint(body, self._class_rgb(class_name))
                self._painted.add(body)
        return self._tiny.render(view, snapshot.bodies)

    # -- episodes ---------------------------------------------------------------------------
    def _follow_episode(self) -> None:
        """Rebuild the per-episode state after a ``twin.reset()``."""
        stations = self.twin.stations
        if self._episode is stations:
            return
        if world_bodies(self.twin) is None:
            msg = "the twin has no episode: call twin.reset() before capturing"
            raise RenderError(msg)
        self._episode = stations
        self._objects = TwinObjects(self.twin)
        self._painted = set()
        if self._gl is not None:
            self._static = self._upload_static(self._gl)
            self._robots = [self._upload_robot(self._gl, s.robot) for s in stations]
        else:
            self._paint_static()

    def _class_rgb(self, class_name: str) -> RGB:
        return self._colours(class_name)

    # -- OpenGL -----------------------------------------------------------------------------
    def _upload_static(self, gl: GlRenderer) -> list[Instance]:
        cell = self.twin.cell
        identity = np.eye(4)
        belt = self._grain(gl, "belt", BELT_RGB)
        floor = self._grain(gl, "floor", FLOOR_RGB)
        gl.add_mesh(("static", "belt"), _triangle_mesh(belt_triangles(cell), texture=belt))
        gl.add_mesh(("static", "floor"), _triangle_mesh(floor_triangles(cell), texture=floor))
        keys: list[Hashable] = []
        for i, (class_name, triangles) in enumerate(bins_triangles(cell)):
            key = ("static", "bin", i)
            gl.add_mesh(key, _triangle_mesh(triangles, rgb=self._class_rgb(class_name)))
            keys.append(key)
        keys += [("static", "belt"), ("static", "floor")]  # the floor last: it is farthest
        return [Instance(mesh=key, worldMobject=identity) for key in keys]

    def _upload_robot(self, gl: GlRenderer, robot: Robot) -> tuple[RobotLinks, list[Hashable]]:
        from twin.link_visuals import link_visuals

        links = RobotLinks.of(robot, link_visuals(robot.urdf))
        keys: list[Hashable] = []
        for visual in links.visuals:
            key = ("link", str(robot.urdf), visual.link)
            if not gl.has_mesh(key):
                gl.add_mesh(key, _triangle_mesh(visual.triangles, rgb=visual.rgba[:3]))
            keys.append(key)
        return links, keys

    def _grain(self, gl: GlRenderer, name: str, rgb: RGB) -> str:
        """The key of the grain texture ``name`` in ``rgb``, uploaded on first use."""
        key = f"grain:{name}:{rgb}"
        if not gl.has_texture(key):
            gl.add_texture(key, grain_texture(name, rgb))
        return key

    def _object_mesh(self, gl: GlRenderer, obj: SceneObject) -> Hashable:
        """The key of the object's mesh, uploaded (with its texture) on first use."""
        key = obj.mesh_key
        if gl.has_mesh(key):
            return key
        spec = obj.spec
        vertices, faces, uv = self._read_obj(spec.mesh_path)
        vertices = vertices * np.array([1.0, 1.0, obj.height_m / spec.height_m])
        texture_path: Path | None = getattr(spec, "texture_path", None)
        if uv is not None and texture_path is not None:
            if not gl.has_texture(texture_path):
                gl.add_texture(texture_path, read_rgb_image(texture_path))
            mesh = MeshData(vertices_m=vertices, faces=faces, uv=uv, texture=texture_path)
        else:
            texture = self._grain(gl, spec.class_name, self._class_rgb(spec.class_name))
            mesh = MeshData(
                vertices_m=vertices, faces=faces, texture=texture, planar_period_m=GRAIN_PERIOD_M
            )
        gl.add_mesh(key, mesh)
        return key

    def _read_obj(self, path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """A mesh file's vertices ``(n, 3)``, faces ``(m, 3)`` and uv ``(n, 2)`` or None, read
        once."""
        cached = self._obj_files.get(path)
        if cached is None:
            mesh = read_mesh(path)
            uv = getattr(mesh, "uv", None)
            cached = (mesh.vertices, mesh.faces, None if uv is None else np.asarray(uv))
            self._obj_files[path] = cached
        return cached

    # -- TinyRenderer -----------------------------------------------------------------------
    def _paint(self, body: int, rgb: RGB) -> None:
        client = self.twin.client
        for shape in pb.getVisualShapeData(body, physicsClientId=client):
            pb.changeVisualShape(
                body,
                shape[1],
                rgbaColor=[*rgb, 1.0],
                textureUniqueId=-1,
                physicsClientId=client,
            )

    def _paint_static(self) -> None:
        bodies = world_bodies(self.twin)
        if bodies is None:
            return
        self._paint(bodies.belt, BELT_RGB)
        self._paint(bodies.floor, FLOOR_RGB)
        for body, class_name in bodies.bins:
            self._paint(body, self._class_rgb(class_name))
