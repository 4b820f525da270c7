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
    out = np.full(n + 1, np.nan)
    if groups.size == 0:
        return out
    order = np.lexsort((values, groups))
    c = counts(groups, n)
    starts = np.cumsum(c) - c
    has = c > 0
    pick = starts + np.floor(q / 100.0 * (c - 1)).astype(np.int64)
    out[has] = values[order][pick[has]]
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


__all__ = ["argmaxima", "counts", "maxima", "means", "percentiles", "sums"]
