"""``python -m detector.bench_grasp DATASET --json``: the grasp geometry the detector reports
(centroid, suction point, its radius, the face's tilt) against the truth, on rendered frames.

The frames are :mod:`detector.bench_perception`'s renders: every photo's meshed pieces laid out
as in the photo under the reference overhead camera (640x480, 1.2 m), stacked where their
footprints overlap, depth with the camera's noise (``--photos`` of them, or all). The detector
runs in depth mode (the twin's camera; geometry only, no classifier). Truth per piece: the
footprint centroid (as the perception bench scores it) and the suction point, radius and tilt of
:class:`twin.suction_point.SuctionPoints` (the pole of the mesh's upturned face: what the twin's
oracle reports and its cup seals on). A detection is matched to the piece it overlaps with mask
IoU >= 0.5. Suction figures count only pieces no later piece lies on (an occluded face's true
pole may lie under its neighbour; the centroid counts every matched piece).

Errors, median and 90th percentile: ``centroid_error_m`` and ``suction_point_error_m`` (belt
plane distance), ``suction_radius_error_m`` and ``suction_tilt_error_rad`` (detected minus true:
signed, so also the 10th percentile). Where the issue's closed-loop figures came from a twin
episode, these come from still frames: no motion, no arm; the same detector code.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from detector.bench_perception import BUILTIN, STACK_CELL_M, LaidPiece, PieceRenderer, lay_out
from detector.detector import Detector, DetectorOutput
from interfaces.camera import RgbdCameraSpec
from interfaces.fileio import write_atomic

MATCH_IOU = 0.5
"""A detection and a rendered piece match at this mask IoU."""

MIN_VISIBLE_PX = 60
"""A piece with fewer visible pixels is not scored (as the perception bench)."""


@dataclass(frozen=True, kw_only=True)
class _Pose:
    """What :class:`twin.suction_point.SuctionPoints` reads of a ground truth."""

    id: int
    position_m: tuple[float, float, float]
    orientation_xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True, kw_only=True)
class PieceErrors:
    """One matched piece's errors (m, rad); suction figures NaN where not scored."""

    centroid_m: float
    suction_point_m: float
    suction_clearance_loss_m: float
    suction_radius_m: float
    suction_tilt_rad: float


def _covered(scene_path: Path, count: int) -> list[bool]:
    """Which of a scene's ``count`` pieces a later piece's footprint overlaps."""
    from detector.bench_perception import _footprint_mask

    data = json.loads(scene_path.read_text(encoding="utf-8"))
    objects = data.get("objects") or []
    belt_w = float(data.get("belt_width_m", 0.6))
    length = belt_w * float(data["height_px"]) / float(data["width_px"])
    origin = (-0.5 * length - 0.05, -0.5 * belt_w - 0.05)
    shape = (int((length + 0.1) / STACK_CELL_M) + 1, int((belt_w + 0.1) / STACK_CELL_M) + 1)
    masks = [_footprint_mask(obj["footprint_m"], origin, shape) for obj in objects[:count]]
    later = np.zeros(shape, dtype=bool)
    out = [False] * len(masks)
    for k in range(len(masks) - 1, -1, -1):
        out[k] = bool((masks[k] & later).any())
        later |= masks[k]
    return out


def frame_errors(
    output: DetectorOutput,
    ids: np.ndarray,
    pieces: Sequence[LaidPiece],
    centre_m: tuple[float, float],
    belt_z_m: float,
    covered: Sequence[bool],
) -> list[PieceErrors]:
    """The errors of every piece of one frame (instance id ``k + 1`` for ``pieces[k]``) that a
    detection of ``output`` matches."""
    from twin.objects import read_mesh
    from twin.suction_point import SuctionPoints

    def mesh_of(object_id: int) -> np.ndarray:
        mesh = read_mesh(pieces[object_id - 1].mesh_path)
        out: np.ndarray = np.asarray(mesh.vertices, dtype=np.float64)[np.asarray(mesh.faces)]
        return out

    truth_points = SuctionPoints(mesh_of)
    labels = output.labels
    n_det = len(output.instances)
    n_true = len(pieces)
    pairs = np.bincount(
        ids.astype(np.int64).ravel() * (n_det + 1) + labels.ravel(),
        minlength=(n_true + 1) * (n_det + 1),
    ).reshape(n_true + 1, n_det + 1)
    true_px = pairs.sum(axis=1)
    det_px = pairs.sum(axis=0)
    out = []
    for k in range(1, n_true + 1):
        if true_px[k] < MIN_VISIBLE_PX:
            continue
        j = int(np.argmax(pairs[k, 1:])) + 1
        inter = pairs[k, j]
        if inter / max(true_px[k] + det_px[j] - inter, 1) < MATCH_IOU:
            continue
        detection = output.instances[j - 1].detection
        if detection is None:
            continue
        piece = pieces[k - 1]
        cx, cy = centre_m[0] + piece.centroid_m[0], centre_m[1] + piece.centroid_m[1]
        centroid = math.hypot(detection.x_m - cx, detection.y_m - cy)
        point = loss = radius = tilt = math.nan
        if not covered[k - 1]:
            pose = _Pose(id=k, position_m=(cx, cy, belt_z_m + piece.base_m + 0.5 * piece.height_m))
            true_point, true_radius, true_tilt = truth_points(pose)  # type: ignore[arg-type]
            sx, sy, _ = detection.suction_point_m
            point = math.hypot(sx - true_point[0], sy - true_point[1])
            loss = true_radius - _clearance(truth_points, k, pose.position_m, (sx, sy))
            radius = detection.suction_radius_m - true_radius
            tilt = detection.suction_tilt_rad - true_tilt
        out.append(
            PieceErrors(
                centroid_m=centroid,
                suction_point_m=point,
                suction_clearance_loss_m=loss,
                suction_radius_m=radius,
                suction_tilt_rad=tilt,
            )
        )
    return out


