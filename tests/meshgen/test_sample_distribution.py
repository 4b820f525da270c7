"""The built-in sample looks like the real CDW sample: per class, the distributions of footprint
length, width, area (and fill) are within a Kolmogorov-Smirnov distance of 0.15 of the real
ones, the class mix is the real one, and the stream is as dense.

Without the real sample the check runs against the stored statistics
(``meshgen/cdw_sample_stats.json``): the distance of the built-in sample from the CDF through
the stored quantiles plus the stored distance of that CDF from the real sample bounds the
two-sample distance (triangle inequality). With the real sample present (``../shared``) the
exact two-sample statistic is checked too, and the stored file is checked against it.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import shapely
from scipy.stats import ks_2samp

from meshgen.errors import DatasetError
from meshgen.sample import write_sample
from meshgen.sample_dims import class_counts, draw_dimensions
from meshgen.sample_ks import ks_table
from meshgen.sample_shapes import outline
from meshgen.sample_stats import (
    FIGURES,
    STATS_PATH,
    ks_against_quantiles,
    load_sample_stats,
    measure,
    read_scenes,
)

KS_BOUND = 0.15
CLASSES = ("concrete", "brick", "wood", "rubber")
STATS = load_sample_stats()


@pytest.mark.parametrize("class_name", CLASSES)
def test_builtin_sample_matches_the_stored_real_distributions(
    default_sample_meshed: Path, class_name: str
) -> None:
    """Measured (seed 0): at most 0.085 (concrete 0.08, brick 0.05, wood 0.05, rubber 0.085)
    with the quantile allowance included; ``python -m meshgen.sample_ks`` prints the table."""
    figures = read_scenes(default_sample_meshed)[class_name]
    stored = STATS.classes[class_name]
    for figure in FIGURES:
        quantiles = np.array(stored.quantiles[figure])
        distance = ks_against_quantiles(figures[figure], quantiles)
        assert distance + stored.quantile_error[figure] <= KS_BOUND, (figure, distance)


@pytest.mark.parametrize("class_name", CLASSES)
def test_builtin_sample_matches_the_real_sample(
    default_sample_meshed: Path, real_meshed: Path, class_name: str
) -> None:
    """Exact two-sample statistics (measured at most 0.077, rubber's fill)."""
    builtin = read_scenes(default_sample_meshed)[class_name]
    real = read_scenes(real_meshed)[class_name]
    for figure in FIGURES:
        statistic = ks_2samp(builtin[figure], real[figure]).statistic
        assert statistic <= KS_BOUND, (figure, statistic)


def test_stored_statistics_are_those_of_the_real_sample(real_meshed: Path) -> None:
    """The data file is what ``python -m meshgen.sample_stats`` makes of the real sample."""
    fresh = measure(real_meshed)
    assert fresh.images == STATS.images
    assert fresh.image_length_m == pytest.approx(STATS.image_length_m, rel=1e-5)
    assert set(fresh.classes) == set(STATS.classes)
    for name, stored in STATS.classes.items():
        now = fresh.classes[name]
        assert now.objects == stored.objects
        for figure in FIGURES:
            assert now.quantiles[figure] == pytest.approx(stored.quantiles[figure], rel=1e-5)
            assert now.quantile_error[figure] == pytest.approx(
                stored.quantile_error[figure], abs=1e-4
            )
        assert np.array(now.rank_correlation) == pytest.approx(
            np.array(stored.rank_correlation), abs=1e-4
        )


def test_class_mix_is_the_real_one_with_enough_of_each_class(default_sample_meshed: Path) -> None:
    """The measured objects split like the real counts (concrete 62, brick 91, wood 81,
    rubber 35); the rarest class still has the ~60 objects that keep the KS noise low."""
    scenes = read_scenes(default_sample_meshed)
    counts = {c: len(scenes[c]["length_m"]) for c in CLASSES}
    total = sum(counts.values())
    expected = class_counts(STATS, total)
    assert counts == expected
    assert min(counts.values()) >= 55


def test_stream_is_as_dense_as_the_real_one(default_sample_meshed: Path) -> None:
    """Objects per metre of image along the belt (how the twin lays images out): within 10 %
    of the real sample's 7.9 per metre (measured 8.35)."""
    builtin = measure(default_sample_meshed)
    assert builtin.objects_per_m == pytest.approx(STATS.objects_per_m, rel=0.10)


REAL_CONCAVE_SHARE = {"concrete": 0.05, "brick": 0.13, "wood": 0.01, "rubber": 0.77}
"""Share of the real pieces whose convex hull adds more than 10 % to their area
(:mod:`meshgen.sample_shapes`; checked against the real sample below when it is present)."""


def _concave_shares(meshed: Path) -> dict[str, float]:
    """Per class, the share of footprints whose convex hull adds more than 10 % to the area."""
    hull_gain: dict[str, list[float]] = {}
    for scene in sorted(meshed.glob("*/scene.csv")):
        with scene.open(newline="") as fh:
            for row in csv.DictReader(fh):
                hull = shapely.convex_hull(
                    shapely.multipoints(_vertices(scene.parent / row["mesh_path"]))
                )
                gain = hull.area / float(row["area_m2"]) - 1.0
                hull_gain.setdefault(row["class_name"], []).append(gain)
    return {c: float(np.mean(np.array(g) > 0.1)) for c, g in hull_gain.items()}


def test_outlines_are_concave_as_often_as_the_real_ones(default_sample_meshed: Path) -> None:
    """Concave where the real pieces are (rubber strips and bent profiles, some broken bricks),
    convex elsewhere: each class's share of clearly concave footprints within 0.1 of the real
    share (measured: concrete 0.06, brick 0.05, wood 0.03, rubber 0.84)."""
    shares = _concave_shares(default_sample_meshed)
    for name, real in REAL_CONCAVE_SHARE.items():
        assert shares[name] == pytest.approx(real, abs=0.1), (name, shares[name])


def test_real_concave_shares_are_those_of_the_real_sample(real_meshed: Path) -> None:
    """The shares quoted above are the real sample's."""
    shares = _concave_shares(real_meshed)
    for name, real in REAL_CONCAVE_SHARE.items():
        assert shares[name] == pytest.approx(real, abs=0.01), (name, shares[name])


def _vertices(obj: Path) -> np.ndarray:
    """The ``(n, 2)`` horizontal coordinates of an OBJ mesh's vertices."""
    lines = obj.read_text().splitlines()
    return np.array(
        [[float(v) for v in line.split()[1:3]] for line in lines if line.startswith("v ")]
    )


@pytest.mark.parametrize("class_name", CLASSES)
def test_drawn_dimensions_follow_the_stored_quantiles(class_name: str) -> None:
    """Length, width and fill are stratified draws (within ~1/n of the stored CDF), width
    never exceeds length, and the area pairing brings the area close to its quantiles."""
    stats = STATS.classes[class_name]
    n = 60
    dims = draw_dimensions(np.random.default_rng(5), stats, n)
    assert dims.shape == (n, 3)
    assert np.all(dims[:, 1] <= dims[:, 0])
    for k, figure in enumerate(("length_m", "width_m", "fill")):
        assert ks_against_quantiles(dims[:, k], np.array(stats.quantiles[figure])) <= 1.0 / n
    area = dims.prod(axis=1)
    assert ks_against_quantiles(area, np.array(stats.quantiles["area_m2"])) <= 0.1


def test_an_outline_has_the_wanted_rectangle_and_fill() -> None:
    rng = np.random.default_rng(1)
    for name, (length, width, fill) in [
        ("rubber", (0.17, 0.05, 0.55)), ("wood", (0.16, 0.05, 0.95)),
        ("concrete", (0.09, 0.07, 0.75)), ("brick", (0.09, 0.06, 0.99)),
    ]:  # fmt: skip
        ring = outline(rng, name, length, width, fill)
        polygon = shapely.Polygon(ring)
        assert polygon.is_valid
        assert len(ring) >= 12
        box = np.ptp(ring, axis=0)
        assert box == pytest.approx([length, width], rel=0.02)
        assert polygon.area / (length * width) == pytest.approx(fill, abs=0.02)


def test_same_seed_same_sample_other_seed_other_sample(tmp_path: Path) -> None:
    write_sample(tmp_path / "a", images=6, seed=4)
    write_sample(tmp_path / "b", images=6, seed=4)
    write_sample(tmp_path / "c", images=6, seed=5)
    for label in sorted((tmp_path / "a" / "labels").iterdir()):
        assert label.read_bytes() == (tmp_path / "b" / "labels" / label.name).read_bytes()
    for photo in sorted((tmp_path / "a" / "images").iterdir()):
        assert photo.read_bytes() == (tmp_path / "b" / "images" / photo.name).read_bytes()
    a = (tmp_path / "a" / "labels" / "sample_000.txt").read_text()
    assert a != (tmp_path / "c" / "labels" / "sample_000.txt").read_text()
    photo = (tmp_path / "a" / "images" / "sample_000.jpg").read_bytes()
    assert photo != (tmp_path / "c" / "images" / "sample_000.jpg").read_bytes()


def test_malformed_statistics_file_names_file_and_field(tmp_path: Path) -> None:
    doc = json.loads(STATS_PATH.read_text())
    doc["classes"]["rubber"]["width_m"] = doc["classes"]["rubber"]["width_m"][:5]
    bad = tmp_path / "stats.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(DatasetError, match=r"stats\.json: classes\.rubber\.width_m: expected"):
        load_sample_stats(bad)
    doc = json.loads(STATS_PATH.read_text())
    doc["classes"]["gypsum"] = doc["classes"].pop("rubber")
    odd = tmp_path / "odd.json"
    odd.write_text(json.dumps(doc))
    with pytest.raises(DatasetError, match=r"classes \['gypsum'\] are not among"):
        write_sample(tmp_path / "s", images=1, stats=load_sample_stats(odd))


def test_ks_table_prints_the_measured_figures(default_sample_meshed: Path) -> None:
    """``python -m meshgen.sample_ks`` reports every class and figure, the bound within 0.15
    (run ``pytest -s`` to see the JSON the lead quotes)."""
    table = ks_table(default_sample_meshed)
    print(json.dumps(table, indent=1))
    assert set(table["bound"]) == set(CLASSES)
    for name in CLASSES:
        assert set(table["bound"][name]) == set(FIGURES)
        assert max(table["bound"][name].values()) <= KS_BOUND, name
    assert table["two_sample"] is None
