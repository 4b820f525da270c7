"""Statistics of pixel groups (one group per instance label), all groups at once.

Every function takes ``groups`` ``(m,) int`` labels in ``0..n`` (0 is ignored) and per-pixel
``values`` ``(m,)``, and returns one value per label ``(n + 1,)`` (index 0 unused; NaN or 0 for a
label without pixels): vectorised with ``bincount`` and one sort, no loop over the instances.
"""

from __future__ import annotations

import numpy as np


def counts(groups: np.ndarray, n: int) -> np.ndarray:
    """Pixels per label, ``(n + 1,) int64``."""
    out: np.ndarray = np.bincount(groups, minlength=n + 1)[: n + 1]
    return out


def sums(groups: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Sum of ``values`` per label, ``(n + 1,) float64``."""
    out: np.ndarray = np.bincount(groups, weights=values, minlength=n + 1)[: n + 1]
    return out


def means(groups: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Mean of ``values`` per label (NaN without pixels), ``(n + 1,) float64``."""
    c = counts(groups, n)
    with np.errstate(invalid="ignore", divide="ignore"):
        out: np.ndarray = sums(groups, values, n) / c
    return out


def maxima(groups: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Largest of ``values`` per label (-inf without pixels), ``(n + 1,) float64``."""
    out = np.full(n + 1, -np.inf)
    np.maximum.at(out, groups, values)
    return out


def percentiles(groups: np.ndarray, values: np.ndarray, n: int, q: float) -> np.ndarray:
    """The ``q``-th percentile (lower, no interpolation) of ``values`` per label (NaN
    without pixels), ``(n + 1,) float64``."""
    out: np.ndarray = percentiles_many(groups, values, n, (q,))[0]
    return out


def _group_order(groups: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The order sorting by group, then value (NaN last within a group)."""
    if values.size and np.isfinite(values).all():
        span = 2.0 * (float(np.abs(values).max()) + 1.0)
        order: np.ndarray = np.argsort(groups * span + values)
        return order
    return np.lexsort((values, groups))


def percentiles_many(
    groups: np.ndarray, values: np.ndarray, n: int, qs: tuple[float, ...]
) -> np.ndarray:
    """:func:`percentiles` for each of ``qs`` with one sort, ``(len(qs), n + 1) float64``
    (finite ``values``: one ``argsort`` of ``group * span + value``, cheaper than a two-key
    ``lexsort``; equal values may swap places, which changes no percentile)."""
    out = np.full((len(qs), n + 1), np.nan)
    if groups.size == 0:
        return out
    values = np.asarray(values, dtype=np.float64)
    ordered = values[_group_order(groups, values)]
    c = counts(groups, n)
    starts = np.cumsum(c) - c
    has = c > 0
    for i, q in enumerate(qs):
        pick = starts + np.floor(q / 100.0 * (c - 1)).astype(np.int64)
        out[i, has] = ordered[pick[has]]
    return out


def argmaxima(groups: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Index into ``values`` of each label's largest value (-1 without pixels),
    ``(n + 1,) int64``."""
    out = np.full(n + 1, -1, dtype=np.int64)
    if groups.size == 0:
        return out
    order = np.lexsort((-values, groups))
    first = np.ones(order.size, dtype=bool)
    first[1:] = groups[order][1:] != groups[order][:-1]
    out[groups[order][first]] = order[first]
    return out


__all__ = ["argmaxima", "counts", "maxima", "means", "percentiles", "percentiles_many", "sums"]
