"""``cdw-twin sample --out DIR [--images N] [--seed N]``: write the procedural YOLO-seg sample."""

from __future__ import annotations

import argparse
from pathlib import Path


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the ``sample`` options."""
    parser.add_argument("--out", type=Path, required=True, help="dataset folder to write")
    from meshgen.sample import DEFAULT_IMAGES

    parser.add_argument(
        "--images",
        type=int,
        default=DEFAULT_IMAGES,
        help=f"number of images (default {DEFAULT_IMAGES})",
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")


def run(args: argparse.Namespace) -> int:
    """Write the sample and print one line about it."""
    from meshgen.sample import write_sample

    summary = write_sample(args.out, images=args.images, seed=args.seed)
    print(
        f"sample: {summary.images} images, {summary.objects} objects "
        f"({summary.border_objects} cut by the border) in {summary.out}"
    )
    return 0
