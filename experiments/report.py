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

The report by job: its data (:mod:`experiments.report_data`), tables
(:mod:`experiments.report_tables`, :mod:`experiments.report_line`), figures
(:mod:`experiments.report_figures`), players (:mod:`experiments.report_players`) and page
(:mod:`experiments.report_html`, from the templates in ``report_assets/``); this module writes
them into the output folder and is the command.

A figure whose data is missing becomes a "not available: <why>" panel. The dataset is
``run.json``'s ``dataset`` when present, else the run's ``scenario.yaml`` dataset, else the
built-in sample.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from experiments.report_data import Episode, ReportError, RunData, Unavailable, load_runs
from experiments.report_figures import FIGURES, save_png
from experiments.report_html import (
    PageParts,
    figure_image,
    figure_missing,
    grid,
    page,
    perception_section,
    player_link,
    table,
)
from experiments.report_line import (
    BIN_COLUMNS,
    CLASS_COLUMNS,
    STATIONS_COLUMNS,
    bin_rows,
    class_rows,
    recovery_by_stations,
)
from experiments.report_perception import (
    PERCEPTION_COLUMNS,
    confusion_table,
    copy_example_frames,
    perception_rows,
)
from experiments.report_players import write_players
from experiments.report_tables import (
    EPISODE_COLUMNS,
    SPEED_COLUMNS,
    STATION_COLUMNS,
    episode_rows,
    speed_rows,
    station_rows,
)
from interfaces.errors import CdwTwinError
from interfaces.fileio import write_atomic


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


def _figures(data: RunData, staging: Path) -> list[str]:
    """Each figure of :data:`FIGURES` drawn into ``staging`` as its PNG, or the panel saying
    why it is not available; their HTML in page order."""
    sections = []
    for stem, heading, make in FIGURES:
        png = staging / f"{stem}.png"
        try:
            fig = make(data)
        except Unavailable as exc:
            png.unlink(missing_ok=True)
            sections.append(figure_missing(stem, heading, str(exc)))
        except (KeyError, IndexError, TypeError, ValueError, OSError, CdwTwinError) as exc:
            png.unlink(missing_ok=True)
            why = f"could not read its data: {type(exc).__name__}: {exc}"
            sections.append(figure_missing(stem, heading, why))
        else:
            save_png(fig, png)
            sections.append(figure_image(stem, heading, png.name))
    return sections


def _write_pages(data: RunData, out: Path, staging: Path) -> None:
    """The figures, the players and ``report.html`` of ``data``, written into ``staging``
    (links as from ``out``, where ``staging`` will be)."""
    import dataclasses

    import matplotlib as mpl

    mpl.use("Agg")
    figures = _figures(data, staging)
    players = write_players(data.episodes, out, staging)
    rows = [
        dataclasses.replace(row, player=player_link(href))
        for row, href in zip(episode_rows(data), players.hrefs, strict=True)
    ]
    stations = table(station_rows(data), STATION_COLUMNS) if len(data.stations()) >= 2 else None
    parts = PageParts(
        perception=_perception(data, staging),
        run_dirs=data.run_dirs,
        datasets=data.datasets,
        speed_table=table(speed_rows(data), SPEED_COLUMNS),
        station_table=stations,
        stations_table=table(recovery_by_stations(data), STATIONS_COLUMNS),
        class_table=table(class_rows(data), CLASS_COLUMNS),
        bin_table=table(bin_rows(data), BIN_COLUMNS),
        episode_table=table(rows, EPISODE_COLUMNS),
        figures=figures,
        notes=(*data.notes, *players.notes),
    )
    write_atomic(staging / "report.html", page(parts))


def _perception(data: RunData, staging: Path) -> str:
    """The perception section (empty when no episode scored a camera: oracle runs)."""
    rows = perception_rows(data)
    if not rows:
        return ""
    columns, confusion = confusion_table(data)
    confusion_html = grid(
        ["cell", "belt m/s", "true class", *columns],
        [
            [line.cell, line.speed_mps, line.true_class, *(line.counts.get(c, 0) for c in columns)]
            for line in confusion
        ],
    )
    frames = copy_example_frames(data.episodes, staging)
    return perception_section(table(rows, PERCEPTION_COLUMNS), confusion_html, frames)


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
    "load_runs",
    "recovery_by_stations",
    "speed_rows",
    "station_rows",
    "write_report",
]
