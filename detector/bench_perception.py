"""``cdw-twin bench perception DATASET --json``: the detector on real photos and on the twin's
renders of the same pieces, side by side.

``DATASET`` is a raw annotated dataset (YOLO-seg with ``data.yaml``/``images``/``labels``, or
what meshgen reads: it is meshed into a temporary folder) or ``builtin`` (the built-in
procedural sample: its photos and its meshgen output). The photos are split by photo, within
each subset (:func:`detector.bench_photos.split_photos`, ``--seed``, ``--train-fraction``): no
photo is on both sides, and both sides use the same split.

- **Real photos** (:func:`detector.bench_photos.bench_photos`): the colour classifier trained on
  the training photos' polygons; the detector on every test photo in **colour** mode (photos
  have no depth) and, where the dataset has height images, in **depth** mode on those; scored
  against the polygons; centroids in pixels of the photo resized to fit 640x480. Annotators
  left small pieces unlabelled: precision counts matched detections and those at least half
  inside a labelled region, the others are reported as unassessed (``precision_all`` counts
  every detection).
- **Rendered** (the twin's renderer, :mod:`twin.camera.gl`, no episode): each test photo's
  meshed pieces laid out as in the photo (meshgen's belt frame: the image centre under the
  camera, which is the cells' reference overhead camera, 640x480 from 1.2 m), stacked in label
  order where their footprints overlap (a later polygon lies on the earlier ones, as the photo's
  rasterised truth assumes), on the twin's dark belt; depth with the camera's sensor noise. The
  colour classifier is the factory's recipe (:mod:`detector.training_set`) on the training
  photos' textures at the camera's scale. The detector runs in **depth** mode (the twin's
  camera) and in **colour** mode on the same frames; truth is the renderer's instance-id image
  (complete: every detection counts for precision), a piece scored when at least
  ``MIN_TRUTH_PX`` of it is visible; centroids in metres (the detection's world centroid
  against the piece's footprint centroid). Pieces meshgen skipped (cut by the photo's border)
  are not rendered.

Recall and precision at mask IoU 0.5, class accuracy over matched pairs, centroid error median
and 90th percentile; the JSON says which mode and source each figure comes from.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from collections.abc import Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw

from detector.bench_photos import bench_photos
from detector.classifier import DEFAULT_L2, ColourClassifier, fit_classifier
from detector.config import DetectorConfig
from detector.detector import Detector
from detector.errors import DatasetError
from detector.score import InstanceSet, PerceptionScorer
from detector.training_set import is_meshgen_output, scene_samples
from interfaces.camera import RgbdCameraSpec, RgbdFrame
from interfaces.fileio import write_atomic

__all__ = [
    "MIN_TRUTH_PX",
    "YAW_ELONGATION",
    "LaidPiece",
    "PieceRenderer",
    "bench_perception",
    "configure",
    "lay_out",
    "run",
]

MIN_TRUTH_PX = 60
"""A rendered piece with fewer visible pixels is not scored (mostly hidden under another)."""

YAW_ELONGATION = 1.2
"""A piece's yaw is scored only when its footprint is at least this much longer than wide."""

STACK_CELL_M = 0.002
"""Grid step of the height map that stacks overlapping footprints."""

BUILTIN = "builtin"


@dataclass(frozen=True, kw_only=True)
class LaidPiece:
    """One meshed piece placed for a render: its mesh file, texture (or None), class, footprint
    centroid ``(x, y)`` in the belt frame (m), the height its mesh has, the height of its
    underside (stacked on the pieces under it) and its footprint's long axis (NaN unless at
    least :data:`YAW_ELONGATION` times longer than wide: a square's axis means nothing)."""

    mesh_path: Path
    texture_path: Path | None
    class_name: str
    centroid_m: tuple[float, float]
    height_m: float
    base_m: float
    yaw_rad: float = math.nan


