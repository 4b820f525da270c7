"""The built-in procedural sample: a YOLO-seg dataset of CDW outlines on a 0.6 m belt.

Each image gets 3-7 objects of the four default classes with realistic sizes (bricks and
concrete 6-20 cm, wood strips up to 30 cm long, rubber fragments 4-12 cm), irregular outlines
and, for rubber and some wood, concave ones (L shapes and notched blobs). Every fourth image has
one object cut by the image border. Image sizes alternate between 1024x960 and 990x990 like the
real sample, and each image is written as a small blank grayscale PNG so that its size is read
from the header. Written files: ``data.yaml``, ``images/<stem>.png``, ``labels/<stem>.txt``.
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshgen.errors import OutputError

CLASS_NAMES: tuple[str, ...] = ("concrete", "brick", "wood", "rubber")
SIZES_PX: tuple[tuple[int, int], ...] = ((1024, 960), (990, 990))
BELT_WIDTH_M = 0.6


@dataclass(frozen=True, slots=True, kw_only=True)
class SampleSummary:
    """What :func:`write_sample` wrote."""

    out: Path
    images: int
    objects: int
    border_objects: int


def png_bytes(width_px: int, height_px: int, gray: int = 96) -> bytes:
    """A valid 8-bit grayscale PNG of one flat colour."""
    row = b"\x00" + bytes([gray]) * width_px
    raw = zlib.compress(row * height_px, 9)

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    ihdr = struct.pack(">IIBBBBB", width_px, height_px, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", raw) + chunk(b"IEND", b"")


def _outline(rng: np.random.Generator, cls: str) -> np.ndarray:
    """A closed outline ``(n, 2)`` in metres around the origin for one object of ``cls``."""
    if cls == "wood":
        length, width = rng.uniform(0.12, 0.30), rng.uniform(0.03, 0.07)
        if rng.random() < 0.4:
            leg = rng.uniform(0.4, 0.7) * length
            pts = np.array(
                [
                    [0, 0],
                    [length, 0],
                    [length, width],
                    [leg, width],
                    [leg, 2.5 * width],
                    [leg - width, 2.5 * width],
                    [leg - width, width],
                    [0, width],
                ]
            )
        else:
            pts = np.array([[0, 0], [length, 0], [length, width], [0, width]])
        pts = pts + rng.normal(0, 0.002, pts.shape)
        centred: np.ndarray = pts - pts.mean(axis=0)
        return centred
    radius = {"concrete": (0.04, 0.10), "brick": (0.04, 0.09), "rubber": (0.02, 0.06)}[cls]
    n = int(rng.integers(12, 40))
    theta = np.sort(rng.uniform(0, 2 * math.pi, n))
    r0 = rng.uniform(*radius)
    r = r0 * (1 + 0.15 * rng.standard_normal(n).clip(-2, 2))
    if cls == "rubber" or (cls == "concrete" and rng.random() < 0.3):
        notch = rng.uniform(0, 2 * math.pi)
        d = np.angle(np.exp(1j * (theta - notch)))
        r = r * np.where(np.abs(d) < 0.5, 0.45, 1.0)
    aspect = rng.uniform(0.5, 1.0) if cls == "brick" else rng.uniform(0.7, 1.0)
    return np.stack((r * np.cos(theta), aspect * r * np.sin(theta)), axis=1)


def write_sample(
    out: Path, images: int = 24, seed: int = 0, objects_per_image: tuple[int, int] = (3, 7)
) -> SampleSummary:
    """Write the procedural YOLO-seg sample to ``out`` (created; files replaced atomically).

    Each image holds between ``objects_per_image[0]`` and ``objects_per_image[1]`` objects.
    """
    if images < 1:
        msg = f"--images must be >= 1, got {images}"
        raise OutputError(msg)
    lo, hi = objects_per_image
    if not 1 <= lo <= hi:
        msg = f"objects per image must satisfy 1 <= min <= max, got {objects_per_image}"
        raise OutputError(msg)
    out = Path(out)
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "labels").mkdir(parents=True, exist_ok=True)
    names = "\n".join(f"  {i}: {n}" for i, n in enumerate(CLASS_NAMES))
    _atomic(out / "data.yaml", f"# cdw-twin procedural sample\npath: .\nnames:\n{names}\n".encode())
    rng = np.random.default_rng(seed)
    total = border = 0
    for i in range(images):
        width, height = SIZES_PX[i % len(SIZES_PX)]
        m_per_px = BELT_WIDTH_M / width
        stem = f"sample_{i:03d}"
        lines = []
        n_obj = int(rng.integers(lo, hi + 1))
        for k in range(n_obj):
            cls_id = int(rng.integers(0, len(CLASS_NAMES)))
            pts_m = _outline(rng, CLASS_NAMES[cls_id])
            yaw = rng.uniform(-math.pi, math.pi)
            c, s = math.cos(yaw), math.sin(yaw)
            pts_m = pts_m @ np.array([[c, s], [-s, c]])
            cut = i % 4 == 3 and k == 0
            ext_u = np.ptp(pts_m[:, 0]) / m_per_px
            ext_v = np.ptp(pts_m[:, 1]) / m_per_px
            if cut:
                cu = rng.uniform(0.3, 0.7) * width
                cv = 0.0
            else:
                cu = rng.uniform(ext_u / 2 + 20, width - ext_u / 2 - 20)
                cv = rng.uniform(ext_v / 2 + 20, height - ext_v / 2 - 20)
            px = np.stack((cu + pts_m[:, 0] / m_per_px, cv + pts_m[:, 1] / m_per_px), axis=1)
            px[:, 0] = px[:, 0].clip(0, width - 1)
            px[:, 1] = px[:, 1].clip(0, height - 1)
            norm = px / np.array([width, height])
            coords = " ".join(f"{v:.6f}" for v in norm.ravel())
            lines.append(f"{cls_id} {coords}")
            total += 1
            border += int(cut)
        _atomic(out / "labels" / f"{stem}.txt", ("\n".join(lines) + "\n").encode())
        _atomic(out / "images" / f"{stem}.png", png_bytes(width, height))
    return SampleSummary(out=out, images=images, objects=total, border_objects=border)


def _atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(data)
    tmp.replace(path)
