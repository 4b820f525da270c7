"""The report's tables per episode, per cell and belt speed, and per station.

Every number is read from the episodes' rows of ``episodes.json`` (their counts and rates, the
metric table's), the twin's summaries (tracking, latency, real-time factor) and telemetry (round
trips): rates of a group pool the counts of its episodes, with 95 % Wilson score intervals
(:func:`experiments.stats.wilson_interval`); a group is a cell at a belt speed (runs of different
cells at one speed are never pooled). Each row is a frozen dataclass; ``*_COLUMNS`` give the
page's columns, ``(field, heading)``, in order.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from experiments import stats
from experiments.report_data import Episode, RunData, percentile
from interfaces.metrics import BY_NAME, rate
from interfaces.run_records import Metrics

COUNT_KEYS = (
    "picked",
    "placed_correct",
    "sorted",
    "targeted",
    "missed",
    "processed",
    "spawned",
    "entered",
    "recovered",
)
"""The counts the report pools: the rates' (``success_rate``, ``miss_rate``,
``recovery_rate``: recovered / entered, the complete cohort), picks and the objects spawned."""

Counts = dict[str, int]
"""Counts by name (:data:`COUNT_KEYS`): one episode's, or summed over a group's."""

Interval = tuple[float, float]
"""A 95 % interval, (low, high)."""


def counts(ep: Episode, station: str | None = None) -> Counts | None:
    """The pooled-count ingredients of one episode (the line's, or ``station``'s); None
    without its metrics (or without that station)."""
    if ep.metrics is None:
        return None
    block = ep.metrics.line if station is None else ep.metrics.stations.get(station)
    if block is None:
        return None
    return {key: int(block.get(key) or 0) for key in COUNT_KEYS}


def pooled(each: Iterable[Counts | None]) -> Counts:
    """The counts summed over the episodes that have them (empty when none has)."""
    present = [c for c in each if c is not None]
    return {k: sum(c[k] for c in present) for k in COUNT_KEYS} if present else {}


def ratio_of(name: str) -> tuple[str, str]:
    """The (numerator, denominator) counts of the metric table's rate ``name``."""
    pair = BY_NAME[name].ratio_of
    if pair is None:
        msg = f"metric {name!r} is not a rate of two counts"
        raise KeyError(msg)
    return pair


def pooled_rate(name: str, total: Counts) -> float | None:
    """The table's rate ``name`` of pooled counts; None without trials (nothing to show)."""
    return rate(name, total) if total.get(ratio_of(name)[1]) else None


def rate_interval(name: str, total: Counts) -> Interval:
    """The 95 % Wilson interval of the rate ``name`` of pooled counts; without trials the
    whole unit interval (these tables show ``[0, 1]`` there)."""
    numerator, denominator = ratio_of(name)
    low, high = stats.wilson_interval(total.get(numerator, 0), total.get(denominator, 0))
    return (0.0, 1.0) if low is None or high is None else (low, high)


# -- per episode ------------------------------------------------------------------------------
@dataclass(frozen=True)
class EpisodeLine:
    """One episode: counts, rates, tracking, RTT p50/p99 (ms), step rate, RTF; ``player`` the
    link to its player (HTML, set by the page)."""

    episode: str
    speed_mps: float | None
    seed: int | None
    complete: bool | None
    picked: int | None
    targeted: int | None
    missed: int | None
    processed: int | None
    placed_correct: int | None
    success_rate: float | None
    miss_rate: float | None
    tracking_time_4mm_mean_s: float | None
    rtt_ms_p50: float | None
    rtt_ms_p99: float | None
    step_rate_hz_mean: float | None
    real_time_factor: float | None
    player: str | None = None


