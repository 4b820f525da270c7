"""``cdw-twin fit``: which tools fit a stream, by the rules the controllers apply.

Examples::

    cdw-twin fit out/real_meshes
    cdw-twin fit out/real_meshes --cell default --json
    cdw-twin fit out/real_meshes --stations 4

For every piece of a meshgen output folder, lying flat on the belt as the stream spawns it, and
for every station judged, :func:`control.fit.takeable` says whether the station's controller
could ever target it, or why not (``no_bin``, ``too_wide``, ``too_flat``, ``too_small``,
``too_tilted``, ``too_heavy``): the static checks of its scheduler, with its tool, its parameter
file's margins, the dataset's class densities and the suction point its camera reports (the
twin marks every spawned piece by the same rule). Timing, reach and clutter (``too_late``,
``blocked``, ...) are not judged: a piece a station can take may still pass it. The stations
judged are one per catalogue tool (each on its robot,
:func:`~experiments.fit_rules.catalogue_setups`) and those of ``--cell`` (default ``line``, its
bin slots taking the dataset's classes as in an episode, with its controllers' parameter file:
``--controller``, default the shipped file of the cell file's name, else ``default``).

A tool mix for a line of ``--stations`` stations (default: the cell's count) is suggested
(:func:`suggest_mix`): greedy cover of the pieces by tools, each piece counting once (so each
class weighs by its share of the pieces), then the stations left over shared out by load.

``--json`` prints one object, keys in this order:

- ``dataset`` (the folder), ``pieces`` (count), ``classes`` (class -> pieces, the dataset's
  class table order), ``size_bins`` (the bins' labels -> pieces: ``narrow_side_cm``, the
  footprint's narrow side, and ``height_cm``);
- ``tools``: catalogue tool -> ``robot``, ``params`` (the parameter file), ``share`` and
  ``takes`` (of all pieces), ``by_class``, ``by_narrow_side_cm``, ``by_height_cm`` (shares;
  null for a group without pieces) and ``refused`` (reason -> pieces, every reason);
- ``cell``: ``name``, ``file``, ``params``, then what the line takes at all (some station
  could take the piece): ``share``, ``takes``, ``by_class``, ``by_narrow_side_cm``,
  ``by_height_cm``, ``refused`` (pieces no station takes, by the ``+``-joined reasons of the
  stations, most first), and ``stations``: station -> ``tool``, ``robot``, ``share``,
  ``takes``, ``by_class``, ``refused``;
- ``mix``: ``stations``, ``method``, ``share`` (what the mix takes at all), ``tools`` (a list,
  in the order chosen: ``tool``, ``robot``, ``stations``, ``adds`` the share of the pieces it
  added to the cover, ``load`` its share of the pieces the mix takes).
"""

from __future__ import annotations

import argparse
import json
import textwrap
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from itertools import pairwise
from pathlib import Path
from typing import Any

from experiments.fit_rules import (
    REFUSALS,
    FitError,
    Piece,
    StationSetup,
    catalogue_setups,
    cell_setups,
    check_meshgen_folder,
    default_params,
    flat_pieces,
    line_refusal,
    params_path,
    takeable,
)

NARROW_EDGES_M: tuple[float, ...] = (0.03, 0.05, 0.08)
"""Edges of the narrow-side bins (m): under 3 cm, 3-5, 5-8, over 8 cm."""

HEIGHT_EDGES_M: tuple[float, ...] = (0.01, 0.02, 0.04, 0.06)
"""Edges of the height bins (m): under 1 cm (tiles), 1-2 (below a jaw's pads), 2-4, 4-6, over
6 cm."""

DEFAULT_CELL = "line"
"""The cell judged unless ``--cell`` names another: the default sorting line."""

MIX_METHOD = (
    "greedy cover: each next tool the catalogue tool that takes the most pieces no chosen tool "
    "takes (ties: the more pieces in all, then catalogue order), each piece counting once (a "
    "class weighs by its share of the pieces), until the stations are used or no tool adds "
    "any; the stations left over go one at a time to the tool with the most load per station "
    "(D'Hondt), a tool's load the pieces it takes, one taken by several chosen tools shared "
    "equally among them"
)
"""How :func:`suggest_mix` chooses, as the JSON and the table say it."""

SHARE_DIGITS = 4
"""Shares are rounded to this many decimals in the output."""


def bin_labels(edges_m: Sequence[float]) -> tuple[str, ...]:
    """Labels of the bins ``edges_m`` bound, in cm: ``<3``, ``3-5``, ..., ``>8``."""

    def cm(value_m: float) -> str:
        return f"{value_m * 100:g}"

    inner = [f"{cm(a)}-{cm(b)}" for a, b in pairwise(edges_m)]
    return (f"<{cm(edges_m[0])}", *inner, f">{cm(edges_m[-1])}")


