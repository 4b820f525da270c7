"""The sweep's pooling: per grid cell the mean and 95 % Student t interval of every metric over
its episodes, the pooled rates with their Wilson intervals (both from :mod:`experiments.stats`)
and the reasons, for the line, each station and each object class.

It pools the typed rows each episode's run wrote (:class:`interfaces.run_records.EpisodeMetrics`
and :class:`~interfaces.run_records.FailedEpisode`, read from ``episodes.json`` or handed over
by the runner) and never scores an episode again. Each result is a frozen record whose
``to_data`` is its block of ``sweep.json``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from experiments.stats import student_t_interval, wilson_interval
from interfaces.metrics import RATES, Scope, in_scope
from interfaces.run_records import (
    PERCEPTION_RATES,
    EpisodeRow,
    Metrics,
    ScopeMetrics,
    succeeded,
)


def _pooled_rates(scope: Scope) -> dict[str, tuple[str, str]]:
    return {m.name: m.ratio_of for m in RATES if scope in m.scopes and m.ratio_of is not None}


CI_METRICS = in_scope("line")
"""Metrics aggregated with Student t intervals: every line metric of the table."""


WILSON_RATES = _pooled_rates("line")
"""Rates also given as Wilson intervals: (successes, trials) counts pooled over episodes, the
table's ``ratio_of`` of every line rate."""


STATION_CI_METRICS = in_scope("station")
"""The per-station metrics aggregated with Student t intervals."""


STATION_WILSON_RATES = _pooled_rates("station")
"""The per-station rates also given as Wilson intervals."""


CLASS_CI_METRICS = in_scope("class")
"""The per-class metrics aggregated with Student t intervals."""


CLASS_WILSON_RATES = _pooled_rates("class")
"""The per-class rates also given as Wilson intervals."""


REASON_BLOCKS = ("untargeted", "untargeted_share", "dropped_by_reason")
"""The per-reason blocks of an episode's metrics (the controllers' untargeted objects, their
share of the objects that entered a station's window, drops), each reason aggregated with a
Student t interval (a reason missing from an episode counts 0 there)."""


ReasonCounts = Mapping[str, int | float]
"""One episode's per-reason block: a count (or a share) by reason."""


@dataclass(frozen=True, kw_only=True)
class Interval:
    """The mean of a metric over a cell's episodes and its 95 % Student t interval (bounds None
    for fewer than two episodes, everything None for none); ``n`` episodes had a value."""

    mean: float | None
    ci95_low: float | None
    ci95_high: float | None
    n: int

    @classmethod
    def of(cls, values: Sequence[float]) -> Interval:
        """The interval of ``values`` (:func:`experiments.stats.student_t_interval`)."""
        mean, low, high = student_t_interval(values)
        return cls(mean=mean, ci95_low=low, ci95_high=high, n=len(values))

    def to_data(self) -> dict[str, float | int | None]:
        """As ``sweep.json`` holds it."""
        return {
            "mean": self.mean,
            "ci95_low": self.ci95_low,
            "ci95_high": self.ci95_high,
            "n": self.n,
        }


@dataclass(frozen=True, kw_only=True)
class PooledRate:
    """A rate pooled over a cell's episodes: the summed counts, their ratio (None without
    trials) and its 95 % Wilson interval."""

    successes: int
    trials: int
    pooled: float | None
    ci95_low: float | None
    ci95_high: float | None

    @classmethod
    def of(cls, successes: int, trials: int) -> PooledRate:
        """The pooled rate of the counts (:func:`experiments.stats.wilson_interval`)."""
        low, high = wilson_interval(successes, trials)
        pooled = successes / trials if trials else None
        return cls(successes=successes, trials=trials, pooled=pooled, ci95_low=low, ci95_high=high)

    def to_data(self) -> dict[str, float | int | None]:
        """As ``sweep.json`` holds it."""
        return {
            "successes": self.successes,
            "trials": self.trials,
            "pooled": self.pooled,
            "ci95_low": self.ci95_low,
            "ci95_high": self.ci95_high,
        }


@dataclass(frozen=True, kw_only=True)
class ScopeSample:
    """What one successful episode gives a scope's pooling: the metric table's values and the
    per-reason blocks it has (of :data:`REASON_BLOCKS`)."""

    values: Metrics
    reasons: Mapping[str, ReasonCounts] = field(default_factory=dict)

    @classmethod
    def of(cls, block: ScopeMetrics) -> ScopeSample:
        """The line's or a station's block of a row (``untargeted_share``: a station's only)."""
        reasons: dict[str, ReasonCounts] = {
            "untargeted": block.untargeted,
            "dropped_by_reason": block.dropped_by_reason,
        }
        if block.untargeted_share is not None:
            reasons["untargeted_share"] = block.untargeted_share
        return cls(values=block.values, reasons=reasons)


@dataclass(frozen=True, kw_only=True)
class ScopePool:
    """The pooled metrics of one scope (the line, a station or a class) of a grid cell: how many
    episodes succeeded and failed, every metric's interval, every rate pooled, and per reason of
    each per-reason block the episodes have, its interval."""

    episodes: int
    failed: int = 0
    metrics: Mapping[str, Interval]
    wilson: Mapping[str, PooledRate]
    reasons: Mapping[str, Mapping[str, Interval]] = field(default_factory=dict)
    """By block of :data:`REASON_BLOCKS` (those the episodes have), by reason (sorted)."""

    def to_data(self) -> dict[str, object]:
        """As ``sweep.json`` holds it: counts, ``metrics``, ``wilson``, then the reason blocks."""
        out: dict[str, object] = {
            "episodes": self.episodes,
            "failed": self.failed,
            "metrics": {k: v.to_data() for k, v in self.metrics.items()},
            "wilson": {k: v.to_data() for k, v in self.wilson.items()},
        }
        for block in REASON_BLOCKS:
            if block in self.reasons:
                out[block] = {k: v.to_data() for k, v in self.reasons[block].items()}
        return out