def _footprint_mask(
    footprint: Sequence[Sequence[float]], origin_m: tuple[float, float], shape: tuple[int, int]
) -> np.ndarray:
    """The cells of the stacking grid a footprint polygon ``(n, 2)`` m covers, ``(h, w) bool``."""
    canvas = Image.new("1", (shape[1], shape[0]), 0)
    points = [
        ((float(y) - origin_m[1]) / STACK_CELL_M, (float(x) - origin_m[0]) / STACK_CELL_M)
        for x, y in footprint
    ]
    if len(points) >= 3:
        ImageDraw.Draw(canvas).polygon(points, fill=1, outline=1)
    return np.asarray(canvas, dtype=bool)


def lay_out(scene_path: Path) -> list[LaidPiece]:
    """The pieces of one meshgen image folder (its ``scene.json``) laid out as in the photo,
    each on the belt or on top of the earlier pieces its footprint overlaps."""
    data = json.loads(scene_path.read_text(encoding="utf-8"))
    objects = data.get("objects") or []
    texture = data.get("texture") or {}
    texture_path = scene_path.parent / str(texture["path"]) if texture.get("path") else None
    belt_w = float(data.get("belt_width_m", 0.6))
    length = belt_w * float(data["height_px"]) / float(data["width_px"])
    origin = (-0.5 * length - 0.05, -0.5 * belt_w - 0.05)
    shape = (int((length + 0.1) / STACK_CELL_M) + 1, int((belt_w + 0.1) / STACK_CELL_M) + 1)
    heights = np.zeros(shape, dtype=np.float64)
    out = []
    for k, obj in enumerate(objects):
        try:
            mask = _footprint_mask(obj["footprint_m"], origin, shape)
            base = float(heights[mask].max()) if mask.any() else 0.0
            height = float(obj["height_m"])
            heights[mask] = base + height
            out.append(
                LaidPiece(
                    mesh_path=scene_path.parent / str(obj["mesh_path"]),
                    texture_path=texture_path if obj.get("texture_path") else None,
                    class_name=str(obj["class_name"]),
                    centroid_m=(float(obj["centroid_x_m"]), float(obj["centroid_y_m"])),
                    height_m=height,
                    base_m=base,
                    yaw_rad=float(obj["yaw_rad"])
                    if float(obj["length_m"]) >= YAW_ELONGATION * float(obj["width_m"])
                    else math.nan,
                )
            )
        except (KeyError, TypeError, ValueError) as exc:
            msg = f"{scene_path}: objects[{k}]: {exc!r}"
            raise DatasetError(msg) from exc
    return out


