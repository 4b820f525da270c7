"""``cdw-twin report``: an offline HTML report with figures from ``cdw-twin run`` folders.

Example::

    cdw-twin report runs/a runs/b --out runs/report
    cdw-twin report runs/            # a folder of run folders

Writes ``report.html`` and one PNG per figure into ``--out`` (default: ``<first RUN_DIR>/report``).
The report is built in a hidden folder next to ``--out`` and put in its place whole when it is
finished (:mod:`experiments.outdir`): an interrupted report leaves the old one as it was. An
existing non-empty ``--out`` is refused unless ``--replace`` is given, and then replaced only
when it is a report (its ``.cdw-report`` marker file).
The page references its PNGs relatively and loads nothing from the network (no scripts). Episodes
of every run are pooled and grouped by belt speed. Figures:

1. step rate over wall time (first 60 s) per belt speed (``telemetry.json``, ``step_rate``);
2. belt setpoint against measured speed over sim time, one episode per speed (``belt``);
3. round-trip latency over wall time and 4. its histogram (``rtt``; see :mod:`twin.telemetry`);
5. tracking time to 4 mm per speed, one dot per settled pursuit (``summary.json``,
   ``tracking.tracking_times_s``), settled/pursuits noted above each speed;
6. success and miss rate per speed with 95 % Wilson score intervals over the pooled counts
   (``success_rate`` = sorted / targeted, ``miss_rate`` = missed / processed: the
   metric table's rates, ``docs/metrics.md``);
7. line recovery against the number of stations of the run's cell, one line per belt speed:
   the mean over the episodes (seeds) with its 95 % Student t interval
   (:mod:`experiments.report_line`; ``cdw-twin report`` on a sweep over ``stations`` x speed);
8. mesh-generation timing of the dataset against the reference (24 ms/image, 5.3 ms/object);
   meshgen records whole-run means only, so those are shown;
9. source polygons (the dataset's annotation files when found next to it, else the pixel polygon
   meshgen recorded in ``scene.json``) over the generated footprints (bottom face of each mesh,
   placed at its ``scene.csv`` centroid) for up to four images.

Every episode row links the episode's player (``epNNN/player.html``, written or refreshed
here by :mod:`experiments.player`: a self-contained page replaying the episode from above).

The tables give per cell and belt speed and per episode the line's numbers (picks per minute,
recovery, success, miss rate, ...) and, when a run has several stations, per cell, speed and
station each station's; then recovery against the number of stations, recovery and purity per
class, and the purity of each bin (runs of different cells at one speed are never pooled).
Every episode's numbers are its row of the run's ``episodes.json``, written once by the run
(:func:`experiments.scoring.score_episode`); the report never scores an episode again.

A figure whose data is missing becomes a "not available: <why>" panel. The dataset is
``run.json``'s ``dataset`` when present, else the run's ``scenario.yaml`` dataset, else the
built-in sample.
"""

from __future__ import annotations

import argparse
import html
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from experiments import stats
from experiments.report_data import (
    Episode,
    ReportError,
    RunData,
    Unavailable,
    episode_rtt_ms,
    episode_tracking_times,
    find_run_dirs,
    load_runs,
    percentile,
    wilson_interval,
)
from experiments.report_figures import (
    fig_belt,
    fig_footprints,
    fig_meshgen,
    fig_rtt_hist,
    fig_rtt_time,
    fig_step_rate,
    fig_tracking,
    save_png,
)
from experiments.report_line import (
    BIN_COLUMNS,
    CLASS_COLUMNS,
    STATIONS_COLUMNS,
    bin_rows,
    class_rows,
    fig_recovery_stations,
    recovery_by_stations,
)
from experiments.report_plot import new_figure
from interfaces.errors import CdwTwinError
from interfaces.fileio import write_atomic
from interfaces.metrics import BY_NAME, rate
from interfaces.run_folder import EpisodeFolder

if TYPE_CHECKING:
    from matplotlib.figure import Figure


# -- per-episode numbers ----------------------------------------------------------------------
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


def _counts(ep: Episode, station: str | None = None) -> dict[str, int] | None:
    """Pooled-count ingredients of one episode (the line's, or ``station``'s), None without
    its metrics."""
    block = ep.metrics
    if block is not None and station is not None:
        block = (block.get("stations") or {}).get(station)
    if block is None:
        return None
    return {key: int(block.get(key) or 0) for key in COUNT_KEYS}


