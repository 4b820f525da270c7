"""The report's line tables and figure: recovery against the number of stations, recovery and
purity per class, purity per bin.

Every number comes from the episodes' metrics (each run's ``episodes.json``): recovery against
the number of stations is the mean over the episodes (seeds) of each episode's line
``recovery_rate`` with its 95 % Student t interval, grouped by the number of stations of the
episode's cell and the belt speed (a sweep over ``stations: [1, 2, 3, 4]`` and speeds gives one
group per grid cell); per class and per bin,
rates pool the counts of every episode of a cell at a speed (Wilson 95 % intervals).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

from experiments import stats
from interfaces.metrics import rate

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from experiments.report_data import Episode, RunData


def _wilson(successes: int, trials: int) -> tuple[float, float] | None:
    low, high = stats.wilson_interval(successes, trials)
    return None if low is None or high is None else (low, high)


def recovery_by_stations(data: RunData) -> list[dict[str, Any]]:
    """One row per number of stations and belt speed: episodes, the mean line recovery over
    them with its 95 % Student t interval (None for fewer than two), and the pooled recovery
    (recovered / entered, summed over the episodes: the table's ``recovery_rate`` of the
    pooled counts) with its Wilson interval."""
    groups: dict[tuple[int, float], list[Episode]] = {}
    for ep in data.episodes:
        if ep.metrics is not None and ep.speed_mps is not None:
            groups.setdefault((ep.n_stations, ep.speed_mps), []).append(ep)
    rows = []
    for (n, speed), eps in sorted(groups.items()):
        values = [float(ep.metrics["recovery_rate"]) for ep in eps if ep.metrics]
        mean, low, high = stats.student_t_interval(values)
        total = _sum_blocks(((ep.metrics or {}) for ep in eps), ("recovered", "entered"))
        pooled, wilson = _pooled("recovery_rate", total)
        rows.append(
            {
                "stations": n,
                "speed_mps": speed,
                "episodes": len(values),
                "recovery_mean": mean,
                "recovery_ci95": None if low is None or high is None else (low, high),
                "recovery_pooled": pooled,
                "recovery_wilson": wilson,
            }
        )
    return rows


def _sum_blocks(blocks: Iterable[dict[str, Any]], keys: Sequence[str]) -> dict[str, int]:
    total = dict.fromkeys(keys, 0)
    for block in blocks:
        for key in keys:
            total[key] += int(block.get(key) or 0)
    return total


def _pooled(name: str, total: dict[str, int]) -> tuple[float | None, tuple[float, float] | None]:
    from interfaces.metrics import BY_NAME

    pair = BY_NAME[name].ratio_of
    if pair is None:
        msg = f"metric {name!r} is not a rate of two counts"
        raise KeyError(msg)
    numerator, denominator = pair
    if not total.get(denominator):
        return None, None
    return rate(name, total), _wilson(total[numerator], total[denominator])


def class_rows(data: RunData) -> list[dict[str, Any]]:
    """One row per cell, belt speed and object class: objects of the class that entered (the
    complete cohort's) and those of them placed in their bin, recovery; objects of the class
    in its bins and those of any class, purity (pooled over the episodes, Wilson 95 %
    intervals)."""
    rows = []
    for cell, speed in data.groups():
        eps = data.in_group(cell, speed)
        names = sorted({c for ep in eps for c in ((ep.metrics or {}).get("classes") or {})})
        for name in names:
            blocks = [((ep.metrics or {}).get("classes") or {}).get(name) or {} for ep in eps]
            total = _sum_blocks(blocks, ("entered", "recovered", "placed_correct", "binned"))
            recovery, recovery_ci = _pooled("recovery_rate", total)
            purity, purity_ci = _pooled("purity", total)
            rows.append(
                {
                    "cell": cell,
                    "speed_mps": speed,
                    "class": name,
                    "episodes": len(eps),
                    **total,
                    "recovery_rate": recovery,
                    "recovery_ci95": recovery_ci,
                    "purity": purity,
                    "purity_ci95": purity_ci,
                }
            )
    return rows


def bin_rows(data: RunData) -> list[dict[str, Any]]:
    """One row per cell, belt speed, station and bin something came to rest in: objects in it,
    those of its class, purity (pooled over the episodes, Wilson 95 % interval)."""
    rows = []
    for cell, speed in data.groups():
        eps = data.in_group(cell, speed)
        stations: dict[str, dict[str, list[dict[str, Any]]]] = {}
        for ep in eps:
            for station, block in ((ep.metrics or {}).get("stations") or {}).items():
                for bin_name, scores in (block.get("bins") or {}).items():
                    stations.setdefault(station, {}).setdefault(bin_name, []).append(scores)
        for station, bins in stations.items():
            for bin_name, blocks in bins.items():
                total = _sum_blocks(blocks, ("binned", "placed_correct"))
                purity, purity_ci = _pooled("purity", total)
                rows.append(
                    {
                        "cell": cell,
                        "speed_mps": speed,
                        "station": station,
                        "bin": bin_name,
                        "episodes": len(eps),
                        **total,
                        "purity": purity,
                        "purity_ci95": purity_ci,
                    }
                )
    return rows


def fig_recovery_stations(data: RunData) -> Figure:
    """Line recovery against the number of stations, one line per belt speed: the mean over
    the episodes (seeds) with its 95 % Student t interval."""
    from experiments.report_data import Unavailable
    from experiments.report_plot import new_figure, speed_colour

    rows = [r for r in recovery_by_stations(data) if r["recovery_mean"] is not None]
    if not rows:
        msg = "no episode has metrics (events, summary and controller stats)"
        raise Unavailable(msg)
    fig = new_figure()
    ax = fig.add_subplot()
    speeds = sorted({r["speed_mps"] for r in rows})
    for i, speed in enumerate(speeds):
        line = [r for r in rows if r["speed_mps"] == speed]
        dx = 0.04 * (i - (len(speeds) - 1) / 2)  # side by side, so equal values stay apart
        xs = [r["stations"] + dx for r in line]
        ys = [r["recovery_mean"] for r in line]
        spans = [r["recovery_ci95"] or (r["recovery_mean"], r["recovery_mean"]) for r in line]
        lo = [y - a for y, (a, _) in zip(ys, spans, strict=True)]
        hi = [b - y for y, (_, b) in zip(ys, spans, strict=True)]
        colour = speed_colour(data, speed)
        ax.errorbar(xs, ys, yerr=[lo, hi], fmt="o-", capsize=4, color=colour, label=f"{speed} m/s")
        for x, y, r in zip(xs, ys, line, strict=True):
            ax.annotate(
                f"n={r['episodes']}",
                (x, y),
                textcoords="offset points",
                xytext=(5, -10),
                fontsize=7,
            )
    ax.set_xticks(sorted({r["stations"] for r in rows}))
    ax.set_ylim(-0.02, 1.05)
    ax.set_xlabel("stations along the belt")
    ax.set_ylabel("recovery (mean, 95 % t interval over seeds)")
    ax.set_title("Recovery against the number of stations")
    ax.legend(title="belt speed", fontsize="small")
    ax.grid(alpha=0.3)
    return fig


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
    ("class", "class"),
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
