"""What a sweep writes beside its cells' run folders: ``sweep.json`` (:class:`SweepSummary`, one
:class:`CellSummary` per grid cell, the :class:`HeadlineRow` rows first) and ``sweep.csv``
(:func:`sweep_csv`), built from each cell's pools (:mod:`experiments.sweep_pooling`).

Each record is frozen; its ``to_data`` is its part of ``sweep.json``, key for key in the order
the file has always had.
"""

from __future__ import annotations

import csv
import dataclasses
import io
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from experiments.sweep_pooling import (
    STATION_WILSON_RATES,
    WILSON_RATES,
    CellPool,
    Interval,
    PooledRate,
    ScopePool,
)
from interfaces.metrics import BY_NAME, METRICS

OverrideValue = float | int | str
"""A grid override's chosen value: a speed or duration, a station count, a mode or a cell."""


@dataclass(frozen=True, kw_only=True)
class BackendNote:
    """Where a sweep's episodes ran (``sweep.json``'s ``backend``): ``local``, or ``ray`` with
    the CPUs each task declared, the nodes that ran them, the CPU seconds the episodes used and
    the cluster's address (``local``: a Ray instance started for the sweep). A field is written
    only once known."""

    name: str = "local"
    cpus_per_episode: float | None = None
    nodes: tuple[str, ...] | None = None
    episode_cpu_s: float | None = None
    address: str | None = None

    def to_data(self) -> dict[str, object]:
        """As ``sweep.json`` holds it."""
        data: dict[str, object] = {"name": self.name}
        if self.cpus_per_episode is not None:
            data["cpus_per_episode"] = self.cpus_per_episode
        if self.nodes is not None:
            data["nodes"] = list(self.nodes)
        if self.episode_cpu_s is not None:
            data["episode_cpu_s"] = self.episode_cpu_s
        if self.address is not None:
            data["address"] = self.address
        return data


@dataclass(frozen=True, kw_only=True)
class CellSummary:
    """One grid cell's entry of ``sweep.json``: its settings, whether every seed succeeded, its
    failures and its pools (``aggregate``)."""

    cell: str
    folder: str
    scenario: str
    stations: tuple[str, ...]
    mode: str
    speed_mps: float
    duration_s: float
    overrides: Mapping[str, OverrideValue]
    complete: bool
    failures: tuple[str, ...]
    aggregate: CellPool

    @property
    def failed(self) -> int:
        """How many of the cell's episodes failed."""
        return self.aggregate.failed

    def to_data(self) -> dict[str, object]:
        """As ``sweep.json`` holds it."""
        return {
            "cell": self.cell,
            "folder": self.folder,
            "scenario": self.scenario,
            "stations": list(self.stations),
            "mode": self.mode,
            "speed_mps": self.speed_mps,
            "duration_s": self.duration_s,
            "overrides": dict(self.overrides),
            "complete": self.complete,
            "failed": self.failed,
            "failures": list(self.failures),
            "aggregate": self.aggregate.to_data(),
        }


@dataclass(frozen=True, kw_only=True)
class HeadlineRow:
    """One headline figure of a grid cell: a metric of one scope (``line`` or ``station S``),
    its mean and 95 % Student t interval over the seeds and, for a rate, the pooled rate."""

    cell: str
    stations: int
    speed_mps: float
    metric: str
    scope: str
    interval: Interval
    rate: PooledRate | None = None

    def to_data(self) -> dict[str, object]:
        """As ``sweep.json``'s ``headline`` holds it."""
        row: dict[str, object] = {
            "cell": self.cell,
            "stations": self.stations,
            "speed_mps": self.speed_mps,
            "metric": self.metric,
            "scope": self.scope,
            **self.interval.to_data(),
        }
        if self.rate is not None:
            row["pooled"] = self.rate.pooled
            row["wilson_low"] = self.rate.ci95_low
            row["wilson_high"] = self.rate.ci95_high
        return row


def headline(cell: CellSummary, names: Sequence[str]) -> list[HeadlineRow]:
    """The grid's ``headline`` metrics of one grid cell: one row per metric and scope (the
    line's when the table gives the metric for the line, else each station's), with the mean,
    its 95 % Student t interval over the seeds and, for a rate, the pooled value with its Wilson
    interval."""
    agg = cell.aggregate
    rows = []
    for name in names:
        scopes = (
            [("line", agg.line)]
            if "line" in BY_NAME[name].scopes
            else [(f"station {s}", pool) for s, pool in agg.stations.items()]
        )
        for scope, pool in scopes:
            interval = pool.metrics.get(name) or Interval.of([])
            rows.append(
                HeadlineRow(
                    cell=cell.cell,
                    stations=len(cell.stations),
                    speed_mps=cell.speed_mps,
                    metric=name,
                    scope=scope,
                    interval=interval,
                    rate=pool.wilson.get(name),
                )
            )
    return rows


