"""The report's line tables: recovery against the number of stations, recovery and purity per
class, purity per bin.

Every number comes from the episodes' metrics (each run's ``episodes.json``): recovery against
the number of stations is the mean over the episodes (seeds) of each episode's line
``recovery_rate`` with its 95 % Student t interval, grouped by the number of stations of the
episode's cell and the belt speed (a sweep over ``stations: [1, 2, 3, 4]`` and speeds gives one
group per grid cell); per class and per bin, rates pool the counts of every episode of a cell at
a speed (95 % Wilson intervals, :func:`experiments.stats.wilson_interval`; None without
trials). The figure of the first is :func:`experiments.report_figures.fig_recovery_stations`.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from experiments import stats
from experiments.report_data import Episode, RunData
from experiments.report_tables import Counts, Interval, ratio_of
from interfaces.metrics import rate
from interfaces.run_records import Metrics


def _sum_blocks(blocks: Iterable[Metrics], keys: Sequence[str]) -> Counts:
    total = dict.fromkeys(keys, 0)
    for block in blocks:
        for key in keys:
            total[key] += int(block.get(key) or 0)
    return total


def _pooled(name: str, total: Counts) -> tuple[float | None, Interval | None]:
    """The table's rate ``name`` of pooled counts with its Wilson interval; (None, None)
    without trials."""
    numerator, denominator = ratio_of(name)
    if not total.get(denominator):
        return None, None
    low, high = stats.wilson_interval(total[numerator], total[denominator])
    interval = None if low is None or high is None else (low, high)
    return rate(name, total), interval


@dataclass(frozen=True)
class StationsLine:
    """Line recovery of the episodes of one number of stations at one belt speed."""

    stations: int
    speed_mps: float
    episodes: int
    recovery_mean: float | None
    recovery_ci95: Interval | None
    """The 95 % Student t interval of the mean (None for fewer than two episodes)."""
    recovery_pooled: float | None
    recovery_wilson: Interval | None


def recovery_by_stations(data: RunData) -> list[StationsLine]:
    """One row per number of stations and belt speed: episodes, the mean line recovery over
    them with its 95 % Student t interval (None for fewer than two), and the pooled recovery
    (recovered / entered, summed over the episodes: the table's ``recovery_rate`` of the
    pooled counts) with its Wilson interval. An episode whose recovery is undefined (nothing
    entered) is left out of the mean."""
    groups: dict[tuple[int, float], list[Episode]] = {}
    for ep in data.episodes:
        if ep.metrics is not None and ep.speed_mps is not None:
            groups.setdefault((ep.n_stations, ep.speed_mps), []).append(ep)
    rows = []
    for (n, speed), eps in sorted(groups.items()):
        lines = [ep.metrics.line for ep in eps if ep.metrics is not None]
        values = [float(v) for v in (line.get("recovery_rate") for line in lines) if v is not None]
        mean, low, high = stats.student_t_interval(values)
        total = _sum_blocks((line.values for line in lines), ("recovered", "entered"))
        pooled, wilson = _pooled("recovery_rate", total)
        rows.append(
            StationsLine(
                stations=n,
                speed_mps=speed,
                episodes=len(values),
                recovery_mean=mean,
                recovery_ci95=None if low is None or high is None else (low, high),
                recovery_pooled=pooled,
                recovery_wilson=wilson,
            )
        )
    return rows


@dataclass(frozen=True)
class ClassLine:
    """One object class of a cell at one belt speed, pooled over the episodes."""

    cell: str
    speed_mps: float
    class_name: str
    episodes: int
    entered: int
    recovered: int
    placed_correct: int
    binned: int
    recovery_rate: float | None
    recovery_ci95: Interval | None
    purity: float | None
    purity_ci95: Interval | None


def class_rows(data: RunData) -> list[ClassLine]:
    """One row per cell, belt speed and object class: objects of the class that entered (the
    complete cohort's) and those of them placed in their bin, recovery; objects of the class
    in its bins and those of any class, purity (pooled over the episodes, Wilson 95 %
    intervals)."""
    rows = []
    for cell, speed in data.groups():
        eps = data.in_group(cell, speed)
        classes = [ep.metrics.classes for ep in eps if ep.metrics is not None]
        for name in sorted({c for by_class in classes for c in by_class}):
            blocks = [by_class.get(name) or {} for by_class in classes]
            total = _sum_blocks(blocks, ("entered", "recovered", "placed_correct", "binned"))
            recovery, recovery_ci = _pooled("recovery_rate", total)
            purity, purity_ci = _pooled("purity", total)
            rows.append(
                ClassLine(
                    cell=cell,
                    speed_mps=speed,
                    class_name=name,
                    episodes=len(eps),
                    entered=total["entered"],
                    recovered=total["recovered"],
                    placed_correct=total["placed_correct"],
                    binned=total["binned"],
                    recovery_rate=recovery,
                    recovery_ci95=recovery_ci,
                    purity=purity,
                    purity_ci95=purity_ci,
                )
            )
    return rows


@dataclass(frozen=True)
class BinLine:
    """One bin of a station of a cell at one belt speed, pooled over the episodes."""

    cell: str
    speed_mps: float
    station: str
    bin: str
    episodes: int
    binned: int
    placed_correct: int
    purity: float | None
    purity_ci95: Interval | None


def bin_rows(data: RunData) -> list[BinLine]:
    """One row per cell, belt speed, station and bin something came to rest in: objects in it,
    those of its class, purity (pooled over the episodes, Wilson 95 % interval)."""
    rows = []
    for cell, speed in data.groups():
        eps = data.in_group(cell, speed)
        stations: dict[str, dict[str, list[Metrics]]] = {}
        for ep in eps:
            for station, block in (ep.metrics.stations if ep.metrics is not None else {}).items():
                for bin_name, scores in (block.bins or {}).items():
                    stations.setdefault(station, {}).setdefault(bin_name, []).append(scores)
        for station, bins in stations.items():
            for bin_name, blocks in bins.items():
                total = _sum_blocks(blocks, ("binned", "placed_correct"))
                purity, purity_ci = _pooled("purity", total)
                rows.append(
                    BinLine(
                        cell=cell,
                        speed_mps=speed,
                        station=station,
                        bin=bin_name,
                        episodes=len(eps),
                        binned=total["binned"],
                        placed_correct=total["placed_correct"],
                        purity=purity,
                        purity_ci95=purity_ci,
                    )
                )
    return rows


STATIONS_COLUMNS = (
    ("stations", "stations"),
    ("speed_mps", "speed (m/s)"),
    ("episodes", "episodes"),
    ("recovery_mean", "recovery, mean"),
    ("recovery_ci95", "95% t interval"),
    ("recovery_pooled", "recovery, pooled"),
    ("recovery_wilson", "Wilson 95% CI"),
)
CLASS_COLUMNS = (
    ("cell", "cell"),
    ("speed_mps", "speed (m/s)"),
    ("class_name", "class"),
    ("episodes", "episodes"),
    ("entered", "entered"),
    ("recovered", "recovered"),
    ("recovery_rate", "recovery"),
    ("recovery_ci95", "recovery 95% CI"),
    ("placed_correct", "in its bins"),
    ("binned", "in its bins (any class)"),
    ("purity", "purity"),
    ("purity_ci95", "purity 95% CI"),
)
BIN_COLUMNS = (
    ("cell", "cell"),
    ("speed_mps", "speed (m/s)"),
    ("station", "station"),
    ("bin", "bin"),
    ("episodes", "episodes"),
    ("binned", "objects in it"),
    ("placed_correct", "of its class"),
    ("purity", "purity"),
    ("purity_ci95", "purity 95% CI"),
)
