"""``cdw-twin detector-node``: the camera detector as a ROS 2 node, until SIGINT/SIGTERM.

Examples::

    cdw-twin detector-node --dataset out/meshes --cell default
    python -m detector.cmd_node --dataset out/meshes --cell line --camera zone1 --no-depth

For every camera of the cell (``--cell``: a path or a shipped cell's name; ``--camera`` picks
some by name) it subscribes to ``/camera/NAME/color/image_raw``, ``/camera/NAME/depth/image_raw``
and ``/camera/NAME/color/camera_info`` (:mod:`interfaces.camera_topics`) and publishes each
frame's detections on ``/objects/detections`` (what the controllers read), stamped with the
frame's capture stamp (:mod:`detector.ros_node`). Each camera's detector is the baseline with a
colour classifier trained on ``--dataset``'s own photos (:func:`detector.factory.detector_for`:
a meshgen output or a YOLO dataset, cached in the dataset folder), or read from
``--classifier`` (a file of ``python -m detector train``); or your own model: ``--onnx
MODEL.onnx`` (:class:`detector.onnx_segmenter.OnnxSegmenter`, class names in ``MODEL.json``) or
``--segmenter MODULE:CALLABLE`` (any :class:`detector.instances.Segmenter`; docs/detector.md).
``--stats-out`` writes the node's counters (frames, detections, refused images, time per
detection) as JSON on shutdown, atomically.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from interfaces.fileio import write_atomic

if TYPE_CHECKING:
    from detector.detector import Detector
    from detector.instances import Segmenter
    from interfaces.camera import RgbdCameraSpec

__all__ = ["configure", "detector_of", "main", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the detector node's options to ``parser``."""
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument(
        "--dataset",
        type=Path,
        help="meshgen output or YOLO dataset whose photos train the colour classifier",
    )
    source.add_argument(
        "--classifier", type=Path, help="a colour classifier file (python -m detector train)"
    )
    source.add_argument(
        "--onnx",
        type=Path,
        help="your own segmentation model (ONNX, docs/detector.md) instead of the baseline",
    )
    source.add_argument(
        "--segmenter",
        metavar="MODULE:CALLABLE",
        help="your own segmenter: a callable returning a detector.instances.Segmenter",
    )
    parser.add_argument(
        "--cell", help="cell file: a path or a shipped cell's name (default: the reference cell)"
    )
    parser.add_argument(
        "--camera",
        action="append",
        default=None,
        help="detect on this camera of the cell only (repeatable; default: every camera)",
    )
    parser.add_argument(
        "--no-depth", action="store_true", help="colour-only: do not subscribe to depth"
    )
    parser.add_argument("--stats-out", type=Path, help="write the counters as JSON on shutdown")
    parser.add_argument("--duration", type=float, help="stop after this many seconds of wall time")


def _cameras(args: argparse.Namespace) -> tuple[float, tuple[RgbdCameraSpec, ...]]:
    """The belt's surface height and the cameras to detect on."""
    from detector.errors import DetectorConfigError
    from interfaces.cell import load_cell

    cell = load_cell(args.cell)
    cameras = cell.cameras
    if not cameras:
        msg = f"{cell.source or cell.name}: the cell declares no cameras (cameras:)"
        raise DetectorConfigError(msg)
    if args.camera:
        known = {c.name: c for c in cameras}
        unknown = [name for name in args.camera if name not in known]
        if unknown:
            msg = f"--camera {unknown}: the cell's cameras are {sorted(known)}"
            raise DetectorConfigError(msg)
        cameras = tuple(known[name] for name in args.camera)
    return cell.belt.surface_z_m, cameras


