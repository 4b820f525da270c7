"""Synthetic RGB-D frames of boxes on a dark belt, ray-cast exactly: known geometry for tests and
for timing the detector without the twin's renderer.

Each piece is a box (length along its yaw, width across, height up), optionally tilted about its
width axis (its top face then rises along its length) and lifted onto whatever it lies on; each
pixel's ray from the camera is intersected with every box (slab test) and with the belt plane.
Colour is the piece's RGB with a per-pixel speckle (texture), the belt near-black; depth is
optionally degraded like a real sensor (:class:`interfaces.camera.DepthNoise`: Gaussian error
growing with the square of the depth, dropouts on depth edges and at random, quantisation).
Deterministic for a seed. Pure numpy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from interfaces.camera import DepthNoise, RgbdCameraSpec, RgbdFrame, project

BELT_RGB = (28, 28, 30)
"""The belt's colour (near-black rubber)."""


@dataclass(frozen=True, kw_only=True)
class Piece:
    """A box on the belt: footprint centre ``(x_m, y_m)``, ``yaw_rad`` of its length axis,
    extents, ``base_z_m`` (where its lowest point rests), ``tilt_rad`` about its width axis
    (0: level), colour ``rgb`` (0-255) and ``speckle`` (std of the texture, 0-255)."""

    x_m: float
    y_m: float
    yaw_rad: float
    length_m: float
    width_m: float
    height_m: float
    rgb: tuple[int, int, int]
    base_z_m: float = 0.0
    tilt_rad: float = 0.0
    speckle: float = 12.0

    def worldMbox(self) -> np.ndarray:  # noqa: N802 (a pose name, aMb)
        """The box's centre frame in the world (x along its length), ``(4, 4)``."""
        cy, sy = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        ct, st = math.cos(self.tilt_rad), math.sin(self.tilt_rad)
        rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
        ry = np.array([[ct, 0.0, -st], [0.0, 1.0, 0.0], [st, 0.0, ct]])
        rot = rz @ ry
        half = np.array([self.length_m, self.width_m, self.height_m]) / 2
        corners = np.array([[sx, sy_, sz] for sx in (-1, 1) for sy_ in (-1, 1) for sz in (-1, 1)])
        lowest = float((corners * half @ rot.T)[:, 2].min())
        m = np.eye(4)
        m[:3, :3] = rot
        m[:3, 3] = (self.x_m, self.y_m, self.base_z_m - lowest)
        return m

    @property
    def top_z_m(self) -> float:
        """World z of the box's highest point."""
        return (
            self.base_z_m
            + self.length_m * abs(math.sin(self.tilt_rad))
            + self.height_m * abs(math.cos(self.tilt_rad))
        )


def render(
    pieces: Sequence[Piece],
    *,
    camera: RgbdCameraSpec | None = None,
    belt_z_m: float = 0.0,
    noise: DepthNoise | None = None,
    seed: int = 0,
    stamp_s: float = 0.0,
) -> RgbdFrame:
    """One frame of ``pieces`` seen by ``camera`` (default: the shipped overhead camera moved
    over the origin, 1.2 m up); ``noise`` ``None``: exact depth. ``instance_ids`` holds
    ``k + 1`` where ``pieces[k]`` is seen."""
    spec = camera or RgbdCameraSpec(position_m=(0.0, 0.0, 1.2))
    k = spec.intrinsics
    pose = spec.worldMoptical()
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0 : k.height_px, 0 : k.width_px]
    rays = np.stack(
        ((u - k.cx_px) / k.fx_px, (v - k.cy_px) / k.fy_px, np.ones(u.shape)), axis=-1
    ).reshape(-1, 3)
    dirs = rays @ pose[:3, :3].T  # world direction per metre of optical depth
    origin = pose[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        belt_t = (belt_z_m - origin[2]) / dirs[:, 2]
    depth = np.where(belt_t > 0, belt_t, np.inf)
    ids = np.zeros(depth.shape, dtype=np.int32)
    flat_index = np.arange(depth.size).reshape(k.height_px, k.width_px)
    for index, piece in enumerate(pieces, start=1):
        window = _pixel_window(piece, spec)
        if window is None:
            continue
        sel = flat_index[window].ravel()
        t = _box_hits(piece, origin, dirs[sel])
        closer = t < depth[sel]
        depth[sel[closer]] = t[closer]
        ids[sel[closer]] = index
    shape = (k.height_px, k.width_px)
    depth_img = depth.reshape(shape)
    ids_img = ids.reshape(shape)
    rgb = np.empty((*shape, 3), dtype=np.float64)
    rgb[:] = BELT_RGB
    speckle = rng.normal(size=shape)
    for index, piece in enumerate(pieces, start=1):
        sel = ids_img == index
        rgb[sel] = np.asarray(piece.rgb, dtype=np.float64) + piece.speckle * speckle[sel, None]
    rgb += rng.normal(scale=2.0, size=rgb.shape)
    depth_out = np.where(np.isfinite(depth_img), depth_img, np.nan).astype(np.float32)
    if noise is not None:
        depth_out = _degrade(depth_out, noise, rng)
    return RgbdFrame(
        camera=spec.name,
        stamp_s=stamp_s,
        rgb=np.clip(np.round(rgb), 0, 255).astype(np.uint8),
        depth_m=depth_out,
        intrinsics=k,
        worldMoptical=pose,
        instance_ids=ids_img,
    )


def _pixel_window(piece: Piece, spec: RgbdCameraSpec) -> tuple[slice, slice] | None:
    """The image rows and columns the box can cover (its corners' projections, 2 px margin)."""
    m = piece.worldMbox()
    half = np.array([piece.length_m, piece.width_m, piece.height_m]) / 2
    signs = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)])
    corners = (signs * half) @ m[:3, :3].T + m[:3, 3]
    k = spec.intrinsics
    uv, z = project(corners, k, spec.worldMoptical())
    if (z <= 0).any():
        return (slice(0, k.height_px), slice(0, k.width_px))
    c0, r0 = np.floor(uv.min(axis=0)).astype(int) - 2
    c1, r1 = np.ceil(uv.max(axis=0)).astype(int) + 3
    r0, c0 = max(int(r0), 0), max(int(c0), 0)
    r1, c1 = min(int(r1), k.height_px), min(int(c1), k.width_px)
    if r0 >= r1 or c0 >= c1:
        return None
    return (slice(r0, r1), slice(c0, c1))


