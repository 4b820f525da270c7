"""The display colour of every waste class: one table for meshes, scene markers, players, pictures.

A dataset names its own classes (COCO, labelme and YOLO files bring theirs), so a colour is a
function of the class name: the four CDW classes have fixed colours (the ones meshgen writes
into a dataset's ``materials.mtl`` by default), any other name gets a stable colour of its
own derived from the name, the same on every machine and in every run. A dataset whose
``materials.mtl`` gives a class another colour (meshgen ``--classes FILE.yaml`` with ``rgb``)
keeps it: :func:`dataset_class_rgb` reads that file.
"""

from __future__ import annotations

import colorsys
import zlib
from pathlib import Path

RGB = tuple[float, float, float]
"""Red, green, blue in [0, 1]."""

CLASS_RGB: dict[str, RGB] = {
    "concrete": (0.62, 0.62, 0.60),
    "brick": (0.70, 0.30, 0.20),
    "wood": (0.76, 0.60, 0.42),
    "rubber": (0.10, 0.10, 0.10),
}
"""The CDW classes' colours: grey concrete, brick red, light-brown wood, near-black rubber."""

MATERIALS_FILE = "materials.mtl"
"""The file in a meshgen output folder that holds each class's colour (``newmtl`` + ``Kd``)."""


def class_rgb(class_name: str, overrides: dict[str, RGB] | None = None) -> RGB:
    """The colour of ``class_name``: ``overrides`` first, then :data:`CLASS_RGB`, else a hue
    taken from the CRC-32 of the name (saturated, mid-bright, so it stands out on the belt)."""
    if overrides and class_name in overrides:
        return overrides[class_name]
    if class_name in CLASS_RGB:
        return CLASS_RGB[class_name]
    hue = (zlib.crc32(class_name.encode("utf-8")) % 360) / 360.0
    red, green, blue = colorsys.hsv_to_rgb(hue, 0.65, 0.85)
    return (round(red, 3), round(green, 3), round(blue, 3))


def rgb_hex(rgb: RGB) -> str:
    """``#rrggbb`` of an RGB triple in [0, 1] (for HTML and SVG)."""
    return "#" + "".join(f"{round(min(max(c, 0.0), 1.0) * 255):02x}" for c in rgb)


def dataset_class_rgb(dataset_dir: Path) -> dict[str, RGB]:
    """Each class's colour as the dataset's ``materials.mtl`` gives it (``{}`` without one).

    Lines other than ``newmtl NAME`` and ``Kd R G B`` are ignored, as are ``Kd`` lines that do
    not hold three numbers: the colour is a display hint, never a reason to refuse a dataset.
    """
    path = Path(dataset_dir) / MATERIALS_FILE
    if not path.is_file():
        return {}
    colours: dict[str, RGB] = {}
    name: str | None = None
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        fields = line.split()
        if len(fields) == 2 and fields[0] == "newmtl":
            name = fields[1]
        elif len(fields) == 4 and fields[0] == "Kd" and name is not None:
            try:
                red, green, blue = (float(v) for v in fields[1:])
            except ValueError:
                continue
            colours[name] = (red, green, blue)
    return colours
