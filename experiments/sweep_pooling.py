"""The sweep's pooling: per grid cell the mean and 95 % Student t interval of every metric over
its episodes, the pooled rates with their Wilson intervals (:mod:`experiments.stats`), the
reasons and the classes, the headline of a cell, and ``sweep.csv``. It reads the rows each
episode's run wrote (``episodes.json``) and never scores an episode again.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from experiments.stats import student_t_interval, wilson_interval
from interfaces.metrics import BY_NAME, METRICS, RATES, Scope, in_scope

if TYPE_CHECKING:
    pass


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


def _interval(values: Sequence[float]) -> dict[str, Any]:
    mean, low, high = student_t_interval(values)
    return {"mean": mean, "ci95_low": low, "ci95_high": high, "n": len(values)}


def _pooled(rows: Sequence[dict[str, Any]], num: str, den: str) -> dict[str, Any]:
    successes = sum(int(r.get(num) or 0) for r in rows)
    trials = sum(int(r.get(den) or 0) for r in rows)
    low, high = wilson_interval(successes, trials)
    return {
        "successes": successes,
        "trials": trials,
        "pooled": successes / trials if trials else None,
        "ci95_low": low,
        "ci95_high": high,
    }


def aggregate_reasons(rows: Sequence[dict[str, Any]], block: str) -> dict[str, dict[str, Any]]:
    """Per reason of the episodes' ``block`` (:data:`REASON_BLOCKS`), its mean with a Student t
    interval over the episodes that have the block (a reason one of them lacks counts 0 there);
    reasons sorted."""
    blocks = [r[block] for r in rows if isinstance(r.get(block), dict)]
    reasons = sorted({str(k) for b in blocks for k in b})
    return {reason: _interval([float(b.get(reason) or 0.0) for b in blocks]) for reason in reasons}


def aggregate_cell(
    rows: Sequence[dict[str, Any]],
    metrics: Sequence[str] = CI_METRICS,
    rates: dict[str, tuple[str, str]] | None = None,
) -> dict[str, Any]:
    """Per-metric ``{mean, ci95_low, ci95_high, n}``, pooled Wilson intervals of the rates and,
    per reason, the untargeted objects and the drops (:data:`REASON_BLOCKS`, those the rows
    have).

    ``rows`` are rows of ``episodes.json`` as written (:meth:`EpisodeMetrics.to_data`; or their
    ``stations`` or ``classes`` blocks, with ``metrics`` and ``rates`` of that scope); a metric
    that is None in an episode (e.g. no settled pursuit) leaves that episode out of that metric
    only. Failed episodes (``"failed": true``) are counted in ``failed`` and left out of
    everything else.
    """
    rates = WILSON_RATES if rates is None else rates
    failed = sum(1 for r in rows if r.get("failed"))
    rows = [r for r in rows if not r.get("failed")]
    out: dict[str, Any] = {"episodes": len(rows), "failed": failed, "metrics": {}, "wilson": {}}
    for key in metrics:
        out["metrics"][key] = _interval([float(r[key]) for r in rows if r.get(key) is not None])
    for rate, (num, den) in rates.items():
        out["wilson"][rate] = _pooled(rows, num, den)
    for block in REASON_BLOCKS:
        if any(block in r for r in rows):
            out[block] = aggregate_reasons(rows, block)
    return out


def _aggregate_entries(
    rows: Sequence[dict[str, Any]],
    block: str,
    metrics: Sequence[str],
    rates: dict[str, tuple[str, str]],
) -> dict[str, dict[str, Any]]:
    good = [r for r in rows if not r.get("failed")]
    names: dict[str, None] = {}
    for row in good:
        names.update(dict.fromkeys(row.get(block) or {}))
    return {
        name: aggregate_cell(
            [r[block][name] for r in good if name in (r.get(block) or {})], metrics, rates
        )
        for name in names
    }


def aggregate_stations(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """:func:`aggregate_cell` of each station's block over the successful episodes."""
    return _aggregate_entries(rows, "stations", STATION_CI_METRICS, STATION_WILSON_RATES)


def aggregate_classes(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """:func:`aggregate_cell` of each object class's block (the line's, per class: recovery,
    purity, ...) over the successful episodes; classes sorted."""
    out = _aggregate_entries(rows, "classes", CLASS_CI_METRICS, CLASS_WILSON_RATES)
    return dict(sorted(out.items()))


def headline(cell: dict[str, Any], names: Sequence[str]) -> list[dict[str, Any]]:
    """The grid's ``headline`` metrics of one grid cell's entry of ``sweep.json``: one row per
    metric and scope (the line's when the table gives the metric for the line, else each
    station's), with the mean, its 95 % Student t interval over the seeds and, for a rate, the
    pooled value with its Wilson interval."""
    agg = cell["aggregate"]
    rows = []
    for name in names:
        scopes = (
            [("line", agg)]
            if "line" in BY_NAME[name].scopes
            else [(f"station {s}", a) for s, a in (agg.get("stations") or {}).items()]
        )
        for scope, block in scopes:
            row: dict[str, Any] = {
                "cell": cell["cell"],
                "stations": len(cell["stations"]),
                "speed_mps": cell["speed_mps"],
                "metric": name,
                "scope": scope,
                **block["metrics"].get(name, _interval([])),
            }
            wilson = block["wilson"].get(name)
            if wilson is not None:
                row["pooled"] = wilson["pooled"]
                row["wilson_low"] = wilson["ci95_low"]
                row["wilson_high"] = wilson["ci95_high"]
            rows.append(row)
    return rows


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


def _csv_row(cell: dict[str, Any], station: str, agg: dict[str, Any]) -> list[Any]:
    row: list[Any] = [
        cell["cell"],
        station,
        cell["scenario"],
        cell["mode"],
        cell["speed_mps"],
        cell["duration_s"],
        agg["episodes"],
        agg.get("failed", 0),
    ]
    for key in CSV_METRICS:
        m = agg["metrics"].get(key)
        row += [None, None, None] if m is None else [m["mean"], m["ci95_low"], m["ci95_high"]]
    for rate in CSV_RATES:
        w = agg["wilson"].get(rate)
        row += [None, None, None] if w is None else [w["pooled"], w["ci95_low"], w["ci95_high"]]
    return ["" if v is None else v for v in row]


def sweep_csv(cells: Sequence[dict[str, Any]]) -> str:
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
        agg = cell["aggregate"]
        stations = agg.get("stations") or {}
        if len(stations) == 1:
            (only,) = stations.values()
            agg = {
                **agg,
                "metrics": {**only["metrics"], **agg["metrics"]},
                "wilson": {**only["wilson"], **agg["wilson"]},
            }
        writer.writerow(_csv_row(cell, "", agg))
        if len(stations) > 1:
            for name, station_agg in stations.items():
                writer.writerow(_csv_row(cell, name, station_agg))
    return buffer.getvalue()
