"""A headless OpenGL renderer (moderngl on EGL; Mesa's llvmpipe without a GPU): colour, depth
and instance ids of a camera view in one draw.

Meshes and textures are uploaded once (:meth:`GlRenderer.add_mesh`, :meth:`add_texture`); each
frame takes a :class:`~twin.camera.render_types.CameraView` and the instances to draw (a mesh
key, its pose, its id) and sets a few uniforms and one draw call per instance, nothing per
vertex. One pass writes two colour attachments (RGBA8 colour, R32I instance id) and the depth
buffer; depth is linearised from the z-buffer to metres along the optical axis. Draw nearer
things first (pieces, then the belt, then the floor): the depth test then spares the shading of
what they hide.

The projection is built from the pinhole model so that a world point lands where
:func:`interfaces.camera.project` puts it: pixel centres at integer coordinates (OpenGL's are at
half-integers: window x = u + 0.5) and image row ``v`` is framebuffer row ``v`` (read back
bottom-up, so the image comes out top-down without a flip). No multisampling: an id never
blends with its neighbour's. Shading is ambient plus one directional light on flat faces: a
mesh is uploaded with unshared vertices, each carrying its face's normal, and the light is
computed per vertex with the normal turned towards the camera (so faces of different normals
differ in brightness as on a photo, whatever a mesh's winding; on Mesa's software rasteriser
this costs a fifth less than shading every fragment).

The EGL context is created once per process (:func:`gl_context`) and shared by every renderer;
a machine without EGL or Mesa gets :class:`~twin.camera.errors.RenderError` saying why.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from twin.camera.errors import RenderError
from twin.camera.render_types import CameraView, Instance, MeshData, RenderedImages

__all__ = ["GlRenderer", "gl_context", "gl_renderer_name", "projection_matrix"]

_VERTEX_SHADER = """
#version 330
uniform mat4 view_proj;
uniform mat4 model;
uniform vec3 light_dir;
uniform vec3 eye;
uniform float ambient;
in vec3 in_position;
in vec2 in_uv;
in vec3 in_normal;
out vec2 v_uv;
out float v_shade;
void main() {
    vec4 world = model * vec4(in_position, 1.0);
    vec3 n = mat3(model) * in_normal;
    if (dot(n, eye - world.xyz) < 0.0) n = -n;
    v_shade = ambient + (1.0 - ambient) * max(dot(n, light_dir), 0.0);
    v_uv = in_uv;
    gl_Position = view_proj * world;
}
"""

_FRAGMENT_SHADER = """
#version 330
uniform sampler2D albedo;
uniform vec3 tint;
uniform int instance_id;
in vec2 v_uv;
in float v_shade;
layout(location = 0) out vec4 out_colour;
layout(location = 1) out int out_id;
void main() {
    out_colour = vec4(texture(albedo, v_uv).rgb * (tint * v_shade), 1.0);
    out_id = instance_id;
}
"""

LIGHT_DIRECTION = (-0.3, 0.35, 1.0)
"""Towards the light, world frame (normalised on use): from above, a little off the vertical,
so the top face is brightest and the four sides each differ."""

AMBIENT = 0.45
"""The share of brightness a face turned away from the light keeps."""

_CONTEXT: Any = None
_CONTEXT_PID = 0
_CONTEXT_ERROR: str | None = None


def gl_context() -> Any:
    """The process's headless OpenGL 3.3+ context (moderngl on EGL), created on first use.

    Raises :class:`RenderError` with the reason when none can be created (no libEGL, no Mesa
    driver, moderngl missing); the answer is kept, so later calls fail at once. The context is
    current on the thread that created it: render from that thread. A process forked after
    the context was made gets a context of its own.
    """
    global _CONTEXT, _CONTEXT_PID, _CONTEXT_ERROR  # noqa: PLW0603 (one per process, by design)
    if _CONTEXT is not None and os.getpid() == _CONTEXT_PID:
        return _CONTEXT
    if _CONTEXT_ERROR is not None:
        raise RenderError(_CONTEXT_ERROR)
    try:
        import moderngl

        settings: dict[str, Any] = {
            "backend": "egl",
            "libgl": "libGL.so.1",
            "libegl": "libEGL.so.1",
        }
        context = moderngl.create_context(standalone=True, **settings)
        if context.version_code < 330:
            msg = f"OpenGL {context.version_code} is older than the 3.3 the shaders need"
            raise RenderError(msg)
    except Exception as exc:  # ImportError, OSError, moderngl.Error: each means "no GL here"
        _CONTEXT_ERROR = f"no headless OpenGL context (EGL): {type(exc).__name__}: {exc}"
        raise RenderError(_CONTEXT_ERROR) from None
    _CONTEXT, _CONTEXT_PID = context, os.getpid()
    return context


def gl_flush() -> Callable[[], None]:
    """``glFlush`` of the process's GL library (the one the context was made with), which
    hands the commands issued so far to the rasteriser without waiting for it; moderngl has
    only ``finish``, which waits. A no-op where the library cannot be loaded: the read then
    waits for the whole draw."""
    import ctypes

    try:
        flush: Callable[[], None] = ctypes.CDLL("libGL.so.1").glFlush
    except (OSError, AttributeError):
        return lambda: None
    return flush


def gl_renderer_name() -> str:
    """The OpenGL renderer string of the process's context (``llvmpipe (LLVM ...)`` on Mesa's
    software rasteriser)."""
    info = gl_context().info
    return f"{info['GL_RENDERER']}; OpenGL {info['GL_VERSION']}"


def projection_matrix(view: CameraView) -> np.ndarray:
    """The ``(4, 4)`` matrix from optical-frame points to clip coordinates.

    ``x_ndc = 2 (u + 0.5) / W - 1`` and ``y_ndc = 2 (v + 0.5) / H - 1`` for the pixel ``(u, v)``
    :func:`interfaces.camera.project` gives, ``w`` the depth along the optical axis, and
    ``z_ndc`` from -1 at ``near_m`` to 1 at ``far_m``.
    """
    k = view.intrinsics
    w, h = k.width_px, k.height_px
    near, far = view.near_m, view.far_m
    m = np.zeros((4, 4))
    m[0, 0] = 2.0 * k.fx_px / w
    m[0, 2] = (2.0 * k.cx_px + 1.0) / w - 1.0
    m[1, 1] = 2.0 * k.fy_px / h
    m[1, 2] = (2.0 * k.cy_px + 1.0) / h - 1.0
    m[2, 2] = (far + near) / (far - near)
    m[2, 3] = -2.0 * far * near / (far - near)
    m[3, 2] = 1.0
    return m


def linear_depth(
    depth_buffer: np.ndarray, near_m: float, far_m: float, out: np.ndarray | None = None
) -> np.ndarray:
    """Metres along the optical axis ``(H, W) float32`` from z-buffer values in [0, 1]
    (:func:`projection_matrix`'s depth range); NaN where the buffer holds its cleared 1.

    Computed in place in ``out`` (a new array if None): a fresh temporary of a frame's size
    costs more in page faults than the arithmetic.
    """
    buffer = np.asarray(depth_buffer, dtype=np.float32)
    depth = np.empty(buffer.shape, dtype=np.float32) if out is None else out
    # z = 2 f n / ((f + n) - (2 d - 1) (f - n)) = f n / (f - d (f - n))
    np.multiply(buffer, np.float32(far_m - near_m), out=depth)
    np.subtract(np.float32(far_m), depth, out=depth)
    with np.errstate(divide="ignore"):
        np.divide(np.float32(far_m * near_m), depth, out=depth)
    depth[buffer >= 1.0] = np.nan
    return depth


@dataclass
class _Mesh:
    vao: Any
    buffers: tuple[Any, ...]
    texture: Hashable | None
    tint: bytes


@dataclass
class _Target:
    fbo: Any
    buffers: tuple[Any, ...]
    z_buffer: np.ndarray


@dataclass(frozen=True, eq=False)
class PendingImages:
    """A draw in flight (:meth:`GlRenderer.draw`): its framebuffer and view."""

    target: _Target
    view: CameraView


class GlRenderer:
    """Draws uploaded meshes with moderngl into an offscreen framebuffer per image size.

    Keys are any hashable values (the rig uses mesh file paths, link names, ``"belt"``).
    :meth:`close` releases the GPU objects (the shared context stays for the process).
    """

    def __init__(self) -> None:
        import moderngl

        self.ctx = gl_context()
        self._program = self.ctx.program(
            vertex_shader=_VERTEX_SHADER, fragment_shader=_FRAGMENT_SHADER
        )
        self._program["albedo"] = 0
        self._program["ambient"] = AMBIENT
        light = np.asarray(LIGHT_DIRECTION, dtype=float)
        self._program["light_dir"] = tuple(float(v) for v in light / np.linalg.norm(light))
        self._view_proj = self._program["view_proj"]
        self._model = self._program["model"]
        self._tint = self._program["tint"]
        self._id = self._program["instance_id"]
        self._eye = self._program["eye"]
        self._meshes: dict[Hashable, _Mesh] = {}
        self._textures: dict[Hashable, Any] = {}
        self._targets: dict[tuple[int, int, int], _Target] = {}
        self._flush = gl_flush()
        self._white = self.ctx.texture((1, 1), 3, bytes((255, 255, 255)))
        self._moderngl = moderngl

    # -- uploads ----------------------------------------------------------------------------
    def has_texture(self, key: Hashable) -> bool:
        """Whether a texture of this key was uploaded."""
        return key in self._textures

    def add_texture(self, key: Hashable, rgb: np.ndarray) -> None:
        """Upload an image ``(H, W, 3) uint8`` (row 0 at the top, as a photo is stored) as
        the texture ``key``: pixel ``(x, y)`` is at uv ``(x / W, 1 - y / H)``; mipmapped,
        repeating (a tiled procedural texture wraps)."""
        image = np.asarray(rgb)
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            msg = (
                f"texture {key!r}: an (H, W, 3) uint8 image needed, not {image.shape} {image.dtype}"
            )
            raise RenderError(msg)
        limit = int(self.ctx.info["GL_MAX_TEXTURE_SIZE"])
        if max(image.shape[:2]) > limit:
            msg = f"texture {key!r}: {image.shape[1]}x{image.shape[0]} exceeds {limit} px"
            raise RenderError(msg)
        self._release_texture(key)
        flipped = np.ascontiguousarray(image[::-1])  # OpenGL's row 0 is at v = 0 (the bottom)
        texture = self.ctx.texture((image.shape[1], image.shape[0]), 3, flipped.tobytes())
        texture.build_mipmaps()
        texture.filter = (self._moderngl.LINEAR_MIPMAP_LINEAR, self._moderngl.LINEAR)
        texture.repeat_x = texture.repeat_y = True
        self._textures[key] = texture

    def has_mesh(self, key: Hashable) -> bool:
        """Whether a mesh of this key was uploaded."""
        return key in self._meshes

    def add_mesh(self, key: Hashable, mesh: MeshData) -> None:
        """Upload ``mesh`` as ``key`` (replacing one of that key) as unshared vertices with
        their face's normal; its texture, if it names one, must have been uploaded first."""
        if mesh.texture is not None and mesh.texture not in self._textures:
            msg = f"mesh {key!r}: texture {mesh.texture!r} was not uploaded"
            raise RenderError(msg)
        self.remove_mesh(key)
        corners = np.asarray(mesh.faces, dtype=np.int64).reshape(-1)
        vertices = np.asarray(mesh.vertices_m, dtype=np.float64)[corners].reshape(-1, 3, 3)
        normals = mesh.face_normals()
        uv = mesh.corner_texture_coordinates(normals)
        interleaved = np.hstack(
            (vertices.reshape(-1, 3), uv, np.repeat(normals, 3, axis=0))
        ).astype(np.float32)
        vbo = self.ctx.buffer(interleaved.tobytes())
        vao = self.ctx.vertex_array(
            self._program, [(vbo, "3f 2f 3f", "in_position", "in_uv", "in_normal")]
        )
        tint = np.asarray(mesh.rgb, dtype=np.float32).tobytes()
        self._meshes[key] = _Mesh(vao=vao, buffers=(vbo,), texture=mesh.texture, tint=tint)

    def remove_mesh(self, key: Hashable) -> None:
        """Release the mesh ``key`` (nothing if there is none)."""
        old = self._meshes.pop(key, None)
        if old is not None:
            old.vao.release()
            for buffer in old.buffers:
                buffer.release()

    def _release_texture(self, key: Hashable) -> None:
        old = self._textures.pop(key, None)
        if old is not None:
            old.release()

    # -- drawing ----------------------------------------------------------------------------
    def _target(self, width_px: int, height_px: int, slot: int) -> _Target:
        key = (width_px, height_px, slot)
        target = self._targets.get(key)
        if target is None:
            size = (width_px, height_px)
            colour = self.ctx.renderbuffer(size, 4)
            ids = self.ctx.renderbuffer(size, 1, dtype="i4")
            depth = self.ctx.depth_renderbuffer(size)
            fbo = self.ctx.framebuffer(color_attachments=[colour, ids], depth_attachment=depth)
            z_buffer = np.empty((height_px, width_px), dtype=np.float32)
            target = _Target(fbo=fbo, buffers=(colour, ids, depth), z_buffer=z_buffer)
            self._targets[key] = target
        return target

    def render(self, view: CameraView, instances: Sequence[Instance]) -> RenderedImages:
        """Colour, depth and instance ids of ``instances`` seen from ``view``, in one pass."""
        return self.read(self.draw(view, instances))

    def draw(
        self, view: CameraView, instances: Sequence[Instance], *, slot: int = 0
    ) -> PendingImages:
        """Start drawing ``instances`` seen from ``view`` into framebuffer ``slot`` and return
        at once: Mesa's rasteriser threads draw while the caller goes on, :meth:`read` waits
        for them. Until it is read, a slot's images are overwritten by its next draw: give
        each image in flight its own slot."""
        k = view.intrinsics
        target = self._target(k.width_px, k.height_px, slot)
        opticalMworld = np.linalg.inv(np.asarray(view.worldMoptical, dtype=float))  # noqa: N806
        view_proj = projection_matrix(view) @ opticalMworld
        ctx = self.ctx
        target.fbo.use()
        ctx.enable_only(self._moderngl.DEPTH_TEST)
        target.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self._view_proj.write(view_proj.T.astype(np.float32).tobytes())
        self._eye.value = tuple(float(v) for v in view.worldMoptical[:3, 3])
        bound: object = None
        meshes = self._meshes
        for instance in instances:
            mesh = meshes.get(instance.mesh)
            if mesh is None:
                msg = f"instance {instance.instance_id}: mesh {instance.mesh!r} was not uploaded"
                raise RenderError(msg)
            texture = self._white if mesh.texture is None else self._textures[mesh.texture]
            if texture is not bound:
                texture.use(0)
                bound = texture
            self._model.write(np.asarray(instance.worldMobject, dtype=np.float32).T.tobytes())
            self._tint.write(mesh.tint)
            self._id.value = int(instance.instance_id)
            mesh.vao.render()
        self._flush()
        return PendingImages(target=target, view=view)

    @staticmethod
    def read(pending: PendingImages) -> RenderedImages:
        """The three images of a :meth:`draw`, read back (new arrays; the z-buffer into the
        target's scratch)."""
        target, view = pending.target, pending.view
        k = view.intrinsics
        h, w = k.height_px, k.width_px
        rgb = np.empty((h, w, 3), dtype=np.uint8)
        target.fbo.read_into(rgb, components=3, attachment=0)
        ids = np.empty((h, w), dtype=np.int32)
        target.fbo.read_into(ids, components=1, attachment=1, dtype="i4")
        target.fbo.read_into(target.z_buffer, components=1, attachment=-1, dtype="f4")
        return RenderedImages(
            rgb=rgb,
            depth_m=linear_depth(target.z_buffer, view.near_m, view.far_m),
            instance_ids=ids,
        )

    def close(self) -> None:
        """Release every mesh, texture and framebuffer of this renderer."""
        for key in list(self._meshes):
            self.remove_mesh(key)
        for key in list(self._textures):
            self._release_texture(key)
        for target in self._targets.values():
            target.fbo.release()
            for buffer in target.buffers:
                buffer.release()
        self._targets.clear()
        self._white.release()
        self._program.release()
