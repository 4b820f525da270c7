"""How far the built-in sample's footprints lie from the real CDW sample's, as JSON.

Per class and figure (length, width, area, fill) of the meshed built-in sample:

- ``bound``: the Kolmogorov-Smirnov distance from the CDF through the stored real quantiles
  (``meshgen/cdw_sample_stats.json``) plus the stored distance of that CDF from the real
  sample; by the triangle inequality it bounds the two-sample statistic, and it needs nothing
  outside the repository;
- ``two_sample``: the exact two-sample statistic against the meshed real sample, when one is
  given (``--real``).

Example::

    python -m meshgen.sample_ks                              # default sample, stored stats
    cdw-twin meshgen ../shared/datasets/cdw_stacked_sample --out /tmp/cdw_real
    python -m meshgen.sample_ks --real /tmp/cdw_real --images 24 --seed 3
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import ks_2samp

from meshgen.config import MeshgenConfig
from meshgen.pipeline import mesh_dataset
from meshgen.sample import DEFAULT_IMAGES, write_sample
from meshgen.sample_stats import (
    FIGURES,
    SampleStats,
    ks_against_quantiles,
    load_sample_stats,
    read_scenes,
)


def ks_table(
    builtin_meshed: Path, real_meshed: Path | None = None, stats: SampleStats | None = None
) -> dict[str, Any]:
    """``{"bound": {class: {figure: d}}, "two_sample": {...} or None, "objects": {class: n}}``
    for a meshed built-in sample (see the module doc)."""
    stats = load_sample_stats() if stats is None else stats
    builtin = read_scenes(builtin_meshed)
    real = read_scenes(real_meshed) if real_meshed is not None else None
    bound: dict[str, dict[str, float]] = {}
    two_sample: dict[str, dict[str, float]] = {}
    for name, stored in stats.classes.items():
        figures = builtin.get(name)
        if figures is None:
            continue
        bound[name] = {
            f: round(
                ks_against_quantiles(figures[f], np.array(stored.quantiles[f]))
                + stored.quantile_error[f],
                4,
            )
            for f in FIGURES
        }
        if real is not None and name in real:
            two_sample[name] = {
                f: round(float(ks_2samp(figures[f], real[name][f]).statistic), 4) for f in FIGURES
            }
    return {
        "objects": {name: len(figures["length_m"]) for name, figures in builtin.items()},
        "bound": bound,
        "two_sample": two_sample if real is not None else None,
    }


def main(argv: list[str] | None = None) -> int:
    """``python -m meshgen.sample_ks [--images N] [--seed N] [--real MESHED]``: print the
    table of :func:`ks_table` for a freshly written and meshed built-in sample."""
    parser = argparse.ArgumentParser(prog="python -m meshgen.sample_ks", description=__doc__)
    parser.add_argument("--images", type=int, default=DEFAULT_IMAGES)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--real", type=Path, help="meshgen output folder of the real sample")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="cdw-sample-ks-") as tmp:
        root = Path(tmp)
        write_sample(root / "sample", images=args.images, seed=args.seed)
        meshed = mesh_dataset(root / "sample", root / "meshes", MeshgenConfig()).out
        table = ks_table(meshed, args.real)
    table = {"images": args.images, "seed": args.seed, **table}
    print(json.dumps(table, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
