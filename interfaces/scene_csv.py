"""The columns of a meshgen output's tables: the one schema its writer and its readers share.

meshgen writes ``<image_stem>/scene.csv`` (one row per meshed object, :mod:`meshgen.records`)
and ``index.csv`` (one row per image, :mod:`meshgen.pipeline`); the twin reads both
(:mod:`twin.objects`). Both sides take the column names from here. Values only; free of both.
"""

from __future__ import annotations

SCENE_FLOAT_COLUMNS: tuple[str, ...] = (
    "centroid_x_m",
    "centroid_y_m",
    "yaw_rad",
    "length_m",
    "width_m",
    "area_m2",
    "height_m",
    "volume_m3",
    "mass_kg",
)
"""The numeric columns of ``scene.csv`` a reader needs (belt-frame pose, size, mass)."""

SCENE_COLUMNS: tuple[str, ...] = (
    "object_id",
    "source_image",
    "class_id",
    "class_name",
    *SCENE_FLOAT_COLUMNS,
    "mesh_path",
    "convex_path",
    "n_convex_pieces",
    "area_change_ratio",
    "repairs",
    "texture_path",
    "height_source",
)
"""Columns of ``<image_stem>/scene.csv``, in order.

``texture_path`` is the piece's texture relative to the scene folder (like ``mesh_path``;
empty when meshgen wrote none, ``--no-textures``); ``height_source`` is ``image`` (from a
height image, ``--heights``) or ``sampled`` (seeded, from the class table)."""

SCENE_REQUIRED_COLUMNS: tuple[str, ...] = (
    "object_id",
    "source_image",
    "class_name",
    *SCENE_FLOAT_COLUMNS,
    "mesh_path",
    "convex_path",
)
"""The columns of ``scene.csv`` a reader cannot do without (the rest are optional: an older
output lacks ``texture_path``)."""

INDEX_COLUMNS: tuple[str, ...] = (
    "image",
    "width_px",
    "height_px",
    "m_per_px",
    "objects",
    "skipped",
    "scene_csv",
)
"""Columns of ``index.csv``, in order."""

INDEX_REQUIRED_COLUMNS: tuple[str, ...] = (
    "image",
    "width_px",
    "height_px",
    "m_per_px",
    "scene_csv",
)
"""The columns of ``index.csv`` a reader cannot do without."""


__all__ = [
    "INDEX_COLUMNS",
    "INDEX_REQUIRED_COLUMNS",
    "SCENE_COLUMNS",
    "SCENE_FLOAT_COLUMNS",
    "SCENE_REQUIRED_COLUMNS",
]
