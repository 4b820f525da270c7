"""Confidence intervals shared by the sweep and the report."""

from __future__ import annotations

import math
from collections.abc import Iterable

Z_95 = 1.959963984540054
"""Two-sided 95 % quantile of the standard normal distribution."""


def mean_of(values: Iterable[float | None]) -> float | None:
    """Mean of the values that are not None; None when there are none."""
    numbers = [float(v) for v in values if v is not None]
    return sum(numbers) / len(numbers) if numbers else None


def wilson_interval(successes: int, trials: int) -> tuple[float | None, float | None]:
    """95 % Wilson score interval of a proportion, ``(None, None)`` without trials."""
    if trials <= 0:
        return None, None
    p = successes / trials
    z2 = Z_95 * Z_95
    denom = 1.0 + z2 / trials
    centre = (p + z2 / (2 * trials)) / denom
    half = Z_95 * math.sqrt(p * (1 - p) / trials + z2 / (4 * trials * trials)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)