def bin_of(value_m: float, edges_m: Sequence[float]) -> int:
    """Index of the bin ``value_m`` falls in (a value on an edge belongs to the bin above)."""
    return sum(1 for edge in edges_m if value_m >= edge)


def _share(takes: int, of: int) -> float | None:
    return round(takes / of, SHARE_DIGITS) if of else None


@dataclass(frozen=True, kw_only=True)
class Groups:
    """The groupings the output splits the pieces by (``by_class``, ``by_narrow_side_cm``,
    ``by_height_cm``): ``keys`` every group of each, in output order (the dataset's class
    table, the size bins from the smallest), ``of_piece`` each piece's group."""

    keys: Mapping[str, tuple[str, ...]]
    of_piece: Mapping[str, tuple[str, ...]]

    @classmethod
    def of(cls, pieces: Sequence[Piece], classes: Sequence[str]) -> Groups:
        """The groups of ``pieces``, classes in the order of ``classes``."""
        narrow, height = bin_labels(NARROW_EDGES_M), bin_labels(HEIGHT_EDGES_M)
        return cls(
            keys={"by_class": tuple(classes), "by_narrow_side_cm": narrow, "by_height_cm": height},
            of_piece={
                "by_class": tuple(p.class_name for p in pieces),
                "by_narrow_side_cm": tuple(
                    narrow[bin_of(p.narrow_m, NARROW_EDGES_M)] for p in pieces
                ),
                "by_height_cm": tuple(height[bin_of(p.height_m, HEIGHT_EDGES_M)] for p in pieces),
            },
        )

    def shares(self, taken: Sequence[bool]) -> dict[str, Any]:
        """``share`` and ``takes`` of all pieces (``taken`` says which, piece by piece), then
        the share taken in each group of each grouping (None: a group without pieces)."""
        out: dict[str, Any] = {"share": _share(sum(taken), len(taken)), "takes": sum(taken)}
        for grouping, keys in self.keys.items():
            total = Counter(self.of_piece[grouping])
            took = Counter(k for k, ok in zip(self.of_piece[grouping], taken, strict=True) if ok)
            out[grouping] = {key: _share(took[key], total[key]) for key in keys}
        return out

    def counts(self) -> dict[str, Any]:
        """Pieces per class and per size bin (every class and bin, zeros included)."""
        n = {grouping: Counter(groups) for grouping, groups in self.of_piece.items()}
        every = {g: {key: n[g][key] for key in keys} for g, keys in self.keys.items()}
        return {
            "classes": every["by_class"],
            "size_bins": {
                "narrow_side_cm": every["by_narrow_side_cm"],
                "height_cm": every["by_height_cm"],
            },
        }


def refusals(pieces: Sequence[Piece], setup: StationSetup) -> tuple[str | None, ...]:
    """Each piece's refusal by the station (:func:`~experiments.fit_rules.takeable`)."""
    return tuple(takeable(piece, setup.config) for piece in pieces)


def _refused(reasons: Sequence[str | None]) -> dict[str, int]:
    counts = Counter(r for r in reasons if r is not None)
    return {reason: counts[reason] for reason in REFUSALS}


@dataclass(frozen=True, kw_only=True)
class MixEntry:
    """One tool of a suggested mix: ``stations`` of it, ``adds`` the share of the pieces it
    added to the cover when chosen, ``load`` its share of the pieces the mix takes (a piece
    several of its tools take shared equally among them)."""

    tool: str
    robot: str
    stations: int
    adds: float
    load: float


@dataclass(frozen=True, kw_only=True)
class ToolMix:
    """A suggested tool mix (:func:`suggest_mix`): its tools in the order chosen and the share
    of the pieces some tool of it takes (``share``)."""

    entries: tuple[MixEntry, ...]
    share: float


