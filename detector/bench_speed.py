"""How long the detector takes per frame: synthetic 640x480 RGB-D frames, one core.

The frame is :mod:`detector.synthetic`'s: ``pieces`` boxes of three colours on the dark belt, seen
by the shipped overhead camera with a real sensor's depth noise; the detector is the baseline
with a colour classifier fitted on that frame's own pieces (so classification is timed too). It
runs ``frames`` times after one warm-up; the result gives the wall-clock and CPU time per frame
(median, 90th percentile, best), the mode and the number of instances found. Run it pinned to one
core to measure what one core does (``taskset -c 0 python -m detector speed --json``).
"""

from __future__ import annotations

import os
import time

import numpy as np

from detector.classifier import fit_classifier
from detector.config import DetectorConfig
from detector.detector import Detector
from detector.features import instance_features
from detector.synthetic import render, scatter
from interfaces.camera import DepthNoise

COLOUR_NAMES = {(150, 150, 145): "concrete", (175, 80, 50): "brick", (190, 150, 105): "wood"}
"""The synthetic pieces' colours and the class each stands for."""


def bench_speed(
    *,
    frames: int = 50,
    pieces: int = 40,
    seed: int = 0,
    config: DetectorConfig | None = None,
    colour_only: bool = False,
) -> dict[str, object]:
    """Time :meth:`detector.detector.Detector.detect` on one synthetic frame, ``frames``
    times; plain JSON data (milliseconds)."""
    scene = scatter(pieces, seed=seed)
    frame = render(scene, seed=seed, noise=DepthNoise())
    assert frame.instance_ids is not None
    truth_names = [COLOUR_NAMES[p.rgb] for p in scene]
    classifier = fit_classifier(
        instance_features(frame.rgb, frame.instance_ids, 2),
        truth_names,
        class_names=sorted(set(COLOUR_NAMES.values())),
    )
    cfg = config or DetectorConfig(mode="colour" if colour_only else "auto")
    detector = Detector(config=cfg, classifier=classifier)
    output = detector.detect(frame)
    wall, cpu = [], []
    for _ in range(frames):
        w0, c0 = time.perf_counter(), time.process_time()
        output = detector.detect(frame)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)

    def stats(values: list[float]) -> dict[str, float]:
        ms = np.array(values) * 1e3
        return {
            "median_ms": round(float(np.median(ms)), 2),
            "p90_ms": round(float(np.percentile(ms, 90)), 2),
            "best_ms": round(float(ms.min()), 2),
        }

    return {
        "frame": f"{frame.rgb.shape[1]}x{frame.rgb.shape[0]}",
        "pieces": len(scene),
        "instances_found": len(output.instances),
        "mode": output.mode,
        "frames_timed": frames,
        "wall": stats(wall),
        "cpu": stats(cpu),
        "cpus_allowed": sorted(os.sched_getaffinity(0)),
    }


__all__ = ["bench_speed"]
