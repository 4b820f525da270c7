"""``cdw-twin photo``: a dataset's photo beside the twin's render of the pieces meshed from it.

The pieces of one meshgen image folder (its ``scene.json``) are laid out as in the photo
(:func:`detector.bench_perception.lay_out`: each on the belt or on the pieces under it), rendered
by the camera's renderer (OpenGL on EGL, the one the twin's cameras use) from the reference
camera straight above their centre, and the render is cut to the photo's own stretch of belt and
turned so that its rows and columns run as the photo's (+x down, +y right: meshgen's belt frame).
Left the photo (the texture meshgen wrote from it), right the render: how far the two look
apart is what the camera's figures rest on (``docs/camera.md``).

Example::

    cdw-twin photo ~/.cache/cdw-twin/.../meshes --image sample_003 --out photo_vs_render.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from PIL import Image

from interfaces.camera import RgbdCameraSpec, project
from twin.errors import CdwTwinError

__all__ = ["PhotoError", "configure", "photo_and_render", "run"]

GAP_PX = 8
"""White columns between the photo and the render."""


class PhotoError(CdwTwinError):
    """No such image folder, or one without its photo."""


def _belt_corners_m(scene: dict[str, object]) -> np.ndarray:
    """The photo's stretch of belt, its four corners in the belt frame (x down the photo)."""
    width_m = float(scene.get("belt_width_m", 0.6))  # type: ignore[arg-type]
    length_m = width_m * float(scene["height_px"]) / float(scene["width_px"])  # type: ignore[arg-type]
    hx, hy = 0.5 * length_m, 0.5 * width_m
    return np.array([[-hx, -hy], [-hx, hy], [hx, -hy], [hx, hy]])


def _oriented(rgb: np.ndarray, camera: RgbdCameraSpec, centre_m: tuple[float, float]) -> np.ndarray:
    """``rgb`` turned (by quarter turns and flips) so that world +x runs down its rows and +y
    along its columns, as in the photo."""
    origin = np.array([[centre_m[0], centre_m[1], 0.0]])
    ends = origin + np.array([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
    uv, _ = project(np.vstack([origin, ends]), camera.intrinsics, camera.worldMoptical())
    along_x, along_y = uv[1] - uv[0], uv[2] - uv[0]
    out = rgb
    if abs(along_x[0]) > abs(along_x[1]):  # +x runs along the columns: swap the axes
        out = np.transpose(out, (1, 0, 2))
        along_x, along_y = along_x[::-1], along_y[::-1]
    if along_x[1] < 0:
        out = out[::-1]
    if along_y[0] < 0:
        out = out[:, ::-1]
    return np.ascontiguousarray(out)


def photo_and_render(folder: Path) -> np.ndarray:
    """The photo of meshgen image folder ``folder`` and the render of its pieces, side by side
    at the photo's height, ``(H, W, 3) uint8``."""
    from detector.bench_perception import PieceRenderer, lay_out

    scene_path = folder / "scene.json"
    if not scene_path.is_file():
        msg = f"{folder}: no scene.json (a meshgen output's image folder is expected)"
        raise PhotoError(msg)
    scene = json.loads(scene_path.read_text(encoding="utf-8"))
    texture = (scene.get("texture") or {}).get("path")
    if not texture or not (folder / str(texture)).is_file():
        msg = f"{scene_path}: no photo texture (meshed without its photo)"
        raise PhotoError(msg)
    photo = np.asarray(Image.open(folder / str(texture)).convert("RGB"))
    camera = RgbdCameraSpec()
    renderer = PieceRenderer(camera, 0.0)
    try:
        frame = renderer.frame(lay_out(scene_path), np.random.default_rng(0))
    finally:
        renderer.close()
    cx, cy = renderer.centre_m
    corners = np.column_stack([_belt_corners_m(scene) + np.array([cx, cy]), np.zeros(4)])
    uv, _ = project(corners, camera.intrinsics, camera.worldMoptical())
    u0, v0 = np.floor(uv.min(axis=0)).astype(int).clip(0)
    u1, v1 = np.ceil(uv.max(axis=0)).astype(int)
    cut = frame.rgb[v0 : min(v1, camera.height_px), u0 : min(u1, camera.width_px)]
    render = _oriented(cut, camera, (cx, cy))
    height = photo.shape[0]
    scale = height / render.shape[0]
    resized = Image.fromarray(render).resize(
        (max(1, round(render.shape[1] * scale)), height), Image.Resampling.BILINEAR
    )
    gap = np.full((height, GAP_PX, 3), 255, dtype=np.uint8)
    return np.hstack([photo, gap, np.asarray(resized)])


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the command's options."""
    parser.add_argument("dataset", type=Path, help="a meshgen output folder")
    parser.add_argument(
        "--image", default=None, help="its image folder's name (default: the first with a photo)"
    )
    parser.add_argument("--out", type=Path, default=Path("photo_vs_render.png"), help="PNG file")


def run(args: argparse.Namespace) -> int:
    """Write the side-by-side picture; prints its path."""
    from experiments.picture import png_bytes, write_bytes_atomic

    if args.image is not None:
        folder = args.dataset / args.image
    else:
        folders = sorted(p.parent for p in args.dataset.glob("*/scene.json"))
        if not folders:
            msg = f"{args.dataset}: no image folder with a scene.json (is it meshgen's output?)"
            raise PhotoError(msg)
        folder = folders[0]
    picture = photo_and_render(folder)
    try:
        write_bytes_atomic(args.out, png_bytes(picture))
    except OSError as exc:
        msg = f"--out {args.out}: cannot write: {exc.strerror}"
        raise PhotoError(msg) from None
    print(args.out)
    return 0
