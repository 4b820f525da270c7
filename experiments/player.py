"""The episode player: one self-contained HTML page per episode that replays it from above.

Example::

    cdw-twin player runs/a/ep000      # writes runs/a/ep000/player.html

``cdw-twin report`` writes one for every episode it lists and links it from ``report.html``.
The page loads nothing (no network, no server: open the file): the episode's data is a JSON block
inside it, drawn by inline JavaScript on a ``<canvas>``. It shows a top view of the belt (the run's
``cell.yaml``) with every station's pick window, base and bins, every object's footprint coloured by
class (the class table's colour: the run's ``cell.yaml`` ``materials``, else the dataset's
``classes.yaml``, :mod:`interfaces.materials`) at its recorded pose (``recording.mcap``,
``/objects/ground_truth``, 30 Hz), each station's TCP with its last two seconds of path
(``tcp_pose``, taken at 30 Hz) and its controller's current target (``controller/target``, moved on
with the target's velocity since its stamp), and the episode's events (``twin/events.jsonl``) on a
timeline. Play, pause, speed and a scrub bar; clicking an object shows its ground truth now and its
events (click an event to go to it). Multi-station lines read each station's topics under its
namespace (:func:`interfaces.contract.resolved_topics`).

Footprints: the outline of the object's mesh (``<dataset>/<image>/<source_id>.obj``, the
``source_id`` of its ``spawned`` event) projected onto the object's own xy plane, with the z
span of the mesh stretched to the recorded height. The page draws the object's top view for the
recorded pose ``(p, q)``: the outline at both ends of that span and the side faces between
them, each point ``R(q) (x, y, z) + p`` projected on the world xy plane (for an object lying
flat, its outline; for one on its side, the side it shows). A length x width x height box (the
ground truth's extents) stands in when the dataset or the mesh is not there.

Time and pixels, for tests and links: ``player.html#t=12.5`` opens paused at 12.5 s; the frame
shown at time ``t`` is the last ground-truth sample stamped at or before ``t``.
``&highlight=ID`` draws object ``ID`` last, in :data:`HIGHLIGHT_HEX` without an outline;
``&select=ID`` opens its panel as a click on it would, ``&click=X,Y`` clicks the page at CSS
pixel ``(X, Y)``. The page writes its world-to-page mapping on the canvas
(``#scene``): ``data-px-per-m`` (s), ``data-origin-x`` and ``data-origin-y``, so the world point
``(x, y)`` is drawn at page pixel ``(origin_x + s * x, origin_y - s * y)`` (CSS pixels from the
top left of the page: travel to the right, y up; rewritten on every zoom or pan, the wheel and
a drag on the canvas); and the ground-truth frame it shows as
``data-frame`` (index) and ``data-frame-t`` (stamp, s) on ``#scene``.

The recording is read into the page's frames by :mod:`experiments.player_frames`; this module
reads the rest of the episode (its events, the run's cell and ``run.json``, the twin's summary)
and writes the page.

Size: positions in mm, quaternions in 1e-4, velocities in mm/s, each stored as differences
from the previous frame: a 30 s episode of the reference cell at 0.4 m/s (73 objects, about
14 000 object-frames) makes a 0.45 MB page, about 25 bytes per object and frame.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TypedDict

from experiments.player_footprints import (
    MeshFinder,
    PlayerError,
    box_outline,
    footprint_outline,
)
from experiments.player_frames import (
    ABSENT_BIT,
    FLAG_BITS,
    ObjectData,
    Target,
    TcpPath,
    belt_positions,
    ground_truth,
    objects,
    targets,
    tcp_path,
)
from interfaces.cell import Cell, CellError, load_cell
from interfaces.class_colours import class_colour, dataset_colour, rgb_hex
from interfaces.errors import cut
from interfaces.fileio import read_text_capped, write_atomic
from interfaces.run_folder import EpisodeFolder, RunFolder
from interfaces.run_records import EpisodeSummary, RecordError, RunMeans

MAX_EVENTS_BYTES = 1_000_000_000
"""The largest ``events.jsonl`` read (a day-long episode's is a few hundred MB)."""

PAGE_NAME = "player.html"
"""The player's file name in an episode folder."""

HIGHLIGHT_HEX = "#ff00ff"
"""The fill of the object named by ``#highlight=ID`` (no class has it)."""

STATION_HEX = ("#1f5fd1", "#d1661f", "#1fa34a", "#a31fa3", "#1fa3a3", "#a3a31f")
"""Each station's colour for its TCP, target and pick window, in the cell's station order
(repeating after six)."""


@dataclass(frozen=True)
class PlayerPage:
    """A written player: where, how big, and what it could not show (``notes``)."""

    path: Path
    size_bytes: int
    notes: tuple[str, ...]


# -- what the page draws ------------------------------------------------------------------------
class EventData(TypedDict):
    """An event of ``events.jsonl`` on the timeline: sim time (s), type, object id (0: none),
    class and its data (floats to 4 decimals)."""

    t: float
    type: str
    id: int
    cls: str
    data: dict[str, object]


class BeltView(TypedDict):
    """The belt's extent along x, its infeed, centre line and width (m)."""

    start: float
    end: float
    infeed: float
    y: float
    width: float


class BinView(TypedDict):
    """A bin: its class, centre and size (m)."""

    cls: str
    x: float
    y: float
    size: float


class StationView(TypedDict):
    """A station: name, ROS namespace, base xy and pick window along x (m), bins."""

    name: str
    ns: str
    base: list[float]
    window: list[float]
    bins: list[BinView]


class CellView(TypedDict):
    """The cell from above: belt, camera field along x, stations and the view's
    ``[x_min, x_max, y_min, y_max]`` (m)."""

    name: str
    belt: BeltView
    camera: list[float]
    stations: list[StationView]
    view: list[float]


class PlayerData(TypedDict):
    """Everything a page draws (the JSON block inside it, read by ``player_assets/player.js``):
    the frames' stamps (s), the belt per frame, the objects, each station's TCP path and
    targets (:mod:`experiments.player_frames`), the events and the notes on what is missing."""

    episode: str
    seed: int | None
    speed_mps: float | None
    duration_s: float
    dataset: str | None
    cell: CellView | None
    classes: dict[str, str]
    highlight: str
    station_colours: list[str]
    flag_bits: list[str]
    absent_bit: int
    frames: list[float]
    belt_mm: list[int]
    objects: list[ObjectData]
    tcp: list[TcpPath]
    targets: list[list[Target]]
    events: list[EventData]
    notes: list[str]


# -- reading an episode -------------------------------------------------------------------------
def _round(value: object) -> object:
    """Floats to 4 decimals (non-finite ones to None: JSON has no NaN), through lists and
    mappings."""
    if isinstance(value, float):
        return round(value, 4) if math.isfinite(value) else None
    if isinstance(value, list):
        return [_round(v) for v in value]
    if isinstance(value, dict):
        return {k: _round(v) for k, v in value.items()}
    return value


def _events(path: Path, notes: list[str]) -> list[EventData]:
    """Every readable line of ``events.jsonl`` (a bad line is noted and skipped)."""
    if not path.is_file():
        notes.append(f"{path}: missing; no events shown")
        return []
    try:
        text = read_text_capped(
            path, max_bytes=MAX_EVENTS_BYTES, what="event log", error=PlayerError
        )
    except PlayerError as exc:
        notes.append(f"{exc}; no events shown")
        return []
    events = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            raw = json.loads(line)
            data = raw["data"] if isinstance(raw.get("data"), dict) else {}
            events.append(
                EventData(
                    t=round(float(raw["time_s"]), 4),
                    type=str(raw["type"]),
                    id=int(raw.get("object_id") or 0),
                    cls=str(raw.get("class_name") or ""),
                    data={str(k): _round(v) for k, v in data.items()},
                )
            )
        except (ValueError, KeyError, TypeError, RecursionError) as exc:
            what = cut(str(exc), 200)
            notes.append(f"{path}:{number}: unreadable event ({type(exc).__name__}: {what})")
    return events


def _cell_view(cell: Cell) -> CellView:
    belt = cell.belt
    stations = []
    for s in cell.stations:
        bins = [
            BinView(cls=b.class_name, x=b.centre_x_m, y=b.centre_y_m, size=b.size_m) for b in s.bins
        ]
        stations.append(
            StationView(
                name=s.name,
                ns=s.namespace,
                base=list(s.base_position_m[:2]),
                window=list(s.pick_window_x_m),
                bins=bins,
            )
        )
    xs = [belt.start_x_m, belt.end_x_m]
    ys = [belt.centre_y_m - 0.5 * belt.width_m, belt.centre_y_m + 0.5 * belt.width_m]
    for s in cell.stations:
        xs.append(s.base_position_m[0])
        ys.append(s.base_position_m[1] - 0.12)
        for b in s.bins:
            xs += [b.centre_x_m - b.size_m / 2, b.centre_x_m + b.size_m / 2]
            ys += [b.centre_y_m - b.size_m / 2, b.centre_y_m + b.size_m / 2]
    margin = 0.08
    return CellView(
        name=cell.name,
        belt=BeltView(
            start=belt.start_x_m,
            end=belt.end_x_m,
            infeed=belt.infeed_x_m,
            y=belt.centre_y_m,
            width=belt.width_m,
        ),
        camera=[cell.camera.fov_min_x_m, cell.camera.fov_max_x_m],
        stations=stations,
        view=[min(xs) - margin, max(xs) + margin, min(ys) - margin, max(ys) + margin],
    )


def _run_means(path: Path, notes: list[str]) -> RunMeans | None:
    """The run's ``run.json`` (its dataset and speed), None when there is none (a bare
    episode folder) or it cannot be read (noted)."""
    if not path.is_file():
        return None
    try:
        return RunMeans.read(path)
    except RecordError as exc:
        notes.append(f"{exc}; no dataset: objects drawn as length x width boxes")
        return None


def _summary(path: Path) -> EpisodeSummary | None:
    """The twin's ``summary.json`` (seed, speed, duration), None without a readable one (a
    crashed twin writes none: the duration is then the last thing recorded)."""
    try:
        return EpisodeSummary.read(path)
    except RecordError:
        return None


def _load_cell(run_dir: Path, notes: list[str]) -> Cell | None:
    path = RunFolder(run_dir).cell
    if not path.is_file():
        notes.append(f"{path}: missing; no belt, bins or stations drawn")
        return None
    try:
        return load_cell(path)
    except CellError as exc:
        notes.append(f"{exc}; no belt, bins or stations drawn")
        return None


def player_data(episode: Path, run_dir: Path | None = None) -> tuple[PlayerData, list[str]]:
    """Everything the page draws, as JSON-ready data, and notes on what is missing.

    ``run_dir`` (default: the episode's parent) holds ``cell.yaml`` and ``run.json``.
    Missing or unreadable inputs leave their part out with a note; nothing raises.
    """
    from mcap.exceptions import McapError

    from twin.recording import RecordingError

    folder = EpisodeFolder(Path(episode))
    run_dir = folder.path.parent if run_dir is None else Path(run_dir)
    notes: list[str] = []
    run = _run_means(RunFolder(run_dir).run_json, notes)
    summary = _summary(folder.summary)
    dataset = Path(run.info.dataset) if run is not None else None
    if dataset is not None and not dataset.is_dir():
        notes.append(f"dataset {dataset} not found: objects drawn as length x width boxes")
        dataset = None
    cell = _load_cell(run_dir, notes)
    events = _events(folder.events, notes)
    source_ids = {
        e["id"]: str(e["data"].get("source_id", "")) for e in events if e["type"] == "spawned"
    }
    classes = dict.fromkeys(cell.classes if cell else ())
    namespaces = [s.namespace for s in cell.stations] if cell else [""]
    times: list[float] = []
    shown: list[ObjectData] = []
    tcps: list[TcpPath] = []
    sent: list[list[Target]] = []
    belt: list[int] = []
    recording = folder.recording
    if recording.is_file():
        try:
            times, states = ground_truth(recording)
            if not times:
                notes.append(f"{recording}: no ground truth recorded; no objects drawn")
            shown, counts = objects(states, source_ids, MeshFinder(dataset))
            if counts["box"] and dataset is not None:
                notes.append(f"{counts['box']} object(s) without a mesh in {dataset}: boxes")
            tcps = [tcp_path(recording, ns) for ns in namespaces]
            sent = [targets(recording, ns) for ns in namespaces]
            belt = belt_positions(recording, times)
        except (RecordingError, McapError, OSError, ValueError, KeyError, AttributeError) as exc:
            notes.append(f"{recording}: unreadable ({type(exc).__name__}: {exc})")
            times, shown, tcps, sent, belt = [], [], [], [], []
    else:
        notes.append(f"{recording}: missing; no objects, TCPs or targets drawn")
    classes.update(dict.fromkeys(o["cls"] for o in shown))
    classes.update(dict.fromkeys(e["cls"] for e in events if e["cls"]))
    colour = class_colour(cell.materials) if cell is not None else dataset_colour(dataset)
    ends = [*times[-1:], *(e["t"] for e in events)]
    ends += [tcp["t"][-1] for tcp in tcps if tcp["t"]]
    duration = summary.sim_seconds if summary is not None else max(ends, default=0.0)
    speed_mps = summary.belt_speed_mps if summary is not None else None
    if speed_mps is None and run is not None:
        speed_mps = run.info.speed_mps
    data = PlayerData(
        episode=f"{run_dir.name}/{folder.path.name}",
        seed=summary.seed if summary is not None else None,
        speed_mps=speed_mps,
        duration_s=round(float(duration), 4),
        dataset=str(dataset) if dataset else None,
        cell=_cell_view(cell) if cell else None,
        classes={c: rgb_hex(colour(c)) for c in classes},
        highlight=HIGHLIGHT_HEX,
        station_colours=list(STATION_HEX),
        flag_bits=list(FLAG_BITS),
        absent_bit=ABSENT_BIT,
        frames=[round(t, 4) for t in times],
        belt_mm=belt,
        objects=shown,
        tcp=tcps,
        targets=sent,
        events=events,
        notes=notes,
    )
    return data, notes


# -- the page -----------------------------------------------------------------------------------
ASSETS = Path(__file__).with_name("player_assets")
"""The page's style, body and script (inlined into every page: it must open with no files)."""


MODULES = ("player.py", "player_frames.py", "player_footprints.py")
"""The modules that make a page: this one, its frames and the objects' footprints."""


def page_sources() -> list[Path]:
    """The files a player's page is made from: its modules (:data:`MODULES`) and every asset (a
    page older than any of them is stale)."""
    here = Path(__file__).resolve().parent
    modules = [here / name for name in MODULES]
    return [*modules, *sorted(p for p in ASSETS.rglob("*") if p.is_file())]


def _asset(name: str) -> str:
    return (ASSETS / name).read_text(encoding="utf-8")


def render_page(data: PlayerData) -> str:
    """The self-contained HTML page of a player's ``data`` (see :func:`player_data`)."""
    import html

    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")
    title = html.escape(f"cdw-twin player: {data['episode']}")
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{title}</title><style>{_asset('player.css')}</style></head>"
        f"<body>{_asset('player_body.html')}"
        f'<script id="data" type="application/json">{payload}</script>'
        f"<script>{_asset('player.js')}</script></body></html>\n"
    )


