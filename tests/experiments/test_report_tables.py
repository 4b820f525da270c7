"""The report's pooled intervals: one Wilson interval (:func:`experiments.stats.wilson_interval`,
the sweep's), shown by the tables per cell and speed as the whole unit interval without trials
and by the line tables as none."""

from __future__ import annotations

import pytest

from experiments.report_tables import pooled_rate, rate_interval
from experiments.stats import wilson_interval


@pytest.mark.parametrize(("k", "n"), [(0, 1), (1, 1), (3, 10), (50, 100)])
def test_the_wilson_interval_contains_the_estimate_and_stays_in_unit_range(k: int, n: int) -> None:
    low, high = wilson_interval(k, n)
    assert low is not None
    assert high is not None
    assert 0.0 <= low <= k / n <= high <= 1.0


def test_the_wilson_interval_known_value() -> None:
    # 50 of 100 at 95 %: 0.5 +- 0.0962 (Wilson)
    assert wilson_interval(50, 100) == pytest.approx((0.4038, 0.5962), abs=1e-4)


def test_a_table_rate_and_its_interval_are_the_pooled_counts_wilson_interval() -> None:
    total = {"sorted": 3, "targeted": 10, "missed": 0, "processed": 0}
    assert pooled_rate("success_rate", total) == pytest.approx(0.3)
    assert rate_interval("success_rate", total) == wilson_interval(3, 10)
    # no trials: no rate, and the tables' interval is the whole unit interval
    assert pooled_rate("miss_rate", total) is None
    assert rate_interval("miss_rate", total) == (0.0, 1.0)
    with pytest.raises(KeyError, match="picked"):
        rate_interval("picked", total)
