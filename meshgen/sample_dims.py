"""Footprint dimensions for the built-in sample, drawn from the real sample's statistics.

For the ``n`` objects of one class, :func:`draw_dimensions` draws length, width and fill
(area / (length x width)) so that each figure's empirical distribution follows the class's
stored quantiles (:mod:`meshgen.sample_stats`) closely even for a few dozen objects:

1. Stratified marginals (Latin hypercube): ``u_i = (pi_i + v_i) / n`` with ``pi`` a random
   permutation of ``0 .. n-1`` and ``v_i`` uniform, mapped through the piecewise-linear quantile
   function. Length and width share the same ``u`` values (independently permuted): the width
   quantiles never exceed the length quantiles, so a pairing with width <= length exists.
2. Natural pairing: Iman and Conover's rank reordering (1982) gives length, width and fill the
   class's stored Spearman correlations without changing any value.
3. Width <= length: objects in increasing order of length each take the free width nearest
   their own among those not above their length (always succeeds, see step 1).
4. Area: area = length x width x fill is a product of paired values, so its distribution depends
   on the pairing. Alternating rank matching re-pairs fill, width and length in turn: each
   object's current area rank gets the target area of that rank, and the values of one figure
   are re-assigned by rank to the values that would give those areas. The pairing with the
   smallest Kolmogorov-Smirnov distance of the areas from the stored area quantiles is kept.

Every value stays one of the stratified draws, so the length, width and fill marginals are
untouched by steps 2-4.
"""

from __future__ import annotations

import numpy as np

from meshgen.annotations import FloatArray
from meshgen.footprint import IntArray
from meshgen.sample_stats import PROBABILITIES, ClassStats, SampleStats, ks_against_quantiles

AREA_ROUNDS = 60
"""Rounds of alternating rank matching (step 4): it settles within about ten."""


def class_counts(stats: SampleStats, total: int) -> dict[str, int]:
    """``total`` objects split over the classes in proportion to the real counts (largest
    remainders get the leftover objects; ties go to the class listed first)."""
    names = list(stats.classes)
    shares = np.array([stats.classes[n].objects for n in names], dtype=np.float64)
    exact = total * shares / shares.sum()
    counts = np.floor(exact).astype(int)
    order = np.argsort(-(exact - counts), kind="stable")
    counts[order[: total - int(counts.sum())]] += 1
    return {n: int(c) for n, c in zip(names, counts, strict=True)}


def _quantile_function(quantiles: tuple[float, ...], u: FloatArray) -> FloatArray:
    return np.interp(u, PROBABILITIES, quantiles)


def _ranks(x: FloatArray) -> IntArray:
    """The rank ``0 .. n-1`` of each of ``x`` ``(n,)`` (ties in order of appearance)."""
    ranks: IntArray = np.argsort(np.argsort(x, kind="stable"), kind="stable")
    return ranks


def _pearson_of_spearman(rank_correlation: tuple[tuple[float, ...], ...]) -> FloatArray:
    """The normal-scores correlation that gives a Spearman matrix, made positive definite."""
    rho = np.array(rank_correlation, dtype=np.float64)
    target = 2.0 * np.sin(np.pi * rho / 6.0)
    values, vectors = np.linalg.eigh(target)
    target = vectors @ np.diag(np.maximum(values, 1e-3)) @ vectors.T
    scale = np.sqrt(np.diag(target))
    result: FloatArray = target / np.outer(scale, scale)
    return result


def _iman_conover(
    rng: np.random.Generator, columns: FloatArray, correlation: FloatArray
) -> FloatArray:
    """Reorder each column of ``columns`` ``(n, d)`` so their rank correlation approaches
    ``correlation`` ``(d, d)``; the values of each column are kept."""
    from scipy.special import ndtri  # only when a sample is drawn (slow to import)

    n, d = columns.shape
    scores = ndtri(np.arange(1, n + 1) / (n + 1))
    mixed = np.stack([rng.permutation(scores) for _ in range(d)], axis=1)
    try:
        have = np.linalg.cholesky(np.corrcoef(mixed, rowvar=False))
        want = np.linalg.cholesky(correlation)
    except np.linalg.LinAlgError:
        return columns
    target = mixed @ np.linalg.inv(have).T @ want.T
    out = np.empty_like(columns)
    for k in range(d):
        out[:, k] = np.sort(columns[:, k])[_ranks(target[:, k])]
    return out


def _widths_not_above_lengths(length: FloatArray, width: FloatArray) -> FloatArray:
    """Step 3: a re-pairing of ``width`` with ``width <= length`` everywhere, close to the given
    one."""
    free = np.sort(width)
    taken = np.zeros(len(free), dtype=bool)
    out = np.empty_like(width)
    for i in np.argsort(length, kind="stable"):
        allowed = np.flatnonzero(~taken & (free <= length[i]))
        k = allowed[np.argmin(np.abs(free[allowed] - width[i]))]
        taken[k] = True
        out[i] = free[k]
    return out


def _match_area(dims: FloatArray, area_quantiles: tuple[float, ...]) -> FloatArray:
    """Step 4 on ``dims`` ``(n, 3)`` (length, width, fill); returns the best pairing found."""
    n = len(dims)
    target = _quantile_function(area_quantiles, (np.arange(n) + 0.5) / n)
    quantiles = np.array(area_quantiles)
    ordered = [np.sort(dims[:, k]) for k in range(3)]
    best, best_ks = dims, ks_against_quantiles(dims.prod(axis=1), quantiles)
    for step in range(AREA_ROUNDS):
        k = (2 - step) % 3  # fill, width, length, fill, ...
        wanted = target[_ranks(dims.prod(axis=1))]
        others = dims.prod(axis=1) / dims[:, k]
        trial = dims.copy()
        trial[:, k] = ordered[k][_ranks(wanted / others)]
        if np.any(trial[:, 1] > trial[:, 0]):
            continue
        dims = trial
        ks = ks_against_quantiles(dims.prod(axis=1), quantiles)
        if ks < best_ks:
            best, best_ks = dims, ks
    return best


def draw_dimensions(rng: np.random.Generator, stats: ClassStats, n: int) -> FloatArray:
    """``(n, 3)`` length (m), width (m) and fill of ``n`` objects of one class (module doc)."""
    if n == 0:
        return np.zeros((0, 3))
    u = (rng.permutation(n) + rng.random(n)) / n
    v = (rng.permutation(n) + rng.random(n)) / n
    q = stats.quantiles
    dims = np.stack(
        [
            _quantile_function(q["length_m"], u),
            _quantile_function(q["width_m"], rng.permutation(u)),
            _quantile_function(q["fill"], v),
        ],
        axis=1,
    )
    if n >= 4:
        dims = _iman_conover(rng, dims, _pearson_of_spearman(stats.rank_correlation))
    dims[:, 1] = _widths_not_above_lengths(dims[:, 0], dims[:, 1])
    if n >= 2:
        dims = _match_area(dims, q["area_m2"])
    return dims


def draw_one(rng: np.random.Generator, stats: ClassStats) -> FloatArray:
    """``(3,)`` length, width and fill of one object drawn independently from the quantiles
    (for objects that are not measured, such as those cut by the image border)."""
    q = stats.quantiles
    length, width, fill = (
        float(np.interp(rng.random(), PROBABILITIES, q[f])) for f in ("length_m", "width_m", "fill")
    )
    return np.array([max(length, width), min(length, width), fill])