class PieceRenderer:
    """The twin's OpenGL renderer with a belt, drawing laid-out pieces under one camera."""

    def __init__(self, camera: RgbdCameraSpec, belt_z_m: float) -> None:
        from twin.camera.gl import GlRenderer
        from twin.camera.render_types import MeshData
        from twin.camera.rig import BELT_RGB
        from twin.camera.textures import GRAIN_PERIOD_M, grain_texture

        self.camera = camera
        self.belt_z_m = belt_z_m
        self.centre_m = (camera.position_m[0], camera.position_m[1])
        self.gl = GlRenderer()
        self.gl.add_texture("belt", grain_texture("belt", BELT_RGB))
        x0, y0 = self.centre_m
        half = 3.0
        corners = np.array(
            [
                [x0 - half, y0 - half, belt_z_m],
                [x0 + half, y0 - half, belt_z_m],
                [x0 + half, y0 + half, belt_z_m],
                [x0 - half, y0 + half, belt_z_m],
            ]
        )
        self.gl.add_mesh(
            "belt",
            MeshData(
                vertices_m=corners,
                faces=np.array([[0, 1, 2], [0, 2, 3]]),
                texture="belt",
                planar_period_m=GRAIN_PERIOD_M,
            ),
        )

    def _mesh(self, piece: LaidPiece) -> str:
        from twin.camera.render_types import MeshData
        from twin.camera.textures import read_rgb_image
        from twin.objects import read_mesh

        key = str(piece.mesh_path)
        if self.gl.has_mesh(key):
            return key
        mesh = read_mesh(piece.mesh_path)
        uv = getattr(mesh, "uv", None)
        texture = piece.texture_path
        if uv is not None and texture is not None:
            if not self.gl.has_texture(texture):
                self.gl.add_texture(texture, read_rgb_image(texture))
            data = MeshData(vertices_m=mesh.vertices, faces=mesh.faces, uv=uv, texture=texture)
        else:
            data = MeshData(vertices_m=mesh.vertices, faces=mesh.faces, rgb=(0.5, 0.5, 0.5))
        self.gl.add_mesh(key, data)
        return key

    def frame(self, pieces: Sequence[LaidPiece], rng: np.random.Generator) -> RgbdFrame:
        """The camera's frame of ``pieces`` (instance id ``k + 1`` for ``pieces[k]``), depth
        with the camera's noise from ``rng``."""
        from twin.camera.depth_noise import noisy_depth
        from twin.camera.render_types import CameraView, Instance

        instances = []
        for k, piece in enumerate(pieces, start=1):
            pose = np.eye(4)
            pose[:3, 3] = (
                self.centre_m[0] + piece.centroid_m[0],
                self.centre_m[1] + piece.centroid_m[1],
                self.belt_z_m + piece.base_m + 0.5 * piece.height_m,
            )
            instances.append(Instance(mesh=self._mesh(piece), worldMobject=pose, instance_id=k))
        instances.append(Instance(mesh="belt", worldMobject=np.eye(4)))
        spec = self.camera
        images = self.gl.render(CameraView.of(spec), instances)
        depth = noisy_depth(
            images.depth_m,
            spec.noise,
            rng,
            depth_min_m=spec.depth_min_m,
            depth_max_m=spec.depth_max_m,
        )
        return RgbdFrame(
            camera=spec.name,
            stamp_s=0.0,
            rgb=images.rgb,
            depth_m=depth,
            intrinsics=spec.intrinsics,
            worldMoptical=spec.worldMoptical(),
            instance_ids=images.instance_ids,
        )

    def close(self) -> None:
        """Release the renderer's GPU objects."""
        self.gl.close()


def _truth(frame: RgbdFrame, pieces: Sequence[LaidPiece], centre: tuple[float, float]) -> Any:
    """The frame's scored truth: pieces with at least :data:`MIN_TRUTH_PX` visible pixels, with
    their world footprint centroids."""
    assert frame.instance_ids is not None
    ids = frame.instance_ids.copy()
    counts = np.bincount(ids.ravel(), minlength=len(pieces) + 1)
    small = np.flatnonzero(counts < MIN_TRUTH_PX)
    ids[np.isin(ids, small)] = 0
    classes = {k: p.class_name for k, p in enumerate(pieces, start=1)}
    centroids = {
        k: (centre[0] + p.centroid_m[0], centre[1] + p.centroid_m[1])
        for k, p in enumerate(pieces, start=1)
    }
    yaws = {k: p.yaw_rad for k, p in enumerate(pieces, start=1)}
    return InstanceSet.from_id_image(ids, classes, centroids=centroids, yaws_rad=yaws)


def _render_classifier(
    meshes: Path, stems: Sequence[str], camera: RgbdCameraSpec, belt_z_m: float
) -> ColourClassifier:
    """The factory's recipe on the textures of ``stems`` only, at ``camera``'s scale."""
    from detector.factory import belt_m_per_px
    from detector.training_set import model_class_names

    m_per_px = belt_m_per_px([camera], belt_z_m=belt_z_m)
    parts, labels = [], []
    for stem in stems:
        scene = meshes / stem / "scene.json"
        if not scene.is_file():
            continue
        found = scene_samples(scene, belt_m_per_px=m_per_px, stride=2)
        if found is not None:
            parts.append(found[0])
            labels.extend(found[1])
    if not labels:
        msg = f"{meshes}: no textured piece in the training photos to train on"
        raise DatasetError(msg)
    return fit_classifier(
        np.concatenate(parts),
        labels,
        class_names=model_class_names(meshes, labels),
        l2=DEFAULT_L2,
        training={"photos": list(stems), "instances": len(labels), "source": "textures"},
    )