def _user_segmenter(text: str) -> Segmenter:
    """The segmenter ``MODULE:CALLABLE`` returns (:class:`detector.errors.DetectorConfigError`
    naming what is wrong)."""
    import importlib

    from detector.errors import DetectorConfigError
    from detector.instances import Segmenter

    module_name, _, attribute = text.partition(":")
    if not module_name or not attribute:
        msg = f"--segmenter {text!r}: expected MODULE:CALLABLE (my_package.models:make)"
        raise DetectorConfigError(msg)
    try:
        factory = getattr(importlib.import_module(module_name), attribute)
    except (ImportError, AttributeError) as exc:
        msg = f"--segmenter {text!r}: {exc}"
        raise DetectorConfigError(msg) from exc
    made = factory()
    if not isinstance(made, Segmenter):
        msg = (
            f"--segmenter {text!r}: returned a {type(made).__name__}, not a Segmenter (a "
            "`segment(rgb, depth_m)` method and a `mode` attribute)"
        )
        raise DetectorConfigError(msg)
    return made


def detector_of(args: argparse.Namespace, belt_z_m: float) -> Callable[[RgbdCameraSpec], Detector]:
    """Each camera's detector as the options say: the baseline trained on ``--dataset``, the
    baseline with ``--classifier``, an ONNX model (``--onnx``) or a user's segmenter
    (``--segmenter``)."""
    from detector.classifier import ColourClassifier
    from detector.detector import Detector
    from detector.factory import detector_for

    if args.classifier is not None:
        classifier = ColourClassifier.load(args.classifier)
        return lambda spec: Detector(classifier=classifier, belt_z_m=belt_z_m)
    if args.onnx is not None:
        from detector.onnx_segmenter import OnnxSegmenter

        onnx = OnnxSegmenter(args.onnx)
        return lambda spec: Detector(segmenter=onnx, belt_z_m=belt_z_m)
    if args.segmenter is not None:
        user = _user_segmenter(args.segmenter)
        return lambda spec: Detector(segmenter=user, belt_z_m=belt_z_m)
    return lambda spec: detector_for(args.dataset, belt_z_m=belt_z_m, cameras=(spec,))


def run(args: argparse.Namespace) -> int:
    """Run the node; 0 on a clean shutdown, 2 on a configuration error."""
    import rclpy
    from rclpy.experimental.events_executor import EventsExecutor
    from rclpy.signals import SignalHandlerOptions
    from rclpy.utilities import try_shutdown

    from detector.ros_node import DetectorNode
    from interfaces.errors import CdwTwinError
    from interfaces.lifecycle import StopRequests, die_with_parent

    if args.duration is not None and not args.duration > 0.0:
        sys.stderr.write(f"--duration: {args.duration!r} must be > 0 s\n")
        return 2
    try:
        belt_z_m, cameras = _cameras(args)
        make = detector_of(args, belt_z_m)
        detectors = {spec.name: make(spec) for spec in cameras}
    except CdwTwinError as exc:
        sys.stderr.write(f"error: {exc}\n")
        return 2
    rclpy.init(args=None, signal_handler_options=SignalHandlerOptions.NO)
    stop = StopRequests()
    node: DetectorNode | None = None
    try:
        die_with_parent()
        node = DetectorNode(
            cameras=cameras,
            detector_of=lambda spec: detectors[spec.name],
            with_depth=not args.no_depth,
        )
        executor = EventsExecutor()
        executor.add_node(node)
        node.log.info(
            f"detector up: cameras {[c.name for c in cameras]}, "
            f"{'colour only' if args.no_depth else 'colour + depth'}"
        )
        start = time.monotonic()
        while not stop:
            executor.spin_once(timeout_sec=0.1)
            if args.duration is not None and time.monotonic() - start >= args.duration:
                break
        return 0
    finally:
        if node is not None:
            summary = node.counters.summary(node.dropped())
            node.log.info(f"detector down: {summary}")
            if args.stats_out is not None:
                write_atomic(args.stats_out, json.dumps(summary, indent=1) + "\n")
            node.destroy_node()  # type: ignore[no-untyped-call]
        try_shutdown()
        stop.restore()


def main(argv: list[str] | None = None) -> int:
    """Entry point for ``python -m detector.cmd_node``."""
    parser = argparse.ArgumentParser(prog="python -m detector.cmd_node", description=__doc__)
    configure(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
