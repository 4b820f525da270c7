"""The report's page, ``report.html``, from its template files in ``report_assets/``.

Each template is a :class:`string.Template` (``${name}`` places); every line of a template is a
piece of the page, joined to the next without its indentation and line break (the page is one
line after its doctype; ``${newline}`` puts a line break where the page has one). The tables are
rows of frozen dataclasses (:mod:`experiments.report_tables`, :mod:`experiments.report_line`)
shown column by column, ``(field, heading)``; every value is escaped but the links to players.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from string import Template

ASSETS = Path(__file__).with_name("report_assets")
"""The page's template files and style sheet (shipped as package data)."""


class Html(str):
    """Table cell text that is already HTML (not escaped again)."""

    __slots__ = ()


@cache
def _template(name: str) -> Template:
    lines = (ASSETS / name).read_text(encoding="utf-8").splitlines()
    return Template("".join(line.strip() for line in lines))


def fill(name: str, **values: str) -> str:
    """The template ``name`` of ``report_assets/`` with its places filled (``${newline}``
    is a line break)."""
    return _template(name).substitute(values, newline="\n")


def _fmt(value: object, digits: int = 3) -> str:
    if isinstance(value, Html):
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


def table(rows: Sequence[object], columns: Sequence[tuple[str, str]]) -> str:
    """An HTML table of ``rows`` (dataclasses): one column per ``(field, heading)``."""
    head = "".join(f"<th>{html.escape(title)}</th>" for _, title in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{_fmt(getattr(row, key))}</td>" for key, _ in columns) + "</tr>"
        for row in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def grid(headings: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """An HTML table of plain rows of values under ``headings`` (a table whose columns depend
    on the data, such as a class confusion)."""
    head = "".join(f"<th>{html.escape(title)}</th>" for title in headings)
    body = "".join("<tr>" + "".join(f"<td>{_fmt(v)}</td>" for v in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _items(values: Sequence[object]) -> str:
    return "".join(f"<li>{html.escape(str(v))}</li>" for v in values)


def player_link(href: str) -> Html:
    """The link to an episode's player (``href`` relative to the report)."""
    return Html(fill("player_link.html", href=html.escape(href, quote=True)))


def figure_image(stem: str, heading: str, src: str) -> str:
    """A figure drawn as the PNG ``src``."""
    body = fill("figure_image.html", stem=stem, src=src, heading=html.escape(heading))
    return fill("figure.html", heading=html.escape(heading), body=body)


def figure_missing(stem: str, heading: str, reason: str) -> str:
    """A "not available: <why>" panel in place of a figure."""
    body = fill("figure_missing.html", stem=stem, reason=html.escape(reason))
    return fill("figure.html", heading=html.escape(heading), body=body)


@dataclass(frozen=True)
class PageParts:
    """What the page shows, in its order: the runs and datasets read, the tables (HTML), the
    figures (HTML, :func:`figure_image` / :func:`figure_missing`) and the notes."""

    run_dirs: Sequence[Path]
    datasets: Sequence[Path]
    speed_table: str
    station_table: str | None
    """The per-station table; None for runs of one station (no section then)."""
    stations_table: str
    class_table: str
    bin_table: str
    episode_table: str
    figures: Sequence[str]
    notes: Sequence[str]
    perception: str = ""
    """The perception section (HTML, :func:`perception_section`); empty for oracle runs."""


def perception_section(
    table_html: str, confusion_html: str, frames: Sequence[tuple[str, str]]
) -> str:
    """The perception section: its table, the class confusion and the example frames (caption,
    image file relative to the report)."""
    images = "".join(
        fill("frame.html", caption=html.escape(caption), src=html.escape(src))
        for caption, src in frames
    )
    return fill(
        "perception.html",
        table=table_html,
        confusion=confusion_html,
        frames=images or "<p>No example frame in these runs.</p>",
    )


def page(parts: PageParts) -> str:
    """The whole ``report.html`` text."""
    stations = (
        "" if parts.station_table is None else fill("per_station.html", table=parts.station_table)
    )
    notes = fill("notes.html", items=_items(parts.notes)) if parts.notes else ""
    return fill(
        "report.html",
        css=fill("report.css"),
        runs=_items(parts.run_dirs),
        datasets=_items(parts.datasets),
        speed_table=parts.speed_table,
        perception_section=parts.perception,
        station_section=stations,
        stations_table=parts.stations_table,
        class_table=parts.class_table,
        bin_table=parts.bin_table,
        episode_table=parts.episode_table,
        figures="".join(parts.figures),
        notes=notes,
    )