def write_player(episode: Path, run_dir: Path | None = None, out: Path | None = None) -> PlayerPage:
    """Write the player of ``episode`` to ``out`` (default ``<episode>/player.html``)."""
    data, notes = player_data(episode, run_dir)
    page = render_page(data)
    path = Path(episode) / PAGE_NAME if out is None else Path(out)
    write_atomic(path, page)  # an OSError is the caller's: the report writes elsewhere then
    return PlayerPage(path=path, size_bytes=len(page.encode("utf-8")), notes=tuple(notes))


def configure(parser: argparse.ArgumentParser) -> None:
    """``cdw-twin player EPISODE_DIR...``: the options."""
    parser.add_argument("episodes", type=Path, nargs="+", metavar="EPISODE_DIR")


def run(args: argparse.Namespace) -> int:
    """Write each episode's player (``<episode>/player.html``); report pages write theirs."""
    for episode in args.episodes:
        if not episode.is_dir():
            msg = f"{episode}: not an episode folder"
            raise PlayerError(msg)
    for episode in args.episodes:
        try:
            page = write_player(episode)
        except OSError as exc:
            msg = f"{episode}: cannot write {PAGE_NAME}: {exc.strerror or exc}"
            raise PlayerError(msg) from None
        print(f"{page.path} ({page.size_bytes / 1e6:.2f} MB)")
        for note in page.notes:
            print(f"  note: {note}")
    return 0


__all__ = [
    "HIGHLIGHT_HEX",
    "PAGE_NAME",
    "STATION_HEX",
    "MeshFinder",
    "PlayerError",
    "PlayerPage",
    "box_outline",
    "footprint_outline",
    "player_data",
    "render_page",
    "write_player",
]