def pool_reasons(samples: Sequence[ScopeSample], block: str) -> dict[str, Interval]:
    """Per reason of the samples' ``block`` (:data:`REASON_BLOCKS`), its mean with a Student t
    interval over the samples that have the block (a reason one of them lacks counts 0 there);
    reasons sorted."""
    blocks = [s.reasons[block] for s in samples if block in s.reasons]
    reasons = sorted({str(k) for b in blocks for k in b})
    return {r: Interval.of([float(b.get(r) or 0.0) for b in blocks]) for r in reasons}


def pool_scope(
    samples: Sequence[ScopeSample],
    metrics: Sequence[str],
    rates: Mapping[str, tuple[str, str]],
    *,
    failed: int = 0,
) -> ScopePool:
    """Every metric's interval over the samples (a metric that is None in an episode, e.g. no
    settled pursuit, leaves that episode out of that metric only), every rate pooled from its
    counts (``rates``: rate -> (successes, trials)) and the reasons."""
    return ScopePool(
        episodes=len(samples),
        failed=failed,
        metrics={
            key: Interval.of([float(v) for s in samples if (v := s.values.get(key)) is not None])
            for key in metrics
        },
        wilson={
            rate: PooledRate.of(
                sum(int(s.values.get(num) or 0) for s in samples),
                sum(int(s.values.get(den) or 0) for s in samples),
            )
            for rate, (num, den) in rates.items()
        },
        reasons={
            block: pool_reasons(samples, block)
            for block in REASON_BLOCKS
            if any(block in s.reasons for s in samples)
        },
    )


def pool_line(rows: Sequence[EpisodeRow]) -> ScopePool:
    """The line's pool over the rows: failed episodes are counted in ``failed`` and left out of
    everything else."""
    good = succeeded(rows)
    samples = [ScopeSample.of(r.line) for r in good]
    return pool_scope(samples, CI_METRICS, WILSON_RATES, failed=len(rows) - len(good))


def pool_stations(rows: Sequence[EpisodeRow]) -> dict[str, ScopePool]:
    """Each station's pool over the successful episodes that have it, stations in the order
    the rows first name them."""
    good = succeeded(rows)
    names = dict.fromkeys(name for r in good for name in r.stations)
    return {
        name: pool_scope(
            [ScopeSample.of(r.stations[name]) for r in good if name in r.stations],
            STATION_CI_METRICS,
            STATION_WILSON_RATES,
        )
        for name in names
    }


def pool_classes(rows: Sequence[EpisodeRow]) -> dict[str, ScopePool]:
    """Each object class's pool (the line's, per class: recovery, purity, ...) over the
    successful episodes that have it; classes sorted."""
    good = succeeded(rows)
    names = sorted({name for r in good for name in r.classes})
    return {
        name: pool_scope(
            [ScopeSample(values=r.classes[name]) for r in good if name in r.classes],
            CLASS_CI_METRICS,
            CLASS_WILSON_RATES,
        )
        for name in names
    }


def pool_perception(rows: Sequence[EpisodeRow]) -> ScopePool | None:
    """The camera's scores over the successful episodes that scored one (None when none did:
    the oracle): every score's interval (keys sorted) and recall and precision pooled from
    their counts (:data:`interfaces.run_records.PERCEPTION_RATES`)."""
    scored = [r for r in succeeded(rows) if r.perception]
    if not scored:
        return None
    keys = sorted({k for r in scored for k in r.perception})
    return pool_scope([ScopeSample(values=r.perception) for r in scored], keys, PERCEPTION_RATES)


@dataclass(frozen=True, kw_only=True)
class CellPool:
    """A grid cell's pooled metrics: the line's (with the episode counts), each station's,
    each object class's and, with a camera, the perception's (``sweep.json``'s
    ``aggregate``)."""

    line: ScopePool
    stations: Mapping[str, ScopePool]
    classes: Mapping[str, ScopePool]
    perception: ScopePool | None = None

    @property
    def episodes(self) -> int:
        """How many of the cell's episodes succeeded (the ones pooled)."""
        return self.line.episodes

    @property
    def failed(self) -> int:
        """How many of the cell's episodes failed."""
        return self.line.failed

    @classmethod
    def of(cls, rows: Sequence[EpisodeRow]) -> CellPool:
        """The pools of a cell's rows, as written (:func:`pool_line`, :func:`pool_stations`,
        :func:`pool_classes`, :func:`pool_perception`)."""
        return cls(
            line=pool_line(rows),
            stations=pool_stations(rows),
            classes=pool_classes(rows),
            perception=pool_perception(rows),
        )

    def to_data(self) -> dict[str, object]:
        """As ``sweep.json`` holds it: the line's block, then ``stations``, ``classes`` and
        (with a camera) ``perception``."""
        out = {
            **self.line.to_data(),
            "stations": {k: v.to_data() for k, v in self.stations.items()},
            "classes": {k: v.to_data() for k, v in self.classes.items()},
        }
        if self.perception is not None:
            out["perception"] = self.perception.to_data()
        return out
