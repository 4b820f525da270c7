"""The meshing pipeline: dataset folder in, metric proxy meshes, scene CSVs and an index out.

Output layout (the twin reads it)::

    OUT/.cdw-meshgen                   marker: a complete meshgen output (see ``meshgen.outdir``)
    OUT/index.csv                      one row per image (see ``export.INDEX_COLUMNS``)
    OUT/summary.json                   counts, skips by reason, timings, config
    OUT/materials.mtl                  one material per class
    OUT/classes.yaml                   the class table it was meshed with: the classes it has
                                       pieces of, in the table's order, and the default
                                       (:func:`interfaces.materials.dataset_table` reads it)
    OUT/<stem>/scene.csv               one row per object (see ``export.SCENE_COLUMNS``)
    OUT/<stem>/scene.json              full per-object metadata
    OUT/<stem>/<object_id>.obj         the prism mesh, centre of mass at the origin, with texture
                                       coordinates into the image's texture
    OUT/<stem>/<object_id>_convex.obj  concave footprints only: one ``o piece_k`` per convex piece
    OUT/<stem>/texture.jpg             the image's texture: its photo, else procedural

``object_id`` is ``<stem>_<k:03d>`` with ``k`` the polygon's index in its source file. Frames
are documented in :mod:`meshgen.footprint` (belt frame) and :mod:`meshgen.mesh` (mesh frame).
Heights come from ``numpy.random.default_rng([seed, crc32(stem), k])``, so they do not depend on
workers or on other objects, and equal seeds give byte-identical mesh, CSV and scene files;
with ``--heights`` they come from height images where there are some (:mod:`meshgen.heights`).
Textures: :mod:`meshgen.textures`; texture coordinates: :mod:`meshgen.imageframe`.

``OUT`` is replaced whole by a finished run, and only when it is empty or an earlier meshgen
output (the rules are in :mod:`meshgen.outdir`). An interrupted run (Ctrl-C) leaves ``OUT`` as
it was and raises :class:`RunInterrupted`, which carries the summary of the images finished.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
import zlib
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from interfaces.materials import DATASET_TABLE, MTL_FILE, ClassTable
from meshgen.annotations import (
    SKIP_REASONS,
    WARNING_REASONS,
    FloatArray,
    ImageAnnotation,
    Notice,
    RawPolygon,
    Skip,
)
from meshgen.classes import ClassSpec
from meshgen.config import MeshgenConfig
from meshgen.export import (
    INDEX_COLUMNS,
    SCENE_COLUMNS,
    FileSink,
    ThreadedFileSink,
    csv_text,
    mtl_text,
    write_json,
    write_text,
)
from meshgen.footprint import (
    Footprint,
    FootprintRejected,
    build_footprints,
)
from meshgen.heights import height_index, measured_heights_m
from meshgen.imageframe import rings_uv
from meshgen.interrupts import deferred_interrupts, ignore_interrupts
from meshgen.loaders import DatasetListing, ImageSource, discover, load_source
from meshgen.mesh import clear_text_caches
from meshgen.outdir import (
    check_location,
    check_replaceable,
    output_error,
    staging_dir,
    staging_path,
    swap_in,
)
from meshgen.prisms import prism_texts
from meshgen.ragged import split_rows
from meshgen.records import EntryExtras, ObjectRecord, csv_row, objects_json_text
from meshgen.seeding import first_doubles, pcg64_first_double
from meshgen.textures import TEXTURE_NAME, Texture, image_texture


@dataclass(frozen=True, slots=True, kw_only=True)
class ImageResult:
    """What meshing one image produced: its index row, records, skips and notices.

    ``texture`` is where its texture came from (``photo``, ``procedural``, or ``""`` when none
    was written).
    """

    stem: str
    width_px: int
    height_px: int
    m_per_px: float
    records: tuple[ObjectRecord, ...]
    skips: tuple[Skip, ...]
    notices: tuple[Notice, ...] = ()
    texture: str = ""


@dataclass(frozen=True, slots=True, kw_only=True)
class DatasetSummary:
    """Result of :func:`mesh_dataset`; ``to_json`` is summary.json.

    ``complete`` is False for the summary an interrupted run carries (:class:`RunInterrupted`):
    the counts are those of the images finished before the interrupt, and nothing was written.
    """

    out: Path
    fmt: str
    images: int
    objects: int
    skips: tuple[Skip, ...]
    elapsed_s: float
    workers: int
    config: MeshgenConfig
    complete: bool = True
    notices: tuple[Notice, ...] = ()
    textures: tuple[tuple[str, int], ...] = ()
    height_sources: tuple[tuple[str, int], ...] = ()
    classes: tuple[tuple[str, int], ...] = ()
    """The classes meshed (class, pieces): those the table names in its order, then those it
    does not (meshed with its default) in the order first met."""

    @property
    def table(self) -> ClassTable:
        """The class table the output was meshed with, as ``classes.yaml`` records it: the
        classes meshed (:attr:`classes`) with their entries, and the default."""
        return self.config.classes.restricted(name for name, _ in self.classes)

    @property
    def skipped(self) -> dict[str, int]:
        """Number of skips by reason (reasons that occurred only, sorted)."""
        return dict(sorted(Counter(s.reason for s in self.skips).items()))

    @property
    def warned(self) -> dict[str, int]:
        """Number of notices (warnings) by reason (reasons that occurred only, sorted)."""
        return dict(sorted(Counter(n.reason for n in self.notices).items()))

    @property
    def ms_per_image(self) -> float:
        """Wall-clock milliseconds per processed image (whole run, everything included)."""
        return 1e3 * self.elapsed_s / self.images if self.images else 0.0

    @property
    def ms_per_object(self) -> float:
        """Wall-clock milliseconds per meshed object (whole run, everything included)."""
        return 1e3 * self.elapsed_s / self.objects if self.objects else 0.0

    def to_json(self) -> dict[str, Any]:
        """The summary as plain JSON data."""
        return {
            "out": str(self.out),
            "format": self.fmt,
            "images": self.images,
            "objects": self.objects,
            "skipped": self.skipped,
            "skipped_total": len(self.skips),
            "skips": [
                {"file": s.file, "where": s.where, "reason": s.reason, "detail": s.detail}
                for s in self.skips
            ],
            "skip_reasons": {r: SKIP_REASONS[r] for r in self.skipped},
            "warnings": [
                {"file": n.file, "where": n.where, "reason": n.reason, "detail": n.detail}
                for n in self.notices
            ],
            "warned": self.warned,
            "warning_reasons": {r: WARNING_REASONS[r] for r in self.warned},
            "textures": dict(self.textures),
            "height_sources": dict(self.height_sources),
            "classes": dict(self.classes),
            "elapsed_s": round(self.elapsed_s, 6),
            "ms_per_image": round(self.ms_per_image, 4),
            "ms_per_object": round(self.ms_per_object, 4),
            "workers": self.workers,
            "config": self.config.to_json(),
        }


def _pcg64_first_double(seed_key: list[int]) -> float:
    """First ``random()`` double of ``numpy.random.default_rng(seed_key)``, computed directly.

    numpy's own ``SeedSequence`` gives the four state words; the PCG64 step is
    :func:`meshgen.seeding.pcg64_first_double`, which saves constructing a ``Generator``. The
    pipeline uses the batched :func:`object_heights_m`; this one-key form serves
    :func:`object_height_m` (and so the baseline).
    """
    words: list[int] = np.random.SeedSequence(seed_key).generate_state(4, np.uint64).tolist()
    return pcg64_first_double((words[0], words[1], words[2], words[3]))


def object_height_m(seed: int, stem: str, index: int, spec: ClassSpec) -> float:
    """Height of object ``index`` of image ``stem``: uniform in the class range, seeded.

    Equal to ``numpy.random.default_rng([seed, crc32(stem), index]).uniform(lo, hi)``
    (tests check this against numpy).
    """
    key = [seed, zlib.crc32(stem.encode()), index]
    low, high = spec.height_min_m, spec.height_max_m
    return low + (high - low) * _pcg64_first_double(key)


def object_heights_m(seed: int, objects: list[tuple[str, int, ClassSpec]]) -> list[float]:
    """:func:`object_height_m` of many ``(stem, index, spec)`` objects, seeded in one batch."""
    crcs = {stem: zlib.crc32(stem.encode()) for stem, _, _ in objects}
    keys = [[seed, crcs[stem], index] for stem, index, _ in objects]
    return [
        spec.height_min_m + (spec.height_max_m - spec.height_min_m) * u
        for (_, _, spec), u in zip(objects, first_doubles(keys), strict=True)
    ]


UNNAMED_CLASS_ID = -1
"""The ``class_id`` of a piece whose class the class table does not name (meshed with the
table's ``default`` entry)."""


def class_entry(config: MeshgenConfig, class_name: str) -> tuple[int, ClassSpec]:
    """The ``class_id`` and table entry of ``class_name``: its position in ``config.classes``,
    or :data:`UNNAMED_CLASS_ID` and the table's default under its name
    (:meth:`interfaces.materials.ClassTable.material`)."""
    table = config.classes
    for index, spec in enumerate(table.classes):
        if spec.name == class_name:
            return index, spec
    return UNNAMED_CLASS_ID, table.material(class_name)


def _skip(ann: ImageAnnotation, poly: RawPolygon, reason: str, detail: str) -> Skip:
    return Skip(file=ann.source, where=poly.where, reason=reason, detail=detail)


def object_id(stem: str, index: int) -> str:
    """``<stem>_<index:03d>``: the id of polygon ``index`` of source file ``stem``."""
    return f"{stem}_{index:03d}"


def _record(
    ann: ImageAnnotation,
    poly: RawPolygon,
    *,
    fp: Footprint,
    cls: tuple[int, ClassSpec],
    height: float,
    n_pieces: int,
    texture_path: str,
    height_source: str,
) -> ObjectRecord:
    """The scene record of one meshed footprint (``n_pieces`` > 1 means it has convex pieces).

    ``cls`` is the class's id and table entry.
    """
    class_id, spec = cls
    name = object_id(ann.stem, poly.index)
    cx, cy = fp.centroid_m
    volume = fp.area_m2 * height
    return ObjectRecord(
        object_id=name,
        source_image=ann.source,
        class_id=class_id,
        class_name=spec.name,
        centroid_x_m=cx,
        centroid_y_m=cy,
        yaw_rad=fp.yaw_rad,
        length_m=fp.length_m,
        width_m=fp.width_m,
        area_m2=fp.area_m2,
        height_m=height,
        volume_m3=volume,
        mass_kg=volume * spec.density_kg_m3,
        mesh_path=f"{name}.obj",
        convex_path="" if fp.convex else f"{name}_convex.obj",
        n_convex_pieces=n_pieces,
        area_change_ratio=fp.area_change_ratio,
        repairs=fp.repairs,
        texture_path=texture_path,
        height_source=height_source,
    )


def _select(
    anns: list[ImageAnnotation], config: MeshgenConfig
) -> tuple[
    list[list[tuple[int, Skip]]],
    list[tuple[int, int, RawPolygon, int, ClassSpec]],
    list[FloatArray],
]:
    """Class and border checks of every polygon of ``anns``; metric rings of the ones kept.

    Returns per image its early skips (with the polygon position), the kept polygons as
    ``(image, position, polygon, class_id, spec)`` and their ``(n, 2)`` belt-frame rings.
    """
    table = {spec.name: (i, spec) for i, spec in enumerate(config.classes.classes)}
    margin = config.border_margin_px
    skips: list[list[tuple[int, Skip]]] = [[] for _ in anns]
    todo: list[tuple[int, int, RawPolygon, int, ClassSpec]] = []
    for img, ann in enumerate(anns):
        for pos, poly in enumerate(ann.polygons):
            class_id, spec = table.get(poly.class_name) or class_entry(config, poly.class_name)
            todo.append((img, pos, poly, class_id, spec))
    if not todo:
        return skips, [], []
    sizes = np.fromiter((len(t[2].points_px) for t in todo), dtype=np.int64, count=len(todo))
    starts = np.cumsum(sizes) - sizes
    pts = np.concatenate([t[2].points_px for t in todo])
    dims = np.array([(anns[t[0]].width_px, anns[t[0]].height_px) for t in todo], dtype=np.float64)
    lo = np.minimum.reduceat(pts, starts)
    hi = np.maximum.reduceat(pts, starts)
    near = (lo <= margin) | (hi >= dims - 1.0 - margin)
    border = np.logical_or(near[:, 0], near[:, 1])
    scale = config.belt_width_m / dims[:, 0]
    per_point = np.repeat(np.concatenate((dims, scale[:, None]), axis=1), sizes, axis=0)
    metric = np.empty_like(pts)
    metric[:, 0] = (pts[:, 1] - 0.5 * per_point[:, 1]) * per_point[:, 2]
    metric[:, 1] = (pts[:, 0] - 0.5 * per_point[:, 0]) * per_point[:, 2]
    rings = split_rows(metric, sizes)
    kept: list[tuple[int, int, RawPolygon, int, ClassSpec]] = []
    kept_rings: list[FloatArray] = []
    cuts = [bool(c) for c in border.tolist()]
    for item, ring, cut in zip(todo, rings, cuts, strict=True):
        if cut:
            img, pos, poly = item[0], item[1], item[2]
            detail = f"a vertex lies within {margin:g} px of the image border"
            skips[img].append((pos, _skip(anns[img], poly, "border_truncated", detail)))
            continue
        kept.append(item)
        kept_rings.append(ring)
    return skips, kept, kept_rings


def _texture_json(texture: Texture | None) -> dict[str, Any] | None:
    """The scene.json ``texture`` entry: the file, where it came from, its size (or None)."""
    if texture is None:
        return None
    return {
        "path": TEXTURE_NAME,
        "source": texture.source,
        "photo": texture.photo,
        "width_px": texture.size_px[0],
        "height_px": texture.size_px[1],
    }


def _scene_json(
    ann: ImageAnnotation,
    config: MeshgenConfig,
    skips: list[Skip],
    objects_json: str,
    *,
    texture: Texture | None,
    notices: list[Notice],
) -> str:
    head = json.dumps(
        {
            "image": ann.stem,
            "source": ann.source,
            "width_px": ann.width_px,
            "height_px": ann.height_px,
            "m_per_px": config.belt_width_m / ann.width_px,
            "belt_width_m": config.belt_width_m,
            "seed": config.seed,
            "up": config.up,
            "frame": "belt: origin image centre, +x image down (travel), +y image right, +z up",
            "skipped": [{"where": s.where, "reason": s.reason, "detail": s.detail} for s in skips],
            "texture": _texture_json(texture),
            "warnings": [
                {"where": n.where, "reason": n.reason, "detail": n.detail} for n in notices
            ],
        },
        sort_keys=True,
        separators=(",", ":"),
    )
    return f'{head[:-1]},"objects":[{objects_json}]}}\n'


_Kept = tuple[tuple[int, int, RawPolygon, int, ClassSpec], Footprint]
"""A polygon kept for meshing (see :func:`_select`) with its footprint."""


def _texture(ann: ImageAnnotation, config: MeshgenConfig) -> Texture:
    """The texture of one image (:func:`meshgen.textures.image_texture`)."""
    return image_texture(
        ann,
        {p.class_name: config.classes.material(p.class_name).colour for p in ann.polygons},
        seed=config.seed,
        belt_width_m=config.belt_width_m,
        max_px=config.texture_max_px,
    )


def mesh_images(
    anns: list[ImageAnnotation],
    config: MeshgenConfig,
    out: Path,
    sink: FileSink | None = None,
    height_images: Mapping[str, Path] | None = None,
) -> list[ImageResult]:
    """Mesh every polygon of several images into ``out / ann.stem`` each.

    Bad polygons become skips. Border checks, metric conversion, footprints
    (:func:`build_footprints`), heights and the mesh texts (:func:`meshgen.prisms.prism_texts`)
    are computed for all polygons of all the images together; then each object's mesh and convex
    pieces are written, one scene.csv and scene.json per image, and (``config.textures``) the
    texture of each image with objects. ``height_images`` maps an image stem to its height
    image (``--heights``). Files go through ``sink`` (default: written right away; the caller
    closes its own sink).
    """
    if sink is None:
        sink = FileSink()
    early, kept, rings = _select(anns, config)
    footprints = (
        build_footprints(
            rings, simplify_m=1e-3 * config.simplify_mm, min_area_m2=1e-6 * config.min_area_mm2
        )
        if rings
        else []
    )
    folders = [os.path.join(out, ann.stem) for ann in anns]
    for folder in folders:
        sink.mkdir(folder)
    records: list[list[ObjectRecord]] = [[] for _ in anns]
    extras: list[list[EntryExtras]] = [[] for _ in anns]
    good: list[_Kept] = [
        (item, fp)
        for item, fp in zip(kept, footprints, strict=True)
        if not isinstance(fp, FootprintRejected)
    ]
    heights = object_heights_m(config.seed, [(anns[t[0]].stem, t[2].index, t[4]) for t, _ in good])
    from_image: list[float | None] = [None] * len(good)
    notices: list[list[Notice]] = [[] for _ in anns]
    if height_images:
        from_image, notices = measured_heights_m(
            anns,
            [(t[0], t[2].where, fp.ring_m) for t, fp in good],
            height_images,
            belt_width_m=config.belt_width_m,
            scale_m=config.height_scale_m,
            percentile=config.height_percentile,
        )
        heights = [h if m is None else m for h, m in zip(heights, from_image, strict=True)]
    texts = prism_texts(
        [fp for _, fp in good],
        heights,
        [t[2].points_px for t, _ in good],
        [object_id(anns[t[0]].stem, t[2].index) for t, _ in good],
        config.up,
        rings_uv(
            [(fp.ring_m, anns[t[0]].width_px, anns[t[0]].height_px) for t, fp in good],
            config.belt_width_m,
        )
        if config.textures
        else None,
    )
    crcs = {ann.stem: zlib.crc32(ann.stem.encode()) for ann in anns}
    made = iter(
        zip(
            heights,
            from_image,
            texts.mesh,
            texts.pieces,
            texts.n_pieces,
            texts.footprint_json,
            texts.polygon_json,
            texts.error,
            strict=True,
        )
    )
    texture_path = TEXTURE_NAME if config.textures else ""
    for (img, pos, poly, class_id, spec), fp in zip(kept, footprints, strict=True):
        ann = anns[img]
        if isinstance(fp, FootprintRejected):
            early[img].append((pos, _skip(ann, poly, fp.reason, fp.detail)))
            continue
        height, measured, mesh, pieces, n_pieces, footprint_json, polygon_json, error = next(made)
        if error:
            early[img].append((pos, _skip(ann, poly, "degenerate", error)))
            continue
        record = _record(
            ann,
            poly,
            fp=fp,
            cls=(class_id, spec),
            height=height,
            n_pieces=n_pieces,
            texture_path=texture_path,
            height_source="sampled" if measured is None else "image",
        )
        header = (
            f"# cdw-twin meshgen {record.object_id}\nmtllib ../materials.mtl\nusemtl {spec.name}\n"
        )
        folder = folders[img]
        sink.write(f"{folder}/{record.mesh_path}", header + mesh)
        if pieces:
            sink.write(f"{folder}/{record.convex_path}", header + pieces)
        records[img].append(record)
        extras[img].append(
            EntryExtras(
                poly.where,
                spec.density_kg_m3,
                (config.seed, crcs[ann.stem], poly.index),
                footprint_json,
                polygon_json,
            )
        )
    results: list[ImageResult] = []
    for img, ann in enumerate(anns):
        early[img].sort(key=lambda item: item[0])
        skips = list(ann.skips) + [s for _, s in early[img]]
        made_image = _MadeImage(records=records[img], extras=extras[img], skips=skips)
        texture = _texture(ann, config) if config.textures and made_image.records else None
        results.append(
            _finish_image(ann, folders[img], made_image, notices[img], texture, config, sink)
        )
    return results


@dataclass(frozen=True, slots=True, kw_only=True)
class _MadeImage:
    """What meshing made of one image: its records with their scene.json extras, its skips."""

    records: list[ObjectRecord]
    extras: list[EntryExtras]
    skips: list[Skip]


def _finish_image(
    ann: ImageAnnotation,
    folder: str,
    made: _MadeImage,
    notices: list[Notice],
    texture: Texture | None,
    config: MeshgenConfig,
    sink: FileSink,
) -> ImageResult:
    """Write one image's texture (when it has one), scene.csv and scene.json."""
    image_notices = list(notices)
    if texture is not None and texture.copy_of is not None:
        sink.copy(texture.copy_of, f"{folder}/{TEXTURE_NAME}")
    elif texture is not None:
        sink.write(f"{folder}/{TEXTURE_NAME}", texture.data)
        if texture.notice is not None:
            image_notices.insert(0, texture.notice)
    header = ",".join(SCENE_COLUMNS) + "\n"
    sink.write(f"{folder}/scene.csv", header + "".join(map(csv_row, made.records)))
    objects_json = objects_json_text(made.records, made.extras, config.seed)
    scene = _scene_json(
        ann, config, made.skips, objects_json, texture=texture, notices=image_notices
    )
    sink.write(f"{folder}/scene.json", scene)
    return ImageResult(
        stem=ann.stem,
        width_px=ann.width_px,
        height_px=ann.height_px,
        m_per_px=config.belt_width_m / ann.width_px,
        records=tuple(made.records),
        skips=tuple(made.skips),
        notices=tuple(image_notices),
        texture="" if texture is None else texture.source,
    )


def mesh_image(ann: ImageAnnotation, config: MeshgenConfig, out: Path) -> ImageResult:
    """Mesh every polygon of one image into ``out / ann.stem``; bad polygons become skips."""
    return mesh_images([ann], config, out)[0]


CHUNK_IMAGES = 32
"""Images meshed together (one batch of vectorised footprint work) per job.

Each batch pays a fixed cost (a few hundred numpy and GEOS calls), so larger batches are
cheaper per object; on the other hand the batches after the first are parsed while the writer
thread is still creating the files of the earlier ones (which matters on a slow file system),
which favours several batches. 32 balances the two (figures in ``docs/benchmarks.md``, meshgen).
"""


_Job = tuple[tuple[ImageSource, ...], Path, MeshgenConfig, Path, dict[str, Path]]
"""One batch: its sources, the dataset, the configuration, the staging folder, the height
images by stem."""


def _process(
    job: _Job,
    sink: FileSink | None = None,
) -> list[tuple[ImageResult | None, list[Skip]]]:
    sources, root, config, staging, height_images = job
    loaded = [load_source(source, root) for source in sources]
    anns = [ann for ann, _ in loaded if ann is not None]
    meshed = iter(mesh_images(anns, config, staging, sink, height_images)) if anns else iter(())
    return [(next(meshed) if ann is not None else None, skips) for ann, skips in loaded]


class RunInterrupted(KeyboardInterrupt):
    """A run stopped by Ctrl-C (or SIGTERM under ``cdw-twin meshgen``).

    ``summary`` counts the images finished before the interrupt (``complete`` False), or is the
    full summary when the interrupt came after the output was already in place.
    """

    def __init__(self, summary: DatasetSummary) -> None:
        super().__init__("meshgen run interrupted")
        self.summary = summary


@dataclass(slots=True, kw_only=True)
class _Run:
    """One :func:`mesh_dataset` run as it goes: what its summary and its clean-up need.

    ``sink`` writes the files of a one-process run (a background writer thread); ``pool`` is
    the worker pool of a multi-process run; ``swapped`` is set once ``out`` holds the result.
    """

    dataset: Path
    out: Path
    staging: Path
    config: MeshgenConfig
    workers: int
    start: float
    listing: DatasetListing
    height_images: dict[str, Path] = field(default_factory=dict)
    results: list[tuple[ImageResult | None, list[Skip]]] = field(default_factory=list)
    sink: FileSink = field(default_factory=FileSink)
    pool: Any = None
    swapped: bool = False


def _summarise(run: _Run, complete: bool) -> tuple[DatasetSummary, list[tuple[object, ...]]]:
    """The summary of the images meshed so far and their ``index.csv`` rows."""
    skips: list[Skip] = list(run.listing.skips)
    notices: list[Notice] = []
    textures: Counter[str] = Counter()
    height_sources: Counter[str] = Counter()
    classes: Counter[str] = Counter()
    rows: list[tuple[object, ...]] = []
    objects = 0
    for result, file_skips in run.results:
        skips.extend(file_skips)
        if result is None:
            continue
        skips.extend(result.skips)
        notices.extend(result.notices)
        objects += len(result.records)
        if result.texture:
            textures[result.texture] += 1
        height_sources.update(r.height_source for r in result.records)
        classes.update(r.class_name for r in result.records)
        rows.append(
            (
                result.stem,
                result.width_px,
                result.height_px,
                result.m_per_px,
                len(result.records),
                len(result.skips),
                f"{result.stem}/scene.csv",
            )
        )
    table = run.config.classes
    ordered = [n for n in table.names if n in classes]
    unnamed = [n for n in classes if not table.names_class(n)]
    notices.extend(_unnamed_notice(table.material(n), classes[n]) for n in unnamed)
    summary = DatasetSummary(
        out=run.out,
        fmt=run.listing.fmt,
        images=len(rows),
        objects=objects,
        skips=tuple(skips),
        elapsed_s=time.perf_counter() - run.start,
        workers=run.workers,
        config=run.config,
        complete=complete,
        notices=tuple(notices),
        textures=tuple(sorted(textures.items())),
        height_sources=tuple(sorted(height_sources.items())),
        classes=tuple((n, classes[n]) for n in (*ordered, *unnamed)),
    )
    return summary, rows


def _unnamed_notice(material: ClassSpec, pieces: int) -> Notice:
    """The warning that a class the table does not name was meshed with its default."""
    detail = (
        f"not in the class table: its {pieces} piece(s) meshed with the table's default "
        f"({material.density_kg_m3:g} kg/m^3, heights {material.height_min_m:g} to "
        f"{material.height_max_m:g} m); name it in --classes FILE.yaml to give its own"
    )
    return Notice(
        file=f"class {material.name!r}", where="", reason="default_material", detail=detail
    )


def _mesh_sources(run: _Run, progress: Callable[[int, int], None] | None) -> None:
    """Mesh the listed images in batches into the staging folder, collecting ``run.results``.

    With several workers the batches go to a process pool (each worker writes its own files);
    otherwise they are meshed here while a writer thread creates the files.
    """
    sources = run.listing.sources
    total = len(sources)
    workers = run.workers
    size = CHUNK_IMAGES if workers <= 1 else max(1, min(CHUNK_IMAGES, total // (4 * workers)))
    jobs: list[_Job] = [
        (sources[i : i + size], run.dataset, run.config, run.staging, run.height_images)
        for i in range(0, total, size)
    ]
    if workers > 1 and len(jobs) > 1:
        from concurrent.futures import ProcessPoolExecutor

        run.pool = ProcessPoolExecutor(max_workers=workers, initializer=ignore_interrupts)
        for chunk in run.pool.map(_process, jobs):
            run.results.extend(chunk)
            if progress is not None:
                progress(len(run.results), total)
        run.pool.shutdown()
    else:
        run.sink = ThreadedFileSink()
        for job in jobs:
            run.results.extend(_process(job, run.sink))
            if progress is not None:
                progress(len(run.results), total)
        run.sink.close()


def _abandon(run: _Run) -> None:
    """Stop the files and workers under way and remove the staging folder (unless swapped)."""
    with deferred_interrupts(redeliver=False):
        run.sink.cancel()
        if run.pool is not None:
            run.pool.shutdown(wait=True, cancel_futures=True)
        if not run.swapped:
            shutil.rmtree(run.staging, ignore_errors=True)


def mesh_dataset(
    dataset: Path,
    out: Path,
    config: MeshgenConfig,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
) -> DatasetSummary:
    """Mesh every image of ``dataset`` into ``out`` (replaced atomically when done).

    ``progress(done, total)`` is called after each batch of images when given. Raises
    :class:`~meshgen.errors.OutputError` before any work when ``out`` may not be replaced or
    cannot be created (:mod:`meshgen.outdir`), and :class:`RunInterrupted` on Ctrl-C, after
    waiting for the files under way and removing the staging folder.
    """
    start = time.perf_counter()
    clear_text_caches()
    out = Path(out).resolve()
    check_location(Path(dataset), out)
    check_replaceable(out)
    run = _Run(
        dataset=Path(dataset),
        out=out,
        staging=staging_path(out),
        config=config,
        workers=workers,
        start=start,
        listing=DatasetListing(fmt=config.fmt, sources=(), skips=()),
    )
    try:
        run.listing = discover(run.dataset, config.fmt, config.image_size_px)
        run.height_images = height_index(config.heights, run.dataset)
        staging_dir(out)
        _mesh_sources(run, progress)
        summary, rows = _summarise(run, complete=True)
        coloured = config.classes.including(name for name, _ in summary.classes)
        write_text(run.staging / MTL_FILE, mtl_text(coloured.classes))
        write_text(run.staging / DATASET_TABLE, summary.table.to_yaml())
        write_text(run.staging / "index.csv", csv_text(INDEX_COLUMNS, rows))
        write_json(run.staging / "summary.json", summary.to_json())
        with deferred_interrupts():
            swap_in(run.staging, out)
            run.swapped = True
    except BaseException as exc:
        _abandon(run)
        if isinstance(exc, KeyboardInterrupt):
            if not run.swapped:
                summary, _ = _summarise(run, complete=False)
            raise RunInterrupted(summary) from exc
        if isinstance(exc, OSError) and str(exc.filename or "").startswith(str(run.staging)):
            raise output_error(out, exc, "write the output") from exc
        raise
    return summary


def tty_progress(done: int, total: int) -> None:
    """Draw a one-line progress bar on stderr (call only when stderr is a terminal)."""
    width = 30
    filled = width * done // max(total, 1)
    end = "\n" if done == total else ""
    print(
        f"\rmeshgen [{'#' * filled}{'.' * (width - filled)}] {done}/{total}",
        end=end,
        file=sys.stderr,
        flush=True,
    )


__all__ = [
    "DatasetSummary",
    "ImageResult",
    "ObjectRecord",
    "RunInterrupted",
    "mesh_dataset",
    "mesh_image",
    "mesh_images",
    "object_height_m",
]