def suggest_mix(
    setups: Sequence[StationSetup], taken: Mapping[str, Sequence[bool]], stations: int
) -> ToolMix:
    """A tool mix for a line of ``stations`` stations, by :data:`MIX_METHOD`.

    ``taken[setup.name]`` says, piece by piece, whether that setup takes it. No entries when
    no tool takes any piece.
    """
    if stations < 1:
        msg = f"--stations {stations}: a line has at least one station"
        raise FitError(msg)
    count = len(next(iter(taken.values()), ()))
    covered = [False] * count
    chosen: list[tuple[StationSetup, int]] = []
    order = {s.name: i for i, s in enumerate(setups)}

    def gain(setup: StationSetup) -> int:
        return sum(ok and not done for ok, done in zip(taken[setup.name], covered, strict=True))

    while len(chosen) < stations:
        left = [s for s in setups if all(s is not c for c, _ in chosen)]
        best = max(left, key=lambda s: (gain(s), sum(taken[s.name]), -order[s.name]), default=None)
        if best is None or gain(best) == 0:
            break
        chosen.append((best, gain(best)))
        covered = [ok or done for ok, done in zip(taken[best.name], covered, strict=True)]
    load = [0.0] * len(chosen)
    for i in range(count):
        takers = [k for k, (s, _) in enumerate(chosen) if taken[s.name][i]]
        for k in takers:
            load[k] += 1.0 / len(takers)
    seats = [1] * len(chosen)
    for _ in range(stations - len(chosen) if chosen else 0):
        k = max(range(len(chosen)), key=lambda k: (load[k] / (seats[k] + 1), -k))
        seats[k] += 1
    entries = tuple(
        MixEntry(
            tool=setup.tool,
            robot=setup.robot,
            stations=seats[k],
            adds=round(added / count, SHARE_DIGITS),
            load=round(load[k] / max(sum(covered), 1), SHARE_DIGITS),
        )
        for k, (setup, added) in enumerate(chosen)
    )
    return ToolMix(entries=entries, share=_share(sum(covered), count) or 0.0)


def fit_report(
    *,
    dataset: Path,
    pieces: Sequence[Piece],
    classes: Sequence[str],
    catalogue: Sequence[StationSetup],
    cell_name: str,
    cell_file: Path,
    cell: Sequence[StationSetup],
    stations: int,
) -> dict[str, Any]:
    """The JSON object of ``cdw-twin fit`` (keys as the module doc lists them) for ``pieces``
    (of the meshgen output ``dataset``, whose class table is ``classes``), the ``catalogue``'s
    setups, the stations of the cell ``cell_name`` (read from ``cell_file``) and a mix of
    ``stations`` stations."""
    if not pieces:
        msg = f"{dataset}: no pieces to judge"
        raise FitError(msg)
    groups = Groups.of(pieces, classes)
    tools: dict[str, Any] = {}
    taken: dict[str, tuple[bool, ...]] = {}
    for setup in catalogue:
        reasons = refusals(pieces, setup)
        taken[setup.name] = tuple(r is None for r in reasons)
        tools[setup.name] = {
            "robot": setup.robot,
            "params": str(setup.params),
            **groups.shares(taken[setup.name]),
            "refused": _refused(reasons),
        }
    per_station: dict[str, Any] = {}
    for setup in cell:
        reasons = refusals(pieces, setup)
        ok = tuple(r is None for r in reasons)
        shares = groups.shares(ok)
        per_station[setup.name] = {
            "tool": setup.tool,
            "robot": setup.robot,
            **{key: shares[key] for key in ("share", "takes", "by_class")},
            "refused": _refused(reasons),
        }
    configs = [s.config for s in cell]
    line = [line_refusal(piece, configs) for piece in pieces]
    left = Counter(r for r in line if r is not None)
    mix = suggest_mix(catalogue, taken, stations)
    return {
        "dataset": str(dataset),
        "pieces": len(pieces),
        **groups.counts(),
        "tools": tools,
        "cell": {
            "name": cell_name,
            "file": str(cell_file),
            "params": str(cell[0].params) if cell else "",
            **groups.shares([r is None for r in line]),
            "refused": dict(sorted(left.items(), key=lambda item: (-item[1], item[0]))),
            "stations": per_station,
        },
        "mix": {
            "stations": stations,
            "method": MIX_METHOD,
            "share": mix.share,
            "tools": [asdict(entry) for entry in mix.entries],
        },
    }


def fit_dataset(
    dataset: Path, *, cell: str = DEFAULT_CELL, controller: str = "", stations: int = 0
) -> dict[str, Any]:
    """What ``cdw-twin fit DATASET`` reports (:func:`fit_report`) for the meshgen output
    ``dataset``, the cell ``cell`` (a shipped name or a path) with its controllers' parameter
    file ``controller`` (a shipped name or a path; empty: the cell's,
    :func:`~experiments.fit_rules.default_params`) and a mix of ``stations`` (0: the cell's
    count). Raises a :class:`~interfaces.errors.CdwTwinError` naming what was wrong."""
    from interfaces.cell import load_cell, resolve_cell, resolve_cell_path
    from interfaces.materials import dataset_table
    from twin.objects import load_dataset

    check_meshgen_folder(dataset)
    table = dataset_table(dataset)
    cell_file = resolve_cell_path(cell)
    the_cell = resolve_cell(load_cell(cell_file), table)
    params = params_path(controller) if controller else default_params(cell_file)
    objects = [o for layout in load_dataset(dataset) for o in layout.objects]
    return fit_report(
        dataset=dataset.resolve(),
        pieces=flat_pieces(objects),
        classes=table.names,
        catalogue=catalogue_setups(table),
        cell_name=the_cell.name,
        cell_file=cell_file,
        cell=cell_setups(the_cell, params),
        stations=stations or len(the_cell.stations),
    )


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    widths = [max(len(r[i]) for r in (header, *rows)) for i in range(len(header))]
    return [
        "  ".join(
            cell.ljust(w) if i == 0 else cell.rjust(w)
            for i, (cell, w) in enumerate(zip(row, widths, strict=True))
        ).rstrip()
        for row in (header, *rows)
    ]


