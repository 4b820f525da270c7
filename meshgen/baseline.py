"""The benchmark baseline: the issue's per-object ``trimesh.creation.extrude_polygon`` + export.

Exact definition (``cmd_bench.BASELINE`` repeats it in the bench JSON): dataset discovery,
parsing, the class-table and border checks and the seeded heights are the pipeline's own code.
Per object the baseline then does what a direct implementation of the reference algorithm does:
a shapely polygon from the metric ring, ``make_valid`` (largest polygonal part) when invalid,
topology-preserving ``simplify`` with the same tolerance, ``orient``, shapely area, centroid and
``minimum_rotated_rectangle`` (yaw, length, width), ``trimesh.creation.extrude_polygon`` (earcut
engine), a translation to the centre of mass, and trimesh's own OBJ export written to
``<image_stem>/<object_id>.obj``; one ``scene.csv`` per image with the same columns. Files are
written with the same one-call writer as the pipeline. It writes no convex decomposition, no
scene.json, index, summary, materials or textures (nor texture coordinates) and uses no staging
folder, so it does less than the pipeline and the comparison is conservative for the pipeline.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from meshgen.annotations import Skip
from meshgen.config import MeshgenConfig
from meshgen.export import SCENE_COLUMNS, csv_text, write_text
from meshgen.footprint import pixels_to_belt, touches_border
from meshgen.loaders import discover, load_source
from meshgen.pipeline import class_entry, object_height_m, object_id


def run_baseline(dataset: Path, out: Path, config: MeshgenConfig) -> tuple[int, int, float]:
    """Mesh ``dataset`` into ``out`` the baseline way; return ``(images, objects, elapsed_s)``."""
    import shapely
    import trimesh

    start = time.perf_counter()
    listing = discover(dataset, config.fmt, config.image_size_px)
    table = {spec.name: (i, spec) for i, spec in enumerate(config.classes.classes)}
    images = objects = 0
    skips: list[Skip] = []
    for source in listing.sources:
        ann, file_skips = load_source(source, dataset)
        skips.extend(file_skips)
        if ann is None:
            continue
        images += 1
        folder = out / ann.stem
        folder.mkdir(parents=True, exist_ok=True)
        m_per_px = config.belt_width_m / ann.width_px
        rows: list[tuple[object, ...]] = []
        for poly in ann.polygons:
            entry = table.get(poly.class_name) or class_entry(config, poly.class_name)
            if touches_border(poly.points_px, ann.width_px, ann.height_px, config.border_margin_px):
                continue
            ring_m = pixels_to_belt(poly.points_px, ann.width_px, ann.height_px, m_per_px)
            shape = shapely.Polygon(ring_m)
            if not shape.is_valid:
                parts = [
                    g
                    for g in shapely.get_parts(shapely.make_valid(shape))
                    if isinstance(g, shapely.Polygon)
                ]
                if not parts:
                    continue
                shape = max(parts, key=lambda g: g.area)
            shape = shapely.geometry.polygon.orient(
                shape.simplify(1e-3 * config.simplify_mm, preserve_topology=True)
            )
            if shape.is_empty or shape.area < 1e-6 * config.min_area_mm2:
                continue
            rect = np.asarray(shape.minimum_rotated_rectangle.exterior.coords)
            edges = np.diff(rect, axis=0)[:2]
            lengths = np.hypot(edges[:, 0], edges[:, 1])
            long_axis = edges[int(np.argmax(lengths))]
            yaw = float(np.arctan2(long_axis[1], long_axis[0]))
            class_id, spec = entry
            height = object_height_m(config.seed, ann.stem, poly.index, spec)
            cx, cy = shape.centroid.x, shape.centroid.y
            mesh = trimesh.creation.extrude_polygon(shape, height, engine="earcut")
            mesh.apply_translation((-cx, -cy, -0.5 * height))
            name = object_id(ann.stem, poly.index)
            text = trimesh.exchange.obj.export_obj(  # type: ignore[no-untyped-call]
                mesh, include_normals=False, include_texture=False
            )
            write_text(folder / f"{name}.obj", text)
            area = shape.area
            volume = area * height
            rows.append(
                (
                    name,
                    ann.source,
                    class_id,
                    spec.name,
                    cx,
                    cy,
                    yaw,
                    float(lengths.max()),
                    float(lengths.min()),
                    area,
                    height,
                    volume,
                    volume * spec.density_kg_m3,
                    f"{name}.obj",
                    "",
                    1,
                    1.0,
                    "",
                    "",
                    "sampled",
                )
            )
            objects += 1
        write_text(folder / "scene.csv", csv_text(SCENE_COLUMNS, rows))
    return images, objects, time.perf_counter() - start
