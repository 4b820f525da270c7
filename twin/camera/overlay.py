"""A rendered frame with its detections drawn on it, as a PNG (for the demo and the report).

:func:`overlay_image` draws each detected instance of a :class:`detector.detector.
DetectorOutput` on the frame's colour image: its mask's outline and bounding box in its class's
colour (the cell's class table, :func:`interfaces.class_colours.class_colour`), and a label
``#k class score`` in white; an instance cut by the image border is drawn in grey.
:func:`write_overlay` writes it atomically (a temporary file in the same folder, then a rename);
:func:`write_twin_overlays` does it for every camera of a running twin (the demo's picture).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image, ImageDraw

from interfaces.camera import RgbdFrame
from twin.camera.errors import RenderError

if TYPE_CHECKING:
    from detector.detector import DetectorOutput
    from twin.sim_view import PerceptionSim

__all__ = ["overlay_image", "write_overlay", "write_twin_overlays"]

BORDER_RGB = (150, 150, 150)
"""The colour of an instance cut by the image border."""


def _edges(mask: np.ndarray) -> np.ndarray:
    """The outline of ``mask`` ``(H, W) bool``: its pixels with a 4-neighbour outside it."""
    inner = mask.copy()
    inner[1:, :] &= mask[:-1, :]
    inner[:-1, :] &= mask[1:, :]
    inner[:, 1:] &= mask[:, :-1]
    inner[:, :-1] &= mask[:, 1:]
    out: np.ndarray = mask & ~inner
    return out


def overlay_image(
    frame: RgbdFrame,
    output: DetectorOutput,
    colour_of: Callable[[str], tuple[float, float, float]] | None = None,
    hidden: np.ndarray | None = None,
) -> Image.Image:
    """``frame``'s colour image ``(H, W, 3) uint8`` with ``output``'s instances drawn on it;
    ``colour_of(class)`` gives a class's colour in [0, 1] (default: white). An instance the
    camera source does not hand on is grey: cut by the border, or ``hidden[label]`` (``(n +
    1,) bool``: touching a robot or a held piece, :func:`twin.camera.filters.occluded_labels`)."""
    rgb = np.asarray(frame.rgb, dtype=np.uint8)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[:2] != output.labels.shape:
        msg = (
            f"frame {frame.camera}: colour {rgb.shape} and labels {output.labels.shape} are not "
            "one image"
        )
        raise RenderError(msg)
    canvas = rgb.copy()
    boxes = []
    for instance in output.instances:
        mask = output.labels == instance.label
        if not mask.any():
            continue
        if instance.at_border or (hidden is not None and hidden[instance.label]):
            colour = BORDER_RGB
        else:
            r, g, b = colour_of(instance.class_name) if colour_of else (1.0, 1.0, 1.0)
            colour = (round(255 * r), round(255 * g), round(255 * b))
        canvas[_edges(mask)] = colour
        rows, cols = np.nonzero(mask)
        box = (int(cols.min()), int(rows.min()), int(cols.max()), int(rows.max()))
        boxes.append((box, colour, f"#{instance.label} {instance.class_name} {instance.score:.2f}"))
    image = Image.fromarray(canvas, mode="RGB")
    draw = ImageDraw.Draw(image)
    for box, colour, text in boxes:
        draw.rectangle(box, outline=colour, width=1)
        x, y = box[0], max(0, box[1] - 11)
        draw.text((x + 1, y + 1), text, fill=(0, 0, 0))
        draw.text((x, y), text, fill=(255, 255, 255))
    return image


def write_overlay(
    path: Path,
    frame: RgbdFrame,
    output: DetectorOutput,
    colour_of: Callable[[str], tuple[float, float, float]] | None = None,
    hidden: np.ndarray | None = None,
) -> Path:
    """Write :func:`overlay_image` as a PNG at ``path`` atomically; returns ``path``."""
    image = overlay_image(frame, output, colour_of, hidden)
    path = Path(path)
    if not path.parent.is_dir():
        msg = f"{path}: its folder {path.parent} does not exist"
        raise RenderError(msg)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            image.save(handle, format="PNG")
        os.chmod(tmp, 0o644)  # mkstemp's 0600 would keep the picture from other readers
        Path(tmp).replace(path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_twin_overlays(twin: PerceptionSim, folder: Path, *, renderer: str = "auto") -> list[Path]:
    """Render every camera of ``twin``'s cell now (after its ``reset``), run its detector
    (:func:`twin.camera.detectors.detectors_for`) on the frame as the camera source filters it
    (:func:`twin.camera.filters.filtered_frame`) and write ``folder/NAME.png`` per camera
    with its detections drawn in their classes' colours; returns the files written."""
    from interfaces.class_colours import class_colour
    from twin.camera.detectors import detectors_for
    from twin.camera.filters import (
        belt_plane_depth,
        filtered_frame,
        occluded_labels,
        occluder_mask,
    )
    from twin.camera.rig import CameraRig

    cameras = twin.cell.cameras
    if not cameras:
        msg = f"the cell {twin.cell.source or twin.cell.name} declares no cameras"
        raise RenderError(msg)
    detectors = detectors_for(
        twin.dataset_dir, belt_z_m=twin.cell.belt.surface_z_m, cameras=cameras
    )
    colours = class_colour(twin.cell.materials)
    held = [truth.id for truth in twin.observe_objects() if truth.held]
    written = []
    with CameraRig(twin, renderer=renderer) as rig:
        snapshot = rig.snapshot()
        for spec, detector in zip(cameras, detectors, strict=True):
            frame, robot = rig.capture_with_robot(spec, snapshot=snapshot)
            belt_depth_m, off_belt = belt_plane_depth(spec, twin.cell.belt)
            occluder = occluder_mask(frame, robot, held_ids=held)
            seen = filtered_frame(frame, occluder | off_belt, belt_depth_m=belt_depth_m)
            output = detector.detect(seen)
            hidden = occluded_labels(output.labels, occluder)
            path = folder / f"{spec.name}.png"
            written.append(write_overlay(path, frame, output, colours, hidden))
    return written