def _ratio_of(name: str) -> tuple[str, str]:
    pair = BY_NAME[name].ratio_of
    if pair is None:
        msg = f"metric {name!r} is not a rate of two counts"
        raise KeyError(msg)
    return pair


def _pooled_rate(name: str, total: dict[str, int]) -> float | None:
    """The table's rate ``name`` of pooled counts; None without trials (nothing to show)."""
    return rate(name, total) if total.get(_ratio_of(name)[1]) else None


def _wilson(name: str, total: dict[str, int]) -> tuple[float, float]:
    numerator, denominator = _ratio_of(name)
    return wilson_interval(total.get(numerator, 0), total.get(denominator, 0))


def _pooled(counts: Sequence[dict[str, int] | None]) -> dict[str, int]:
    present = [c for c in counts if c is not None]
    return {k: sum(c[k] for c in present) for k in COUNT_KEYS} if present else {}


def episode_rows(data: RunData) -> list[dict[str, Any]]:
    """One row per episode: counts, rates, tracking, RTT p50/p99 (ms), step rate, RTF."""
    rows = []
    for ep in data.episodes:
        counts = _counts(ep) or {}
        latency = (ep.summary or {}).get("latency") or {}
        rtt = episode_rtt_ms(ep)
        rows.append(
            {
                "episode": ep.name,
                "speed_mps": ep.speed_mps,
                "seed": ep.seed,
                "complete": (ep.summary or {}).get("complete"),
                **counts,
                "success_rate": _pooled_rate("success_rate", counts),
                "miss_rate": _pooled_rate("miss_rate", counts),
                "tracking_time_4mm_mean_s": stats.mean_of(episode_tracking_times(ep)),
                "rtt_ms_p50": latency.get("rtt_ms_p50", percentile(rtt, 50)),
                "rtt_ms_p99": latency.get("rtt_ms_p99", percentile(rtt, 99)),
                "step_rate_hz_mean": (ep.summary or {}).get("step_rate_hz_mean"),
                "real_time_factor": (ep.summary or {}).get("real_time_factor"),
            }
        )
    return rows


def _picks_per_min(blocks: Sequence[dict[str, Any] | None]) -> float | None:
    return stats.mean_of((b or {}).get("pick_throughput_per_min") for b in blocks)


def speed_rows(data: RunData) -> list[dict[str, Any]]:
    """One row per cell and belt speed over the pooled episodes (rates with Wilson 95 %
    intervals; picks per minute the mean over the episodes)."""
    rows = []
    for cell, speed in data.groups():
        eps = data.in_group(cell, speed)
        total = _pooled([_counts(ep) for ep in eps])
        rtt = [v for ep in eps for v in episode_rtt_ms(ep)]
        latencies = [_latency(ep) for ep in eps]
        p50s = [float(x["rtt_ms_p50"]) for x in latencies if x.get("rtt_ms_p50") is not None]
        p99s = [float(x["rtt_ms_p99"]) for x in latencies if x.get("rtt_ms_p99") is not None]
        times = [t for ep in eps for t in episode_tracking_times(ep)]
        rtfs = [float(ep.summary["real_time_factor"]) for ep in eps if ep.summary]
        rows.append(
            {
                "cell": cell,
                "stations": eps[0].n_stations,
                "speed_mps": speed,
                "episodes": len(eps),
                "picks": total.get("picked"),
                **{f"{k}_total": v for k, v in total.items() if k != "picked"},
                "pick_throughput_per_min": _picks_per_min([ep.metrics for ep in eps]),
                "recovery_rate": _pooled_rate("recovery_rate", total),
                "recovery_ci95": _wilson("recovery_rate", total),
                "success_rate": _pooled_rate("success_rate", total),
                "success_ci95": _wilson("success_rate", total),
                "miss_rate": _pooled_rate("miss_rate", total),
                "miss_ci95": _wilson("miss_rate", total),
                "tracking_time_4mm_mean_s": stats.mean_of(times),
                "rtt_ms_p50": percentile(rtt, 50) if rtt else stats.mean_of(p50s),
                "rtt_ms_p99": percentile(rtt, 99) if rtt else stats.mean_of(p99s),
                "real_time_factor": stats.mean_of(rtfs),
            }
        )
    return rows


