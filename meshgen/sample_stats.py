"""Summary statistics of the real CDW sample that the built-in sample is drawn from.

The real sample (``cdw_stacked_sample``: 60 labelme files from Bazenr's *Dataset of stacked
construction solid waste*, CC BY-NC-SA 4.0) may not be copied into the repository, so only its
summary lives here, in ``meshgen/cdw_sample_stats.json``: per class the object count, 21
quantiles (probabilities 0, 0.05, ..., 1, numpy's linear interpolation) of the footprint
``length_m``, ``width_m``, ``area_m2`` and ``fill`` (area / (length x width)) as meshgen measures
them (default configuration, border-truncated outlines skipped), the Spearman rank
correlations of length, width and fill, and for each figure how far the piecewise-linear CDF
through the quantiles lies from the real empirical CDF (``quantile_error``, a
Kolmogorov-Smirnov distance). The stream figures (images, objects, summed image length along
the belt) give the real stream's density.

Regenerate (with the real sample at hand)::

    cdw-twin meshgen ../shared/datasets/cdw_stacked_sample --out /tmp/cdw_real
    python -m meshgen.sample_stats /tmp/cdw_real --out meshgen/cdw_sample_stats.json
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from interfaces.fileio import write_atomic
from meshgen.annotations import FloatArray
from meshgen.errors import DatasetError

STATS_PATH = Path(__file__).resolve().parent / "cdw_sample_stats.json"
FIGURES: tuple[str, ...] = ("length_m", "width_m", "area_m2", "fill")
"""The footprint figures summarised per class; ``fill`` is ``area_m2 / (length_m * width_m)``."""
PROBABILITIES: tuple[float, ...] = tuple(k / 20 for k in range(21))
SOURCE = (
    "cdw_stacked_sample: 60 labelme files of Bazenr, 'Dataset of stacked construction solid "
    "waste' (https://github.com/Bazenr/Dataset-of-stacked-construction-solid-waste, "
    "CC BY-NC-SA 4.0), meshed by cdw-twin meshgen with its default configuration"
)


@dataclass(frozen=True, slots=True, kw_only=True)
class ClassStats:
    """One class's summary: object count, quantiles ``(21,)`` per figure, rank correlations.

    ``quantiles[figure]`` are taken at :data:`PROBABILITIES`; ``rank_correlation`` is the
    ``(3, 3)`` Spearman matrix of length, width and fill; ``quantile_error[figure]`` is the
    largest gap between the real empirical CDF and the piecewise-linear CDF through the
    quantiles.
    """

    objects: int
    quantiles: dict[str, tuple[float, ...]]
    rank_correlation: tuple[tuple[float, ...], ...]
    quantile_error: dict[str, float]


@dataclass(frozen=True, slots=True, kw_only=True)
class SampleStats:
    """The real sample's summary: per-class statistics and the stream's extent."""

    source: str
    images: int
    image_length_m: float
    classes: dict[str, ClassStats]

    @property
    def objects(self) -> int:
        """Objects meshgen kept, all classes."""
        return sum(c.objects for c in self.classes.values())

    @property
    def objects_per_m(self) -> float:
        """Objects per metre of image along the belt (the twin adds ``image_gap_m`` between
        images)."""
        return self.objects / self.image_length_m


def quantile_cdf(x: FloatArray, quantiles: FloatArray) -> FloatArray:
    """The piecewise-linear CDF through ``quantiles`` (at :data:`PROBABILITIES`) at ``x``."""
    return np.interp(x, quantiles, PROBABILITIES)


def ks_against_quantiles(values: FloatArray, quantiles: FloatArray) -> float:
    """Kolmogorov-Smirnov distance of the empirical CDF of ``values`` ``(n,)`` from
    :func:`quantile_cdf`: the largest gap, found at the jumps of the step function."""
    x = np.sort(np.asarray(values, dtype=np.float64))
    n = len(x)
    if n == 0:
        msg = "ks_against_quantiles: no values"
        raise ValueError(msg)
    cdf = quantile_cdf(x, np.asarray(quantiles, dtype=np.float64))
    steps = np.arange(n + 1) / n
    return float(max(np.max(steps[1:] - cdf), np.max(cdf - steps[:-1])))


def read_scenes(meshed: Path) -> dict[str, dict[str, FloatArray]]:
    """Per class, the ``(n,)`` arrays of every figure of :data:`FIGURES` of a meshgen output."""
    columns: dict[str, dict[str, list[float]]] = {}
    scenes = sorted(meshed.glob("*/scene.csv"))
    if not scenes:
        msg = f"{meshed}: no */scene.csv files; is it a meshgen output folder?"
        raise DatasetError(msg)
    for scene in scenes:
        with scene.open(newline="", encoding="utf-8") as fh:
            for row in csv.DictReader(fh):
                figures = columns.setdefault(row["class_name"], {f: [] for f in FIGURES})
                length, width, area = (float(row[k]) for k in ("length_m", "width_m", "area_m2"))
                for name, value in zip(
                    FIGURES, (length, width, area, area / (length * width)), strict=True
                ):
                    figures[name].append(value)
    return {c: {f: np.array(v) for f, v in figs.items()} for c, figs in columns.items()}


def _image_length_m(meshed: Path) -> tuple[int, float]:
    """Images with objects and their summed length along the belt, from ``index.csv``."""
    with (meshed / "index.csv").open(newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.DictReader(fh) if int(r["objects"]) > 0]
    return len(rows), sum(float(r["height_px"]) * float(r["m_per_px"]) for r in rows)


def measure(meshed: Path, source: str = SOURCE) -> SampleStats:
    """The :class:`SampleStats` of a meshgen output folder ``meshed``."""
    # imported here: the sample's generator imports this module only to read the stored
    # statistics, and scipy.stats takes half a second to import
    from scipy import stats as sps

    classes = {}
    for name, figures in sorted(read_scenes(meshed).items()):
        quantiles = {f: tuple(np.quantile(v, PROBABILITIES).tolist()) for f, v in figures.items()}
        dims = np.stack([figures["length_m"], figures["width_m"], figures["fill"]], axis=1)
        rho = np.atleast_2d(sps.spearmanr(dims).statistic) if len(dims) > 2 else np.eye(3)
        classes[name] = ClassStats(
            objects=len(figures["length_m"]),
            quantiles=quantiles,
            rank_correlation=tuple(tuple(float(v) for v in row) for row in rho),
            quantile_error={
                f: ks_against_quantiles(v, np.array(quantiles[f])) for f, v in figures.items()
            },
        )
    images, length_m = _image_length_m(meshed)
    return SampleStats(source=source, images=images, image_length_m=length_m, classes=classes)


def _rounded(value: float) -> float:
    return float(f"{value:.6g}")


def to_json(summary: SampleStats) -> str:
    """The JSON text of ``summary`` (6 significant digits)."""
    doc: dict[str, Any] = {
        "source": summary.source,
        "regenerate": (
            "cdw-twin meshgen <cdw_stacked_sample> --out <dir>; "
            "python -m meshgen.sample_stats <dir> --out meshgen/cdw_sample_stats.json"
        ),
        "probabilities": list(PROBABILITIES),
        "images": summary.images,
        "image_length_m": _rounded(summary.image_length_m),
        "classes": {
            name: {
                "objects": c.objects,
                **{f: [_rounded(v) for v in c.quantiles[f]] for f in FIGURES},
                "rank_correlation_length_width_fill": [
                    [round(v, 4) for v in row] for row in c.rank_correlation
                ],
                "quantile_error": {f: round(c.quantile_error[f], 4) for f in FIGURES},
            }
            for name, c in summary.classes.items()
        },
    }
    return _dumps(doc, "") + "\n"


def _dumps(value: Any, indent: str) -> str:
    """JSON with one key per line and every list of numbers on one line."""
    if not isinstance(value, dict):
        return json.dumps(value)
    inner = indent + "  "
    items = [f"{inner}{json.dumps(k)}: {_dumps(v, inner)}" for k, v in value.items()]
    return "{\n" + ",\n".join(items) + "\n" + indent + "}"


def _checked(values: Any, where: str, size: int) -> tuple[float, ...]:
    if not (isinstance(values, list) and len(values) == size):
        msg = f"{where}: expected a list of {size} numbers"
        raise DatasetError(msg)
    out = tuple(float(v) for v in values)
    if not all(math.isfinite(v) for v in out):
        msg = f"{where}: expected finite numbers"
        raise DatasetError(msg)
    return out


def load_sample_stats(path: Path = STATS_PATH) -> SampleStats:
    """Read the stored summary; :class:`DatasetError` names the file and field when malformed."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        classes = {}
        for name, entry in doc["classes"].items():
            where = f"{path}: classes.{name}"
            quantiles = {}
            for f in FIGURES:
                q = _checked(entry[f], f"{where}.{f}", len(PROBABILITIES))
                if any(b < a for a, b in itertools.pairwise(q)):
                    msg = f"{where}.{f}: quantiles must not decrease"
                    raise DatasetError(msg)
                quantiles[f] = q
            rho = entry["rank_correlation_length_width_fill"]
            classes[name] = ClassStats(
                objects=int(entry["objects"]),
                quantiles=quantiles,
                rank_correlation=tuple(
                    _checked(row, f"{where}.rank_correlation_length_width_fill", 3) for row in rho
                ),
                quantile_error={f: float(entry["quantile_error"][f]) for f in FIGURES},
            )
        return SampleStats(
            source=str(doc["source"]),
            images=int(doc["images"]),
            image_length_m=float(doc["image_length_m"]),
            classes=classes,
        )
    except (OSError, ValueError, KeyError, TypeError) as exc:
        msg = f"{path}: cannot read the sample statistics: {exc}"
        raise DatasetError(msg) from exc


def main(argv: list[str] | None = None) -> int:
    """``python -m meshgen.sample_stats MESHED --out FILE``: summarise a meshed real sample."""
    parser = argparse.ArgumentParser(prog="python -m meshgen.sample_stats", description=__doc__)
    parser.add_argument("meshed", type=Path, help="meshgen output folder of the real sample")
    parser.add_argument("--out", type=Path, default=STATS_PATH, help=f"default {STATS_PATH}")
    args = parser.parse_args(argv)
    summary = measure(args.meshed)
    write_atomic(args.out, to_json(summary))
    counts = ", ".join(f"{n} {c.objects}" for n, c in summary.classes.items())
    print(f"sample stats: {summary.objects} objects ({counts}) in {summary.images} images -> "
          f"{args.out}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