def episode_rows(data: RunData) -> list[EpisodeLine]:
    """One row per episode: counts, rates, tracking, RTT p50/p99 (ms), step rate, RTF."""
    rows = []
    for ep in data.episodes:
        total = counts(ep) or {}
        summary = ep.summary
        p50 = summary.latency.rtt_ms_p50 if summary is not None else None
        p99 = summary.latency.rtt_ms_p99 if summary is not None else None
        rows.append(
            EpisodeLine(
                episode=ep.name,
                speed_mps=ep.speed_mps,
                seed=ep.seed,
                complete=summary.complete if summary is not None else None,
                picked=total.get("picked"),
                targeted=total.get("targeted"),
                missed=total.get("missed"),
                processed=total.get("processed"),
                placed_correct=total.get("placed_correct"),
                success_rate=pooled_rate("success_rate", total),
                miss_rate=pooled_rate("miss_rate", total),
                tracking_time_4mm_mean_s=stats.mean_of(ep.tracking_times_s),
                rtt_ms_p50=p50 if p50 is not None else percentile(ep.rtt_ms, 50),
                rtt_ms_p99=p99 if p99 is not None else percentile(ep.rtt_ms, 99),
                step_rate_hz_mean=summary.step_rate_hz_mean if summary is not None else None,
                real_time_factor=summary.real_time_factor if summary is not None else None,
            )
        )
    return rows


# -- per cell and belt speed ------------------------------------------------------------------
@dataclass(frozen=True)
class SpeedLine:
    """One cell at one belt speed over its pooled episodes."""

    cell: str
    stations: int
    speed_mps: float
    episodes: int
    picks: int | None
    totals: Counts
    """The pooled counts by name (empty when no episode has metrics)."""
    pick_throughput_per_min: float | None
    recovery_rate: float | None
    recovery_ci95: Interval
    success_rate: float | None
    success_ci95: Interval
    miss_rate: float | None
    miss_ci95: Interval
    tracking_time_4mm_mean_s: float | None
    rtt_ms_p50: float | None
    rtt_ms_p99: float | None
    real_time_factor: float | None


def _picks_per_min(blocks: Iterable[Metrics | None]) -> float | None:
    return stats.mean_of(b.get("pick_throughput_per_min") for b in blocks if b is not None)


def speed_rows(data: RunData) -> list[SpeedLine]:
    """One row per cell and belt speed over the pooled episodes (rates with Wilson 95 %
    intervals; picks per minute the mean over the episodes)."""
    rows = []
    for cell, speed in data.groups():
        eps = data.in_group(cell, speed)
        total = pooled(counts(ep) for ep in eps)
        rtt = [v for ep in eps for v in ep.rtt_ms]
        summaries = [ep.summary for ep in eps if ep.summary is not None]
        p50s = [s.latency.rtt_ms_p50 for s in summaries]
        p99s = [s.latency.rtt_ms_p99 for s in summaries]
        rows.append(
            SpeedLine(
                cell=cell,
                stations=eps[0].n_stations,
                speed_mps=speed,
                episodes=len(eps),
                picks=total.get("picked"),
                totals=total,
                pick_throughput_per_min=_picks_per_min(
                    ep.metrics.line.values if ep.metrics is not None else None for ep in eps
                ),
                recovery_rate=pooled_rate("recovery_rate", total),
                recovery_ci95=rate_interval("recovery_rate", total),
                success_rate=pooled_rate("success_rate", total),
                success_ci95=rate_interval("success_rate", total),
                miss_rate=pooled_rate("miss_rate", total),
                miss_ci95=rate_interval("miss_rate", total),
                tracking_time_4mm_mean_s=stats.mean_of(
                    t for ep in eps for t in ep.tracking_times_s
                ),
                rtt_ms_p50=percentile(rtt, 50) if rtt else stats.mean_of(p50s),
                rtt_ms_p99=percentile(rtt, 99) if rtt else stats.mean_of(p99s),
                real_time_factor=stats.mean_of(s.real_time_factor for s in summaries),
            )
        )
    return rows


# -- per cell, belt speed and station ---------------------------------------------------------
@dataclass(frozen=True)
class StationLine:
    """One station of a cell at one belt speed over the pooled episodes."""

    cell: str
    speed_mps: float
    station: str
    episodes: int
    picks: int | None
    pick_throughput_per_min: float | None
    placed_correct: int | None
    targeted: int | None
    recovery_rate: float | None
    success_rate: float | None
    success_ci95: Interval
    miss_rate: float | None
    miss_ci95: Interval
    tracking_time_4mm_mean_s: float | None