def station_rows(data: RunData) -> list[dict[str, Any]]:
    """One row per cell, belt speed and station over the pooled episodes (rates with Wilson
    95 % intervals), from each episode's station metrics."""
    rows = []
    for cell, speed in data.groups():
        eps = data.in_group(cell, speed)
        for station in data.stations(eps):
            total = _pooled([_counts(ep, station) for ep in eps])
            blocks = [((ep.metrics or {}).get("stations") or {}).get(station) or {} for ep in eps]
            rows.append(
                {
                    "cell": cell,
                    "speed_mps": speed,
                    "station": station,
                    "episodes": len(eps),
                    "picks": total.get("picked"),
                    "pick_throughput_per_min": _picks_per_min(blocks),
                    "placed_correct": total.get("placed_correct"),
                    "targeted": total.get("targeted"),
                    "recovery_rate": _pooled_rate("recovery_rate", total),
                    "success_rate": _pooled_rate("success_rate", total),
                    "success_ci95": _wilson("success_rate", total),
                    "miss_rate": _pooled_rate("miss_rate", total),
                    "miss_ci95": _wilson("miss_rate", total),
                    "tracking_time_4mm_mean_s": stats.mean_of(
                        b.get("tracking_time_4mm_mean_s") for b in blocks
                    ),
                }
            )
    return rows


def _latency(ep: Episode) -> dict[str, Any]:
    return dict((ep.summary or {}).get("latency") or {})


# -- figures ----------------------------------------------------------------------------------


# -- output -----------------------------------------------------------------------------------


def fig_rates(data: RunData) -> Figure:
    """Success and miss rate per speed with 95 % Wilson intervals over pooled counts."""
    rows = [
        r for r in speed_rows(data) if r["success_rate"] is not None or r["miss_rate"] is not None
    ]
    if not rows:
        msg = "no episode has both twin/summary.json scores and targeted objects or processed ones"
        raise Unavailable(msg)
    fig = new_figure()
    ax = fig.add_subplot()
    x = list(range(len(rows)))
    for offset, key, total, label, colour in (
        (-0.15, "success", "targeted_total", "success (correct bin / targeted)", "tab:green"),
        (0.15, "miss", "processed_total", "miss (missed / processed)", "tab:red"),
    ):
        xs, ys, lo, hi = [], [], [], []
        for i, row in enumerate(rows):
            rate = row[f"{key}_rate"]
            if rate is None:
                continue
            a, b = row[f"{key}_ci95"]
            xs.append(i + offset)
            ys.append(rate)
            lo.append(rate - a)
            hi.append(b - rate)
            ax.annotate(f"n={row[total]}", (i + offset, b), ha="center", va="bottom", fontsize=7)
        ax.errorbar(xs, ys, yerr=[lo, hi], fmt="o", capsize=4, color=colour, label=label)
    several = len({r["cell"] for r in rows}) > 1
    labels = [
        f"{r['cell']}\n{r['speed_mps']} m/s" if several else f"{r['speed_mps']} m/s" for r in rows
    ]
    ax.set_xticks(x, labels)
    ax.set_xlim(-0.6, len(rows) - 0.4)
    ax.set_ylim(-0.02, 1.1)
    ax.set_ylabel("rate (95 % Wilson interval, pooled episodes)")
    ax.set_xlabel("cell and belt speed" if several else "belt speed")
    ax.set_title("Success and miss rate per belt speed")
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3, axis="y")
    return fig


FIGURES: tuple[tuple[str, str, Callable[[RunData], Figure]], ...] = (
    ("step_rate", "Step rate over 60 s per belt speed", fig_step_rate),
    ("belt", "Belt velocity setpoint against actual", fig_belt),
    ("rtt_time", "Round-trip latency over time", fig_rtt_time),
    ("rtt_hist", "Round-trip latency histogram", fig_rtt_hist),
    ("tracking", "Tracking time to 4 mm per speed", fig_tracking),
    ("rates", "Success and miss rate per speed (95 % Wilson intervals)", fig_rates),
    ("recovery_stations", "Recovery against the number of stations", fig_recovery_stations),
    ("meshgen", "Mesh-generation timing", fig_meshgen),
    ("footprints", "Source polygons over generated footprints", fig_footprints),
)
"""``(file stem, heading, figure function)`` in page order."""


class _Html(str):
    """Table cell text that is already HTML (not escaped again)."""

    __slots__ = ()