def _clearance(
    truth_points: Any, object_id: int, position_m: Sequence[float], point_xy: Sequence[float]
) -> float:
    """How far the point ``point_xy`` (world x, y) lies inside the outline of the piece's
    upturned face (negative: outside), seen from above; the piece is not rotated."""
    from shapely.geometry import Point

    faces, normals = truth_points.faces(object_id)
    up = int(np.argmax(normals[:, 2]))
    face = faces[up]
    u_vec, v_vec = np.asarray(face.u, dtype=np.float64), np.asarray(face.v, dtype=np.float64)
    origin = np.asarray(face.origin, dtype=np.float64)
    normal = np.cross(u_vec, v_vec)
    dx, dy = point_xy[0] - position_m[0], point_xy[1] - position_m[1]
    # where the vertical line through the point meets the face's plane
    dz = (
        (origin @ normal - dx * normal[0] - dy * normal[1]) / normal[2]
        if abs(normal[2]) > 1e-9
        else 0.0
    )
    offset = np.array([dx, dy, dz]) - origin
    where = Point(float(offset @ u_vec), float(offset @ v_vec))
    distance = float(face.polygon.boundary.distance(where))
    return distance if face.polygon.contains(where) else -distance


def _stats(values: Sequence[float], *, signed: bool) -> dict[str, float | int | None]:
    """Median, 90th (and for signed errors 10th) percentile of the finite values."""
    finite = np.array([v for v in values if math.isfinite(v)], dtype=np.float64)
    if finite.size == 0:
        return {"count": 0, "median": None, "p90": None}
    out: dict[str, float | int | None] = {
        "count": int(finite.size),
        "median": round(float(np.median(finite)), 6),
        "p90": round(float(np.percentile(finite, 90)), 6),
    }
    if signed:
        out["p10"] = round(float(np.percentile(finite, 10)), 6)
        out["abs_median"] = round(float(np.median(np.abs(finite))), 6)
    return out


def bench_grasp(dataset: str | Path, *, photos: int = 0, seed: int = 0) -> dict[str, Any]:
    """Render the dataset's photos (the first ``photos`` in name order; 0: all), detect, score
    (see the module); plain JSON data."""
    from detector.bench_perception import _resolve

    camera = RgbdCameraSpec()
    belt_z_m = 0.0
    detector = Detector(belt_z_m=belt_z_m)
    errors: list[PieceErrors] = []
    frames = 0
    with ExitStack() as stack:
        _, meshes = _resolve(str(dataset), stack)
        scenes = sorted(meshes.glob("*/scene.json"))
        if photos > 0:
            scenes = scenes[:photos]
        renderer = PieceRenderer(camera, belt_z_m)
        rng = np.random.default_rng(seed)
        try:
            for scene in scenes:
                pieces = lay_out(scene)
                if not pieces:
                    continue
                frame = renderer.frame(pieces, rng)
                assert frame.instance_ids is not None
                output = detector.detect(frame)
                covered = _covered(scene, len(pieces))
                errors.extend(
                    frame_errors(
                        output, frame.instance_ids, pieces, renderer.centre_m, belt_z_m, covered
                    )
                )
                frames += 1
        finally:
            renderer.close()
    return {
        "dataset": str(dataset),
        "frames": frames,
        "matched_pieces": len(errors),
        "centroid_error_m": _stats([e.centroid_m for e in errors], signed=False),
        "suction_point_error_m": _stats([e.suction_point_m for e in errors], signed=False),
        "suction_clearance_loss_m": _stats(
            [e.suction_clearance_loss_m for e in errors], signed=False
        ),
        "suction_radius_error_m": _stats([e.suction_radius_m for e in errors], signed=True),
        "suction_tilt_error_rad": _stats([e.suction_tilt_rad for e in errors], signed=True),
        "notes": [
            "still frames of the perception bench's layouts, reference overhead camera",
            "suction figures only for pieces no later piece lies on; signed: detected - true",
        ],
    }


def configure(parser: argparse.ArgumentParser) -> None:
    """The command's arguments."""
    parser.add_argument("dataset", help=f"an annotated dataset folder, or {BUILTIN!r}")
    parser.add_argument("--photos", type=int, default=0, help="render the first N photos (0: all)")
    parser.add_argument("--seed", type=int, default=0, help="the depth noise's seed (0)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--out", type=Path, help="also write the JSON result here (atomically)")


def run(args: argparse.Namespace) -> int:
    """Run the bench and print its result."""
    result = bench_grasp(args.dataset, photos=args.photos, seed=args.seed)
    text = json.dumps(result, indent=1)
    if args.out is not None:
        write_atomic(args.out, text + "\n")
    if args.json:
        print(text)
    else:
        for key in (
            "centroid_error_m",
            "suction_point_error_m",
            "suction_clearance_loss_m",
            "suction_radius_error_m",
        ):
            print(key, result[key])
        print("suction_tilt_error_rad", result["suction_tilt_error_rad"])
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m detector.bench_grasp``."""
    parser = argparse.ArgumentParser(prog="python -m detector.bench_grasp")
    configure(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["MATCH_IOU", "MIN_VISIBLE_PX", "PieceErrors", "bench_grasp", "frame_errors"]