def station_rows(data: RunData) -> list[StationLine]:
    """One row per cell, belt speed and station over the pooled episodes (rates with Wilson
    95 % intervals), from each episode's station metrics."""
    rows = []
    for cell, speed in data.groups():
        eps = data.in_group(cell, speed)
        for station in data.stations(eps):
            total = pooled(counts(ep, station) for ep in eps)
            blocks: list[Metrics] = []
            for ep in eps:
                block = ep.metrics.stations.get(station) if ep.metrics is not None else None
                blocks.append(block.values if block is not None else {})
            rows.append(
                StationLine(
                    cell=cell,
                    speed_mps=speed,
                    station=station,
                    episodes=len(eps),
                    picks=total.get("picked"),
                    pick_throughput_per_min=_picks_per_min(blocks),
                    placed_correct=total.get("placed_correct"),
                    targeted=total.get("targeted"),
                    recovery_rate=pooled_rate("recovery_rate", total),
                    success_rate=pooled_rate("success_rate", total),
                    success_ci95=rate_interval("success_rate", total),
                    miss_rate=pooled_rate("miss_rate", total),
                    miss_ci95=rate_interval("miss_rate", total),
                    tracking_time_4mm_mean_s=stats.mean_of(
                        b.get("tracking_time_4mm_mean_s") for b in blocks
                    ),
                )
            )
    return rows


SPEED_COLUMNS = (
    ("cell", "cell"),
    ("stations", "stations"),
    ("speed_mps", "speed (m/s)"),
    ("episodes", "episodes"),
    ("picks", "picks"),
    ("pick_throughput_per_min", "picks/min"),
    ("recovery_rate", "recovery"),
    ("recovery_ci95", "recovery 95% CI"),
    ("success_rate", "success"),
    ("success_ci95", "success 95% CI"),
    ("miss_rate", "miss"),
    ("miss_ci95", "miss 95% CI"),
    ("tracking_time_4mm_mean_s", "tracking to 4 mm, mean (s)"),
    ("rtt_ms_p50", "RTT p50 (ms)"),
    ("rtt_ms_p99", "RTT p99 (ms)"),
    ("real_time_factor", "RTF"),
)
STATION_COLUMNS = (
    ("cell", "cell"),
    ("speed_mps", "speed (m/s)"),
    ("station", "station"),
    ("episodes", "episodes"),
    ("picks", "picks"),
    ("pick_throughput_per_min", "picks/min"),
    ("placed_correct", "placed correct"),
    ("targeted", "targeted"),
    ("recovery_rate", "recovery"),
    ("success_rate", "success"),
    ("success_ci95", "success 95% CI"),
    ("miss_rate", "miss"),
    ("miss_ci95", "miss 95% CI"),
    ("tracking_time_4mm_mean_s", "tracking to 4 mm, mean (s)"),
)
EPISODE_COLUMNS = (
    ("episode", "episode"),
    ("speed_mps", "speed (m/s)"),
    ("seed", "seed"),
    ("complete", "complete"),
    ("picked", "picks"),
    ("targeted", "targeted"),
    ("success_rate", "success"),
    ("miss_rate", "miss"),
    ("tracking_time_4mm_mean_s", "tracking mean (s)"),
    ("rtt_ms_p50", "RTT p50 (ms)"),
    ("rtt_ms_p99", "RTT p99 (ms)"),
    ("step_rate_hz_mean", "steps/s"),
    ("real_time_factor", "RTF"),
    ("player", "player"),
)

__all__ = [
    "COUNT_KEYS",
    "EPISODE_COLUMNS",
    "SPEED_COLUMNS",
    "STATION_COLUMNS",
    "EpisodeLine",
    "SpeedLine",
    "StationLine",
    "counts",
    "episode_rows",
    "pooled",
    "pooled_rate",
    "rate_interval",
    "speed_rows",
    "station_rows",
]