def _fmt(share: float | None) -> str:
    return "-" if share is None else f"{share:.2f}"


def _reasons(refused: Mapping[str, int]) -> str:
    return ", ".join(f"{r} {n}" for r, n in refused.items() if n) or "-"


def format_report(report: Mapping[str, Any]) -> str:
    """The short readable tables of a :func:`fit_report` object (``cdw-twin fit`` without
    ``--json``)."""
    classes = list(report["classes"])
    bins = report["size_bins"]
    narrow, height = list(bins["narrow_side_cm"]), list(bins["height_cm"])
    counts = ", ".join(f"{c} {n}" for c, n in report["classes"].items())
    lines = [
        f"{report['pieces']} pieces in {report['dataset']}: {counts}",
        "narrow side, cm: " + ", ".join(f"{b} {n}" for b, n in bins["narrow_side_cm"].items()),
        "height, cm: " + ", ".join(f"{b} {n}" for b, n in bins["height_cm"].items()),
        "",
        "share each catalogue tool can take (flat on the belt, by the controllers' rules)",
    ]
    tools = report["tools"]
    lines += _table(
        ["tool", "robot", "all", *classes, "refused"],
        [
            [name, t["robot"], _fmt(t["share"])]
            + [_fmt(t["by_class"][c]) for c in classes]
            + [_reasons(t["refused"])]
            for name, t in tools.items()
        ],
    )
    lines += ["", "by size: narrow side (cm) | height (cm)"]
    lines += _table(
        ["tool", *narrow, "|", *height],
        [
            [name]
            + [_fmt(t["by_narrow_side_cm"][b]) for b in narrow]
            + ["|"]
            + [_fmt(t["by_height_cm"][b]) for b in height]
            for name, t in tools.items()
        ],
    )
    cell = report["cell"]
    lines += ["", f"cell {cell['name']} ({cell['file']}; controllers: {cell['params']})"]
    rows = [
        [name, s["tool"], _fmt(s["share"])]
        + [_fmt(s["by_class"][c]) for c in classes]
        + [_reasons(s["refused"])]
        for name, s in cell["stations"].items()
    ]
    rows.append(
        ["any station", "", _fmt(cell["share"])]
        + [_fmt(cell["by_class"][c]) for c in classes]
        + [_reasons(cell["refused"])]
    )
    lines += _table(["station", "tool", "all", *classes, "refused"], rows)
    mix = report["mix"]
    chosen = ", ".join(f"{e['stations']} x {e['tool']} ({e['robot']})" for e in mix["tools"])
    takes = f"takes {_fmt(mix['share'])} (the cell: {_fmt(cell['share'])})"
    lines += [
        "",
        f"suggested mix of {mix['stations']} stations: {chosen or 'none'}; {takes}",
        *textwrap.wrap(f"({mix['method']})", 100),
    ]
    return "\n".join(lines)


def configure(parser: argparse.ArgumentParser) -> None:
    """Add ``fit``'s options to ``parser``."""
    parser.add_argument("dataset", type=Path, help="meshgen output folder")
    parser.add_argument(
        "--cell",
        default=DEFAULT_CELL,
        help=f"the cell whose line is judged: a shipped name or a path (default {DEFAULT_CELL})",
    )
    parser.add_argument(
        "--controller",
        default="",
        help="the cell's controller parameter file: a name in control/config/ or a path "
        "(default: the one named as the cell file, else default)",
    )
    parser.add_argument(
        "--stations",
        type=int,
        default=0,
        help="stations of the suggested tool mix (default: the cell's count)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    """Judge the dataset and print the report (JSON with ``--json``); 0 on success."""
    if args.stations < 0:
        msg = f"--stations {args.stations}: must be at least 1 (0: the cell's count)"
        raise FitError(msg)
    report = fit_dataset(
        args.dataset, cell=args.cell, controller=args.controller, stations=args.stations
    )
    print(json.dumps(report) if args.json else format_report(report))
    return 0
