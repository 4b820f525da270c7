"""Confidence intervals shared by the sweep and the report."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

Z_95 = 1.959963984540054
"""Two-sided 95 % quantile of the standard normal distribution."""


def mean_of(values: Iterable[float | None]) -> float | None:
    """Mean of the values that are not None; None when there are none."""
    numbers = [float(v) for v in values if v is not None]
    return sum(numbers) / len(numbers) if numbers else None


def wilson_interval(successes: int, trials: int) -> tuple[float | None, float | None]:
    """95 % Wilson score interval of a proportion, ``(None, None)`` without trials (or with
    more successes than trials: not a proportion)."""
    if trials <= 0 or not 0 <= successes <= trials:
        return None, None
    p = successes / trials
    z2 = Z_95 * Z_95
    denom = 1.0 + z2 / trials
    centre = (p + z2 / (2 * trials)) / denom
    half = Z_95 * math.sqrt(p * (1 - p) / trials + z2 / (4 * trials * trials)) / denom
    # the bounds are exactly 0 and 1 at none and all (the formula leaves rounding error there)
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == trials else min(1.0, centre + half)
    return low, high


def student_t_interval(values: Sequence[float]) -> tuple[float | None, float | None, float | None]:
    """Mean and 95 % Student t interval of ``values`` (interval None for fewer than 2)."""
    from scipy import stats

    n = len(values)
    if n == 0:
        return None, None, None
    mean = math.fsum(values) / n
    if n < 2:
        return mean, None, None
    sd = math.sqrt(math.fsum((v - mean) ** 2 for v in values) / (n - 1))
    half = float(stats.t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
    return mean, mean - half, mean + half