def _fmt(value: Any, digits: int = 3) -> str:
    if isinstance(value, _Html):
        return str(value)
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    if isinstance(value, tuple):
        return "[" + ", ".join(_fmt(v, 2) for v in value) + "]"
    return html.escape(str(value))


def _table(rows: list[dict[str, Any]], columns: Sequence[tuple[str, str]]) -> str:
    head = "".join(f"<th>{html.escape(title)}</th>" for _, title in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{_fmt(row.get(key))}</td>" for key, _ in columns) + "</tr>"
        for row in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


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

_CSS = (
    "body{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222}"
    "table{border-collapse:collapse;font-size:0.85em;margin-bottom:1.5em}"
    "th,td{border:1px solid #bbb;padding:0.25em 0.5em;text-align:right}"
    "th{background:#eee}figure{margin:1.5em 0}img{max-width:100%}"
    ".na{border:2px dashed #c33;background:#fee;padding:1em;color:#900}"
    ".notes{font-size:0.8em;color:#666}"
)


def _station_section(data: RunData) -> str:
    """The per-station table, for runs of several stations (empty otherwise)."""
    if len(data.stations()) < 2:
        return ""
    return (
        '<h2 id="per-station">Per cell, belt speed and station</h2>'
        "<p>Each station's own events (its window, its bins) and its controller's targets; "
        "rates pool the counts of every episode of a cell at a speed.</p>"
        f"{_table(station_rows(data), STATION_COLUMNS)}"
    )


def _line_section(data: RunData) -> str:
    """Recovery against the number of stations, recovery and purity per class, purity per
    bin."""
    return (
        '<h2 id="recovery-stations">Recovery against the number of stations</h2>'
        "<p>Line recovery (objects placed in their class's bin / objects that entered the "
        "belt, both over the complete cohort: every object spawned before the first one still "
        "undecided at the end of the episode): the mean over the episodes (seeds) with its "
        "95 % Student t interval, and the pooled counts with a Wilson interval.</p>"
        f"{_table(recovery_by_stations(data), STATIONS_COLUMNS)}"
        '<h2 id="per-class">Per class: recovery and purity</h2>'
        "<p>Recovery: objects of the class placed in its bin / objects of the class that "
        "entered (those of the complete cohort, cut over every class). Purity: objects of the "
        "class / all objects that came to rest in the bins sorting it, over every station.</p>"
        f"{_table(class_rows(data), CLASS_COLUMNS)}"
        '<h2 id="per-bin">Per bin: purity</h2>'
        "<p>Objects of the bin's class / all objects that came to rest in it (bins nothing "
        f"came to rest in are left out).</p>{_table(bin_rows(data), BIN_COLUMNS)}"
    )


def _players(
    data: RunData, out: Path, notes: list[str], staging: Path | None = None
) -> list[_Html]:
    """Write (or refresh) each episode's player; a link to it, relative to ``out``.

    A player is rewritten when it is older than its episode's files or than the player's code
    or assets (:func:`experiments.player.page_sources`).
    An episode folder that cannot be written to gets its player in ``out/players/`` (written
    into ``staging``, the folder that becomes ``out``, when given).
    """
    from experiments.player import PAGE_NAME, page_sources, write_player

    code = page_sources()
    links = []
    for ep in data.episodes:
        page = ep.folder / PAGE_NAME
        episode = EpisodeFolder(ep.folder)
        inputs = [*code, episode.run.cell, episode.recording, episode.events]
        stamp = page.stat().st_mtime if page.is_file() else -1.0
        if any(p.is_file() and p.stat().st_mtime > stamp for p in inputs):
            try:
                written = write_player(ep.folder, ep.run_dir)
            except OSError:
                name = Path("players") / ep.run_dir.name / f"{ep.folder.name}.html"
                page = out / name
                written = write_player(ep.folder, ep.run_dir, (staging or out) / name)
            notes.extend(f"{ep.name} player: {note}" for note in written.notes)
        href = html.escape(Path(os.path.relpath(page, out)).as_posix(), quote=True)
        links.append(_Html(f'<a class="player" href="{href}">play</a>'))
    return links


def write_report(run_dirs: Sequence[Path], out: Path, *, replace: bool = False) -> Path:
    """Write ``report.html`` and its PNGs into ``out``, whole: built in a staging folder and
    swapped in when finished (:mod:`experiments.outdir`); returns the HTML path.

    Raises :class:`ReportError` when a path is not a run folder (nor a folder of them), and
    :class:`experiments.outdir.OutputError` when ``out`` exists and is not empty (unless
    ``replace`` and it is a report) or cannot be written.
    """
    from experiments.outdir import (
        REPORT,
        OutputError,
        check_output,
        discard,
        reason,
        staging_folder,
        swap_in,
    )

    out = Path(out)
    check_output(out, REPORT, replace=replace)
    data = load_runs(run_dirs)
    staging = staging_folder(out, REPORT, replace=replace)
    try:
        _write_pages(data, out, staging)
        swap_in(staging, out, REPORT, replace=replace)
    except OSError as exc:
        discard(staging)
        msg = f"--out {out}: cannot write the report: {reason(exc)}"
        raise OutputError(msg) from None
    except BaseException:
        discard(staging)
        raise
    return out / "report.html"


def _write_pages(data: RunData, out: Path, staging: Path) -> None:
    """The figures, the players and ``report.html`` of ``data``, written into ``staging``
    (links as from ``out``, where ``staging`` will be)."""
    import matplotlib as mpl

    mpl.use("Agg")
    sections = []
    for stem, heading, make in FIGURES:
        png = staging / f"{stem}.png"
        try:
            fig = make(data)
        except Unavailable as exc:
            png.unlink(missing_ok=True)
            body = f'<div class="na" id="na-{stem}">not available: {html.escape(str(exc))}</div>'
        except (KeyError, IndexError, TypeError, ValueError, OSError, CdwTwinError) as exc:
            png.unlink(missing_ok=True)
            reason = f"could not read its data: {type(exc).__name__}: {exc}"
            body = f'<div class="na" id="na-{stem}">not available: {html.escape(reason)}</div>'
        else:
            save_png(fig, png)
            body = f'<img id="fig-{stem}" src="{png.name}" alt="{html.escape(heading)}">'
        sections.append(f"<figure><h2>{html.escape(heading)}</h2>{body}</figure>")
    player_notes: list[str] = []
    rows = episode_rows(data)
    for row, link in zip(rows, _players(data, out, player_notes, staging), strict=True):
        row["player"] = link
    runs = "".join(f"<li>{html.escape(str(p))}</li>" for p in data.run_dirs)
    sets = "".join(f"<li>{html.escape(str(p))}</li>" for p in data.datasets)
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in (*data.notes, *player_notes))
    page = (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>cdw-twin report</title><style>{_CSS}</style></head><body>"
        "<h1>cdw-twin report</h1>"
        f"<p>Runs:</p><ul>{runs}</ul><p>Datasets:</p><ul>{sets}</ul>"
        "<h2>Per cell and belt speed</h2>"
        "<p>Rates pool the counts of every episode of a cell at a speed; intervals are Wilson "
        "score intervals (95 %). RTT pools every command's round trip.</p>"
        f"{_table(speed_rows(data), SPEED_COLUMNS)}"
        f"{_station_section(data)}"
        f"{_line_section(data)}"
        "<h2>Per episode</h2><p>Each episode's player replays it from above (open the file; "
        "it needs no network).</p>"
        f"{_table(rows, EPISODE_COLUMNS)}"
        + "".join(sections)
        + (f'<div class="notes"><p>Notes:</p><ul>{notes}</ul></div>' if notes else "")
        + "</body></html>\n"
    )
    write_atomic(staging / "report.html", page)


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the report options."""
    from experiments.run import add_replace_option

    parser.add_argument("run_dirs", type=Path, nargs="+", metavar="RUN_DIR", help="run folders")
    parser.add_argument("--out", type=Path, default=None, help="folder (RUN_DIR/report)")
    add_replace_option(parser, "report")


def run(args: argparse.Namespace) -> int:
    """Write the report and print its path."""
    out = args.out if args.out is not None else args.run_dirs[0] / "report"
    print(write_report(args.run_dirs, out, replace=bool(getattr(args, "replace", False))))
    return 0


__all__ = [
    "FIGURES",
    "Episode",
    "ReportError",
    "RunData",
    "bin_rows",
    "class_rows",
    "episode_rows",
    "find_run_dirs",
    "load_runs",
    "recovery_by_stations",
    "speed_rows",
    "station_rows",
    "wilson_interval",
    "write_report",
]