def _rendered(
    meshes: Path,
    train: Sequence[str],
    test: Sequence[str],
    class_names: Sequence[str],
    *,
    seed: int,
) -> dict[str, Any]:
    """Score the detector on renders of the test photos' pieces (see the module)."""
    camera = RgbdCameraSpec()
    belt_z_m = 0.0
    classifier = _render_classifier(meshes, train, camera, belt_z_m)
    detectors = {
        "depth": Detector(classifier=classifier, belt_z_m=belt_z_m),
        "colour": Detector(
            config=DetectorConfig(mode="colour"), classifier=classifier, belt_z_m=belt_z_m
        ),
    }
    names = tuple(class_names)
    scorers = {m: PerceptionScorer(class_names=names, centroid_unit="m") for m in detectors}
    seconds: dict[str, list[float]] = {m: [] for m in detectors}
    renderer = PieceRenderer(camera, belt_z_m)
    rng = np.random.default_rng(seed)
    frames = pieces_total = 0
    try:
        for stem in test:
            scene = meshes / stem / "scene.json"
            if not scene.is_file():
                continue
            pieces = lay_out(scene)
            if not pieces:
                continue
            frame = renderer.frame(pieces, rng)
            truth = _truth(frame, pieces, renderer.centre_m)
            frames += 1
            pieces_total += len(pieces)
            for mode, detector in detectors.items():
                start = time.process_time()
                output = detector.detect(frame)
                seconds[mode].append(time.process_time() - start)
                scorers[mode].add(output.instance_set(world=True), truth)
    finally:
        renderer.close()
    out: dict[str, Any] = {
        "frames": frames,
        "pieces_rendered": pieces_total,
        "camera": {
            "size": f"{camera.width_px}x{camera.height_px}",
            "hfov_deg": camera.hfov_deg,
            "height_over_belt_m": camera.position_m[2] - belt_z_m,
        },
        "classifier": {
            "trained_on": "textures of the training photos at the camera's scale",
            "samples_per_class": classifier.training.get("samples_per_class"),
        },
        "modes": {},
    }
    for mode, scorer in scorers.items():
        data = scorer.result().to_data()
        data["median_cpu_ms_per_frame"] = (
            round(float(np.median(seconds[mode])) * 1e3, 1) if seconds[mode] else None
        )
        out["modes"][mode] = data
    return out


def _resolve(dataset: str, stack: ExitStack) -> tuple[Path, Path]:
    """The raw photo dataset and its meshgen output (meshed into a temporary folder)."""
    if dataset == BUILTIN:
        from twin.builtin import builtin_dataset

        meshes = builtin_dataset()
        return meshes.parent / "sample", meshes
    raw = Path(dataset)
    if not raw.is_dir():
        msg = f"{raw}: no such dataset folder (or give {BUILTIN!r})"
        raise DatasetError(msg)
    if is_meshgen_output(raw):
        msg = (
            f"{raw}: a meshgen output; give the annotated dataset it was meshed from (the real "
            "photos and their polygons are the other side of the comparison)"
        )
        raise DatasetError(msg)
    from meshgen.config import MeshgenConfig
    from meshgen.pipeline import mesh_dataset

    tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="cdw-bench-perception-")))
    mesh_dataset(raw, tmp / "meshes", MeshgenConfig(seed=0))
    return raw, tmp / "meshes"