@dataclass(frozen=True, kw_only=True)
class SweepSummary:
    """The content of ``sweep.json``: whether the sweep completed, its grid, how many episodes
    it planned, ran and lost, its wall time, the headline rows, every grid cell, where the
    episodes ran, the Ray tasks retried and, for a sweep that stopped, why."""

    complete: bool
    grid: str
    workers: int
    episodes_planned: int
    episodes: int
    failed: int
    wall_s: float
    headline: tuple[HeadlineRow, ...]
    cells: tuple[CellSummary, ...]
    backend: BackendNote
    retried: tuple[str, ...] = ()
    stopped: str | None = None

    def to_data(self) -> dict[str, object]:
        """As ``sweep.json`` holds it (``retried`` and ``stopped`` only when there are any)."""
        data: dict[str, object] = {
            "complete": self.complete,
            "grid": self.grid,
            "workers": self.workers,
            "episodes_planned": self.episodes_planned,
            "episodes": self.episodes,
            "failed": self.failed,
            "wall_s": self.wall_s,
            "headline": [row.to_data() for row in self.headline],
            "cells": [cell.to_data() for cell in self.cells],
            "backend": self.backend.to_data(),
        }
        if self.retried:
            data["retried"] = list(self.retried)
        if self.stopped:
            data["stopped"] = self.stopped
        return data

    def stop_note(self) -> dict[str, object]:
        """The short ``sweep.json`` written in place when the tables cannot be written."""
        data = self.to_data()
        return {k: data.get(k) for k in ("complete", "grid", "episodes", "failed", "stopped")}


CSV_HEADER = (
    "cell",
    "station",
    "scenario",
    "mode",
    "speed_mps",
    "duration_s",
    "episodes",
    "failed",
)
"""The leading columns of ``sweep.csv``; then mean and interval of every metric and rate."""


CSV_METRICS = tuple(m.name for m in METRICS if {"line", "station"} & set(m.scopes))
"""The metric columns of ``sweep.csv``: every metric given for the line or per station."""


CSV_RATES = {**WILSON_RATES, **STATION_WILSON_RATES}
"""The pooled-rate columns of ``sweep.csv``."""


CsvValue = str | float | int
"""A value of a ``sweep.csv`` row (an empty string where there is none)."""


def _csv_row(cell: CellSummary, station: str, pool: ScopePool) -> list[CsvValue]:
    row: list[CsvValue | None] = [
        cell.cell,
        station,
        cell.scenario,
        cell.mode,
        cell.speed_mps,
        cell.duration_s,
        pool.episodes,
        pool.failed,
    ]
    for key in CSV_METRICS:
        m = pool.metrics.get(key)
        row += [None, None, None] if m is None else [m.mean, m.ci95_low, m.ci95_high]
    for rate in CSV_RATES:
        w = pool.wilson.get(rate)
        row += [None, None, None] if w is None else [w.pooled, w.ci95_low, w.ci95_high]
    return ["" if v is None else v for v in row]


def sweep_csv(cells: Sequence[CellSummary]) -> str:
    """``sweep.csv``: one row per grid cell (``station`` empty: the line), mean and interval of
    every metric, and for a cell of several stations one more row per station (a metric not
    given per station, or not for the line, is left empty; in a cell of one station the line
    is the station, so its row also gives the per-station metrics, such as ``unfit_share``)."""
    header = list(CSV_HEADER)
    for key in CSV_METRICS:
        header += [f"{key}_mean", f"{key}_ci95_low", f"{key}_ci95_high"]
    for rate in CSV_RATES:
        header += [f"{rate}_pooled", f"{rate}_wilson_low", f"{rate}_wilson_high"]
    buffer = io.StringIO()
    writer = csv.writer(buffer)
    writer.writerow(header)
    for cell in cells:
        line = cell.aggregate.line
        stations = cell.aggregate.stations
        if len(stations) == 1:
            (only,) = stations.values()
            line = dataclasses.replace(
                line,
                metrics={**only.metrics, **line.metrics},
                wilson={**only.wilson, **line.wilson},
            )
        writer.writerow(_csv_row(cell, "", line))
        if len(stations) > 1:
            for name, pool in stations.items():
                writer.writerow(_csv_row(cell, name, pool))
    return buffer.getvalue()
