"""``cdw-twin meshgen DATASET --out DIR``: annotated polygons to metric 3D proxy meshes.

Example::

    cdw-twin meshgen data/sample --out out/meshes --json
    cdw-twin meshgen PATH/cdw_stacked_sample --out out/real --heights auto   # heights/ images
    cdw-twin meshgen data/sample --out out/plain --no-textures    # no texture.jpg, no vt lines

Every piece is textured (:mod:`meshgen.textures`): its image's photo when the dataset has it,
else a procedural picture of its pieces.

Every skipped object or file is printed to stderr as a warning naming file, line and reason,
and so is everything made otherwise than asked (a procedural texture for an image without a
usable photo, a sampled height where a height image gives none); those are not skips: the
meshes are written, and ``--strict`` does not count them.
Exit status 0 when objects were produced, 1 when nothing was produced or, with ``--strict``,
when anything was skipped, 2 on a usage error (an ``--out`` that may not be replaced, see
:mod:`meshgen.outdir`), 130 when interrupted by Ctrl-C or SIGTERM: the summary of the images
finished is still printed (with ``--json``: ``"complete": false``) and ``OUT`` is left as it
was.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from meshgen.config import MeshgenConfig
    from meshgen.pipeline import DatasetSummary

FORMAT_CHOICES = ("auto", "yolo", "coco", "labelme")


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the ``meshgen`` options."""
    parser.add_argument("dataset", type=Path, help="dataset folder (YOLO-seg, COCO or labelme)")
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        help="output folder: must be empty, new or an earlier meshgen output (then replaced)",
    )
    parser.add_argument("--format", dest="fmt", choices=FORMAT_CHOICES, default="auto")
    parser.add_argument("--belt-width", type=float, default=0.6, help="belt width in m")
    parser.add_argument("--image-size", default=None, help="WxH when nothing else gives it")
    parser.add_argument("--seed", type=int, default=0, help="height seed (default 0)")
    parser.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument("--strict", action="store_true", help="exit 1 on any skip")
    parser.add_argument("--simplify-mm", type=float, default=1.0, help="0 disables (default 1)")
    parser.add_argument("--border-margin-px", type=float, default=1.0)
    parser.add_argument("--min-area-mm2", type=float, default=25.0)
    parser.add_argument("--up", choices=("z", "y"), default="z", help="up axis of the meshes")
    parser.add_argument(
        "--classes",
        type=Path,
        default=None,
        help="the dataset's class table YAML, over the shipped one (interfaces/materials.yaml)",
    )
    parser.add_argument(
        "--no-textures",
        dest="textures",
        action="store_false",
        help="write no textures and no texture coordinates",
    )
    parser.add_argument(
        "--texture-max-px", type=int, default=1024, help="long side of a texture at most (1024)"
    )
    parser.add_argument(
        "--heights",
        default="",
        help="heights from height images: a folder of <stem>.* images, or auto (DATASET/heights)",
    )
    parser.add_argument(
        "--height-scale-m", type=float, default=0.001, help="m per height-image level (0.001)"
    )
    parser.add_argument(
        "--height-percentile",
        type=float,
        default=90.0,
        help="percentile of a piece's levels taken as its top (90)",
    )


def config_from_args(args: argparse.Namespace) -> MeshgenConfig:
    """Build a :class:`meshgen.config.MeshgenConfig` from parsed options."""
    from interfaces.materials import shipped_table
    from meshgen.classes import load_table_file
    from meshgen.config import MeshgenConfig, parse_image_size

    table = load_table_file(args.classes) if args.classes else shipped_table()
    return MeshgenConfig(
        fmt=args.fmt,
        belt_width_m=args.belt_width,
        image_size_px=parse_image_size(args.image_size) if args.image_size else None,
        seed=args.seed,
        simplify_mm=args.simplify_mm,
        border_margin_px=args.border_margin_px,
        min_area_mm2=args.min_area_mm2,
        up=args.up,
        classes=table,
        textures=args.textures,
        texture_max_px=args.texture_max_px,
        heights=args.heights if args.heights in ("", "auto") else str(Path(args.heights).resolve()),
        height_scale_m=args.height_scale_m,
        height_percentile=args.height_percentile,
    )


def _report(summary: DatasetSummary, as_json: bool) -> None:
    """Print every skip and notice to stderr, and the summary (JSON or a table) to stdout."""
    for skip in summary.skips:
        print(f"warning: {skip.message()}", file=sys.stderr)
    for notice in summary.notices:
        print(f"warning: {notice.message()}", file=sys.stderr)
    if as_json:
        print(json.dumps({**summary.to_json(), "complete": summary.complete}, sort_keys=True))
        return
    counts = f"{summary.images} images, {summary.objects} objects"
    if summary.complete:
        print(f"meshgen: {counts} -> {summary.out}")
    else:
        print(f"meshgen: interrupted after {counts}; nothing written to {summary.out}")
    print(
        f"  format {summary.fmt}, {summary.ms_per_image:.2f} ms/image, "
        f"{summary.ms_per_object:.3f} ms/object"
    )
    for reason, count in summary.skipped.items():
        print(f"  skipped {count:4d}  {reason}")
    for reason, count in summary.warned.items():
        print(f"  warned  {count:4d}  {reason}")


def run(args: argparse.Namespace) -> int:
    """Mesh the dataset, print warnings, a summary (table or JSON), return the exit status."""
    from meshgen.errors import MeshgenError
    from meshgen.interrupts import terminate_as_interrupt
    from meshgen.pipeline import RunInterrupted, mesh_dataset, tty_progress

    if args.workers < 1:
        msg = f"--workers must be >= 1, got {args.workers}"
        raise MeshgenError(msg)
    config = config_from_args(args)
    progress = tty_progress if sys.stderr.isatty() and not args.json else None
    interrupted = False
    with terminate_as_interrupt():
        try:
            summary = mesh_dataset(
                args.dataset, args.out, config, workers=args.workers, progress=progress
            )
        except RunInterrupted as exc:
            summary, interrupted = exc.summary, True
            if progress is not None:
                print(file=sys.stderr)  # end the progress bar's line
    _report(summary, args.json)
    if interrupted:
        print("cdw-twin: interrupted", file=sys.stderr)
        return 130
    if summary.objects == 0:
        return 1
    if args.strict and summary.skips:
        return 1
    return 0