def _side_by_side(real: dict[str, Any], rendered: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per source and mode with the headline figures."""
    rows = []
    for source, block in (("real_photos", real), ("rendered", rendered)):
        for mode, data in block.get("modes", {}).items():
            scores = data.get("all", data)
            centroid = scores.get("centroid_error") or {}
            rows.append(
                {
                    "source": source,
                    "mode": mode,
                    "frames": data.get("photos", scores.get("frames")),
                    "recall": scores.get("recall"),
                    "precision": scores.get("precision"),
                    "class_accuracy": scores.get("class_accuracy"),
                    "centroid_error_median": centroid.get("median"),
                    "centroid_error_p90": centroid.get("p90"),
                    "centroid_unit": centroid.get("unit"),
                    "yaw_error_median_rad": (scores.get("yaw_error_rad") or {}).get("median"),
                }
            )
    return rows


def bench_perception(
    dataset: str | Path, *, seed: int = 0, train_fraction: float = 0.5
) -> dict[str, Any]:
    """Run both sides (see the module); plain JSON data."""
    start = time.perf_counter()
    with ExitStack() as stack:
        raw, meshes = _resolve(str(dataset), stack)
        real_data, _ = bench_photos(
            raw, seed=seed, train_fraction=train_fraction, comparisons=False
        )
        real: dict[str, Any] = dict(real_data)
        split: dict[str, Any] = real["split"]
        rendered = _rendered(meshes, split["train"], split["test"], real["class_names"], seed=seed)
    real_modes = real["modes"]
    result: dict[str, Any] = {
        "dataset": str(dataset),
        "class_names": real["class_names"],
        "split": {k: split[k] for k in ("seed", "train_fraction", "by")}
        | {"train_photos": len(split["train"]), "test_photos": len(split["test"])},
        "side_by_side": _side_by_side(real, rendered),
        "real_photos": {
            "photos_tested": len(split["test"]),
            "photo_size": real["photo_size"],
            "classifier": real["classifier"],
            "modes": real_modes,
        },
        "rendered": rendered,
        "targets": {
            "rendered_recall": 0.95,
            "rendered_class_accuracy": 0.90,
            "real_photos_recall": 0.80,
        },
        "notes": [
            (
                "real_photos.colour: every test photo, colour only (photos have no depth); "
                "real_photos.depth: the test photos with a height image (relative levels)"
            ),
            (
                "real photos: precision counts matched detections and those at least half inside "
                "a labelled region (annotators left small pieces unlabelled); the rest are "
                "unassessed_predictions; precision_all counts every detection; centroid error in "
                "pixels of the photo resized to fit 640x480"
            ),
            (
                "rendered: the test photos' meshed pieces laid out as in the photo under the "
                "reference overhead camera (640x480, 1.2 m); rendered.depth is the twin's camera "
                "mode, rendered.colour the same frames without depth; truth complete (every "
                f"detection counts), pieces with fewer than {MIN_TRUTH_PX} visible pixels not "
                "scored; centroid error in metres"
            ),
            "class accuracy is over matched pairs; recall and precision at mask IoU 0.5",
            "pieces meshgen skipped (polygons touching the photo's border) are not rendered",
        ],
        "seconds": round(time.perf_counter() - start, 1),
    }
    return result


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark's options."""
    parser.add_argument(
        "dataset", help=f"annotated dataset folder (YOLO-seg, labelme, COCO) or {BUILTIN!r}"
    )
    parser.add_argument("--seed", type=int, default=0, help="the photo split's seed (0)")
    parser.add_argument(
        "--train-fraction", type=float, default=0.5, help="photos per subset trained on (0.5)"
    )
    parser.add_argument("--json", action="store_true", help="print the whole result as JSON")
    parser.add_argument("--out", type=Path, help="also write the JSON result here (atomically)")


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and print its figures."""
    result = bench_perception(args.dataset, seed=args.seed, train_fraction=args.train_fraction)
    text = json.dumps(result, indent=1)
    if args.out is not None:
        write_atomic(args.out, text + "\n")
    if args.json:
        sys.stdout.write(text + "\n")
        return 0
    for row in result["side_by_side"]:
        unit = row["centroid_unit"] or ""
        sys.stdout.write(
            f"{row['source']:12s} {row['mode']:7s} frames {row['frames']!s:>4}  "
            f"recall {_fmt(row['recall'])}  precision {_fmt(row['precision'])}  "
            f"class accuracy {_fmt(row['class_accuracy'])}  "
            f"centroid {_fmt(row['centroid_error_median'])} {unit}\n"
        )
    return 0


def _fmt(value: object) -> str:
    return f"{value:.3f}" if isinstance(value, float) and math.isfinite(value) else "  -  "


def main(argv: list[str] | None = None) -> int:
    """Entry point for ``python -m detector.bench_perception``."""
    parser = argparse.ArgumentParser(prog="python -m detector.bench_perception")
    configure(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