def _box_hits(piece: Piece, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Optical depth at which each ray enters the box (inf where it misses), ``(n,)``."""
    m = piece.worldMbox()
    rot, centre = m[:3, :3], m[:3, 3]
    o = rot.T @ (origin - centre)
    d = dirs @ rot
    half = np.array([piece.length_m, piece.width_m, piece.height_m]) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - o) / d
        t2 = (half - o) / d
    near = np.nanmax(np.minimum(t1, t2), axis=1)
    far = np.nanmin(np.maximum(t1, t2), axis=1)
    hit = (near <= far) & (far > 0)
    return np.where(hit, np.maximum(near, 0.0), np.inf)


def _degrade(depth: np.ndarray, noise: DepthNoise, rng: np.random.Generator) -> np.ndarray:
    """``depth`` with a real sensor's errors (see :class:`interfaces.camera.DepthNoise`)."""
    z = depth.astype(np.float64)
    std = noise.base_std_m + noise.quadratic_std_per_m * z * z
    out = z + rng.normal(size=z.shape) * np.nan_to_num(std)
    padded = np.pad(z, 1, mode="edge")
    jump = np.zeros(z.shape, dtype=bool)
    for dr, dc in ((0, 1), (2, 1), (1, 0), (1, 2)):
        jump |= np.abs(padded[dr : dr + z.shape[0], dc : dc + z.shape[1]] - z) > noise.edge_jump_m
    drop = (jump & (rng.random(z.shape) < noise.edge_dropout)) | (
        rng.random(z.shape) < noise.dropout
    )
    if noise.quantum_m > 0:
        out = np.round(out / noise.quantum_m) * noise.quantum_m
    out[drop] = np.nan
    return out.astype(np.float32)


def scatter(
    count: int,
    *,
    seed: int = 0,
    area_m: tuple[float, float] = (0.9, 1.2),
    colours: Sequence[tuple[int, int, int]] = ((150, 150, 145), (175, 80, 50), (190, 150, 105)),
) -> list[Piece]:
    """``count`` level boxes of random size, yaw and colour, not overlapping, within
    ``area_m`` (along x, along y) around the origin (fewer when they do not fit)."""
    rng = np.random.default_rng(seed)
    pieces: list[Piece] = []
    placed: list[tuple[float, float, float]] = []
    for _ in range(count * 50):
        if len(pieces) == count:
            break
        length = float(rng.uniform(0.05, 0.16))
        width = float(rng.uniform(0.035, min(length, 0.08)))
        x = float(rng.uniform(-area_m[0] / 2 + 0.08, area_m[0] / 2 - 0.08))
        y = float(rng.uniform(-area_m[1] / 2 + 0.08, area_m[1] / 2 - 0.08))
        radius = 0.5 * math.hypot(length, width)
        if any(math.hypot(x - px, y - py) < radius + pr + 0.01 for px, py, pr in placed):
            continue
        placed.append((x, y, radius))
        pieces.append(
            Piece(
                x_m=x,
                y_m=y,
                yaw_rad=float(rng.uniform(-math.pi / 2, math.pi / 2)),
                length_m=length,
                width_m=width,
                height_m=float(rng.uniform(0.02, 0.06)),
                rgb=colours[int(rng.integers(len(colours)))],
            )
        )
    return pieces


__all__ = ["BELT_RGB", "Piece", "render", "scatter"]
