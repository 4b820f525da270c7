"""``python -m detector``: the detector's jobs from the command line.

- ``python -m detector photos DATASET [--json] [--seed N] [--train-fraction F] [--out FILE]
  [--classifier-out MODEL.json]``: the detector on a YOLO dataset's real photos against their
  polygons (:mod:`detector.bench_photos`), per mode (colour, depth where height images exist);
- ``python -m detector train DATASET --out MODEL.json``: a colour classifier trained on every
  labelled photo of a dataset (for the detector of a cell sorting that dataset's pieces);
- ``taskset -c 0 python -m detector speed [--frames N] [--colour] [--json]``: time per
  640x480 frame (:mod:`detector.bench_speed`).

Without ``--json`` a short summary is printed; errors the package raises on purpose print one
line and exit 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from detector.errors import DetectorError
from interfaces.errors import CdwTwinError
from interfaces.fileio import write_atomic


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m detector", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="job", required=True)
    photos = sub.add_parser("photos", help="score the detector on a dataset's real photos")
    photos.add_argument("dataset", type=Path)
    photos.add_argument("--seed", type=int, default=0)
    photos.add_argument("--train-fraction", type=float, default=0.5)
    photos.add_argument("--json", action="store_true", help="print the whole result as JSON")
    photos.add_argument("--out", type=Path, help="also write the JSON result to this file")
    photos.add_argument("--classifier-out", type=Path, help="write the trained classifier here")
    train = sub.add_parser("train", help="train the colour classifier on a dataset's photos")
    train.add_argument("dataset", type=Path)
    train.add_argument("--out", type=Path, required=True, help="the classifier file (JSON)")
    speed = sub.add_parser("speed", help="time the detector on synthetic 640x480 frames")
    speed.add_argument("--frames", type=int, default=100)
    speed.add_argument("--pieces", type=int, default=40)
    speed.add_argument("--colour", action="store_true", help="colour-only mode (no depth)")
    speed.add_argument("--json", action="store_true")
    return parser


def _summary_line(mode: str, data: dict[str, object]) -> str:
    scores = data["all"]
    assert isinstance(scores, dict)
    return (
        f"{mode:24s} photos {data['photos']:3}  recall {scores['recall']}  "
        f"precision {scores['precision']}  class accuracy {scores['class_accuracy']}"
    )


def _photos(args: argparse.Namespace) -> int:
    from detector.bench_photos import bench_photos

    result, classifier = bench_photos(
        args.dataset, seed=args.seed, train_fraction=args.train_fraction
    )
    text = json.dumps(result, indent=1)
    if args.out:
        write_atomic(args.out, text + "\n")
    if args.classifier_out:
        classifier.save(args.classifier_out)
    if args.json:
        sys.stdout.write(text + "\n")
    else:
        modes = result["modes"]
        assert isinstance(modes, dict)
        for mode, data in modes.items():
            sys.stdout.write(_summary_line(mode, data) + "\n")
    return 0


def _train(args: argparse.Namespace) -> int:
    from detector.bench_photos import PHOTO_L2, train_on_photos
    from detector.config import DetectorConfig
    from detector.photos import read_photo_dataset

    data = read_photo_dataset(args.dataset)
    classifier = train_on_photos(
        data.photos, data.class_names, l2=PHOTO_L2, detected=DetectorConfig()
    )
    classifier.save(args.out)
    sys.stdout.write(
        f"{args.out}: classes {list(classifier.class_names)}, "
        f"{classifier.training.get('instances')} instances from {len(data.photos)} photos\n"
    )
    return 0


def _speed(args: argparse.Namespace) -> int:
    from detector.bench_speed import bench_speed

    result = bench_speed(frames=args.frames, pieces=args.pieces, colour_only=args.colour)
    if args.json:
        sys.stdout.write(json.dumps(result, indent=1) + "\n")
    else:
        cpu, wall = result["cpu"], result["wall"]
        assert isinstance(cpu, dict)
        assert isinstance(wall, dict)
        sys.stdout.write(
            f"{result['frame']}, {result['pieces']} pieces, {result['mode']} mode: "
            f"median {wall['median_ms']} ms wall, {cpu['median_ms']} ms CPU per frame\n"
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run one job; the exit status."""
    args = _parser().parse_args(argv)
    jobs = {"photos": _photos, "train": _train, "speed": _speed}
    try:
        return jobs[args.job](args)
    except (DetectorError, CdwTwinError) as exc:
        sys.stderr.write(f"python -m detector {args.job}: {exc}\n")
        return 2


__all__ = ["main"]
