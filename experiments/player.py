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

Size: positions in mm, quaternions in 1e-4, velocities in mm/s, each stored as differences
from the previous frame: a 30 s episode of the reference cell at 0.4 m/s (73 objects, about
14 000 object-frames) makes a 0.45 MB page, about 25 bytes per object and frame.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from experiments.player_footprints import (
    Footprint,
    MeshFinder,
    PlayerError,
    box_outline,
    footprint_outline,
)
from interfaces.cell import Cell, CellError, load_cell
from interfaces.class_colours import class_colour, dataset_colour, rgb_hex
from interfaces.contract import BELT_STATE, GROUND_TRUTH_TOPIC, PICK_TARGET, TCP_POSE
from interfaces.errors import cut
from interfaces.fileio import MAX_JSON_BYTES, read_text_capped, write_atomic
from interfaces.run_folder import EpisodeFolder, RunFolder

MAX_EVENTS_BYTES = 1_000_000_000
"""The largest ``events.jsonl`` read (a day-long episode's is a few hundred MB)."""

PAGE_NAME = "player.html"
"""The player's file name in an episode folder."""

HIGHLIGHT_HEX = "#ff00ff"
"""The fill of the object named by ``#highlight=ID`` (no class has it)."""

STATION_HEX = ("#1f5fd1", "#d1661f", "#1fa34a", "#a31fa3", "#1fa3a3", "#a3a31f")
"""Each station's colour for its TCP, target and pick window, in the cell's station order
(repeating after six)."""

SAMPLE_HZ = 30.0
"""Rate at which TCP poses are kept (ground truth is recorded at this rate already)."""

FLAG_BITS = ("on_belt", "in_workspace", "held", "in_bin")
"""The ground truth's flags, bit 0 upwards, in the per-frame flag words."""
ABSENT_BIT = 16
"""Flag bit of a frame in which the object is missing from the ground truth."""


@dataclass(frozen=True)
class PlayerPage:
    """A written player: where, how big, and what it could not show (``notes``)."""

    path: Path
    size_bytes: int
    notes: tuple[str, ...]


# -- reading an episode -------------------------------------------------------------------------
def _stamp_s(header: Any) -> float:
    return float(header.stamp.sec) + 1e-9 * float(header.stamp.nanosec)


def _mm(value: float) -> int:
    return round(value * 1000.0)


def _deltas(values: Iterable[int]) -> list[int]:
    """``values`` as differences from the previous one (the first from 0)."""
    out, last = [], 0
    for v in values:
        out.append(v - last)
        last = v
    return out


def _read(recording: Path, topic: str) -> Iterable[Any]:
    from experiments.offline import read_topic

    for _, msg in read_topic(recording, topic):
        yield msg


def _flags(obj: Any) -> int:
    return sum(1 << i for i, name in enumerate(FLAG_BITS) if getattr(obj, name))


def _ground_truth(recording: Path) -> tuple[list[float], dict[int, dict[int, Any]]]:
    """Frame stamps (s, ascending, distinct) and, per object id, its state per frame index."""
    by_stamp: dict[float, Any] = {}
    for msg in _read(recording, GROUND_TRUTH_TOPIC.name):
        by_stamp[round(_stamp_s(msg.header), 6)] = msg
    times = sorted(by_stamp)
    states: dict[int, dict[int, Any]] = {}
    for k, t in enumerate(times):
        for obj in by_stamp[t].objects:
            states.setdefault(int(obj.id), {})[k] = obj
    return times, states


def _track(states: dict[int, Any]) -> dict[str, Any]:
    """One object's per-frame arrays: from its first frame to its last, difference-coded."""
    first, last = min(states), max(states)
    cols: dict[str, list[int]] = {k: [] for k in ("x", "y", "z", "qx", "qy", "qz", "qw")}
    cols |= {"vx": [], "vy": [], "vz": []}
    flags: list[list[int]] = []
    prev: Any = None
    prev_flags = -1
    for k in range(first, last + 1):
        obj = states.get(k)
        word = ABSENT_BIT if obj is None else _flags(obj)
        obj = obj if obj is not None else prev
        p, q, v = obj.pose.position, obj.pose.orientation, obj.twist.linear
        for key, value in (("x", p.x), ("y", p.y), ("z", p.z), ("vx", v.x), ("vy", v.y)):
            cols[key].append(_mm(value))
        cols["vz"].append(_mm(v.z))
        sign = -1.0 if q.w < 0 else 1.0  # q and -q are one rotation: keep w >= 0
        for key, value in (("qx", q.x), ("qy", q.y), ("qz", q.z), ("qw", q.w)):
            cols[key].append(round(sign * value * 1e4))
        if word != prev_flags:
            flags.append([k - first, word])
            prev_flags = word
        prev = obj
    return {"first": first, "n": last - first + 1, "flags": flags} | {
        key: _deltas(values) for key, values in cols.items()
    }


def _sampled(recording: Path, topic: str, hz: float) -> list[Any]:
    """Messages of ``topic`` at most ``hz`` per second of their stamps (the first of each
    period), with their stamps."""
    out: list[Any] = []
    period = 1.0 / hz
    next_t = -math.inf
    for msg in _read(recording, topic):
        t = _stamp_s(msg.header)
        if t + 1e-9 >= next_t:
            out.append((t, msg))
            next_t = (math.floor(t / period + 1e-6) + 1) * period
    return out


def _tcp(recording: Path, namespace: str) -> dict[str, Any]:
    samples = _sampled(recording, TCP_POSE.resolve(namespace), SAMPLE_HZ)
    pos = [m.pose.position for _, m in samples]
    return {
        "t": [round(t, 4) for t, _ in samples],
        "x": _deltas(_mm(p.x) for p in pos),
        "y": _deltas(_mm(p.y) for p in pos),
        "z": _deltas(_mm(p.z) for p in pos),
    }


def _targets(recording: Path, namespace: str) -> list[list[Any]]:
    """``[t, track_id, phase, class, x, y, z, vx, vy]`` (mm, mm/s) of every target sent."""
    out = []
    for msg in _read(recording, PICK_TARGET.resolve(namespace)):
        g, v = msg.grasp_point, msg.velocity
        out.append(
            [
                round(_stamp_s(msg.header), 4),
                int(msg.track_id),
                str(msg.phase),
                str(msg.class_name),
                *(_mm(c) for c in (g.x, g.y, g.z, v.x, v.y)),
            ]
        )
    return out


def _belt_positions(recording: Path, times: Sequence[float]) -> list[int]:
    """The belt's travelled distance (mm) at each frame, difference-coded."""
    states = [(_stamp_s(m.header), m.position_m) for m in _read(recording, BELT_STATE.name)]
    out, j, pos = [], 0, 0.0
    for t in times:
        while j < len(states) and states[j][0] <= t + 1e-6:
            pos = states[j][1]
            j += 1
        out.append(_mm(pos))
    return _deltas(out)


def _round(value: Any) -> Any:
    """Floats to 4 decimals (non-finite ones to None: JSON has no NaN), through lists and
    mappings."""
    if isinstance(value, float):
        return round(value, 4) if math.isfinite(value) else None
    if isinstance(value, list):
        return [_round(v) for v in value]
    if isinstance(value, dict):
        return {k: _round(v) for k, v in value.items()}
    return value


def _events(path: Path, notes: list[str]) -> list[dict[str, Any]]:
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
            events.append(
                {
                    "t": round(float(raw["time_s"]), 4),
                    "type": str(raw["type"]),
                    "id": int(raw.get("object_id") or 0),
                    "cls": str(raw.get("class_name") or ""),
                    "data": _round(raw["data"] if isinstance(raw.get("data"), dict) else {}),
                }
            )
        except (ValueError, KeyError, TypeError, RecursionError) as exc:
            what = cut(str(exc), 200)
            notes.append(f"{path}:{number}: unreadable event ({type(exc).__name__}: {what})")
    return events


def _cell_data(cell: Cell) -> dict[str, Any]:
    belt = cell.belt
    stations = []
    for s in cell.stations:
        bins = [
            {"cls": b.class_name, "x": b.centre_x_m, "y": b.centre_y_m, "size": b.size_m}
            for b in s.bins
        ]
        stations.append(
            {
                "name": s.name,
                "ns": s.namespace,
                "base": list(s.base_position_m[:2]),
                "window": list(s.pick_window_x_m),
                "bins": bins,
            }
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
    return {
        "name": cell.name,
        "belt": {
            "start": belt.start_x_m,
            "end": belt.end_x_m,
            "infeed": belt.infeed_x_m,
            "y": belt.centre_y_m,
            "width": belt.width_m,
        },
        "camera": [cell.camera.fov_min_x_m, cell.camera.fov_max_x_m],
        "stations": stations,
        "view": [min(xs) - margin, max(xs) + margin, min(ys) - margin, max(ys) + margin],
    }


def _read_json(path: Path) -> dict[str, Any]:
    try:
        text = read_text_capped(path, max_bytes=MAX_JSON_BYTES, what="JSON file", error=PlayerError)
        data = json.loads(text)
    except (PlayerError, ValueError, RecursionError):
        return {}
    return data if isinstance(data, dict) else {}


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


def _objects(
    states: dict[int, dict[int, Any]], source_ids: dict[int, str], meshes: MeshFinder
) -> tuple[list[dict[str, Any]], dict[str, int]]:
    """Every object's static data, outline (1e-4 m) and track; how many outlines each source."""
    objects = []
    counts = {"mesh": 0, "box": 0}
    for oid in sorted(states):
        per_frame = states[oid]
        first = per_frame[min(per_frame)]
        source = source_ids.get(oid, "")
        mesh = meshes.find(source)
        outline: Footprint | None = None
        kind = "box"
        if mesh is not None:
            try:
                outline, kind = footprint_outline(mesh).scaled_z(first.height_m), "mesh"
            except (PlayerError, OSError):
                outline = None
        if outline is None:
            outline = box_outline(first.length_m, first.width_m, first.height_m)
        counts[kind] += 1
        objects.append(
            {
                "id": oid,
                "cls": str(first.class_name),
                "src": source,
                "outline_from": kind,
                "outline": [[round(x * 1e4), round(y * 1e4)] for x, y in outline.ring],
                "zspan": [round(outline.z_low_m * 1e4), round(outline.z_high_m * 1e4)],
                "dims": _round(
                    {
                        "length_m": first.length_m,
                        "width_m": first.width_m,
                        "height_m": first.height_m,
                        "area_m2": first.area_m2,
                        "volume_m3": first.volume_m3,
                        "mass_kg": first.mass_kg,
                    }
                ),
            }
            | _track(per_frame)
        )
    return objects, counts


def player_data(episode: Path, run_dir: Path | None = None) -> tuple[dict[str, Any], list[str]]:
    """Everything the page draws, as JSON-ready data, and notes on what is missing.

    ``run_dir`` (default: the episode's parent) holds ``cell.yaml`` and ``run.json``.
    Missing or unreadable inputs leave their part out with a note; nothing raises.
    """
    from mcap.exceptions import McapError

    from twin.recording import RecordingError

    episode = Path(episode)
    run_dir = episode.parent if run_dir is None else Path(run_dir)
    notes: list[str] = []
    run = _read_json(RunFolder(run_dir).run_json)
    summary = _read_json(EpisodeFolder(episode).summary)
    dataset = Path(run["dataset"]) if isinstance(run.get("dataset"), str) else None
    if dataset is not None and not dataset.is_dir():
        notes.append(f"dataset {dataset} not found: objects drawn as length x width boxes")
        dataset = None
    cell = _load_cell(run_dir, notes)
    events = _events(EpisodeFolder(episode).events, notes)
    source_ids = {
        e["id"]: str(e["data"].get("source_id", "")) for e in events if e["type"] == "spawned"
    }
    classes = dict.fromkeys(cell.classes if cell else ())
    namespaces = [s.namespace for s in cell.stations] if cell else [""]
    times: list[float] = []
    objects: list[dict[str, Any]] = []
    tcps: list[dict[str, Any]] = []
    targets: list[list[list[Any]]] = []
    belt: list[int] = []
    recording = EpisodeFolder(episode).recording
    if recording.is_file():
        try:
            times, states = _ground_truth(recording)
            if not times:
                notes.append(f"{recording}: no ground truth recorded; no objects drawn")
            objects, counts = _objects(states, source_ids, MeshFinder(dataset))
            if counts["box"] and dataset is not None:
                notes.append(f"{counts['box']} object(s) without a mesh in {dataset}: boxes")
            tcps = [_tcp(recording, ns) for ns in namespaces]
            targets = [_targets(recording, ns) for ns in namespaces]
            belt = _belt_positions(recording, times)
        except (RecordingError, McapError, OSError, ValueError, KeyError, AttributeError) as exc:
            notes.append(f"{recording}: unreadable ({type(exc).__name__}: {exc})")
            times, objects, tcps, targets, belt = [], [], [], [], []
    else:
        notes.append(f"{recording}: missing; no objects, TCPs or targets drawn")
    classes.update(dict.fromkeys(o["cls"] for o in objects))
    classes.update(dict.fromkeys(e["cls"] for e in events if e["cls"]))
    colour = class_colour(cell.materials) if cell is not None else dataset_colour(dataset)
    ends = [*times[-1:], *(e["t"] for e in events)]
    ends += [tcp["t"][-1] for tcp in tcps if tcp["t"]]
    duration = summary.get("sim_seconds")
    if not isinstance(duration, (int, float)):
        duration = max(ends, default=0.0)
    data = {
        "episode": f"{run_dir.name}/{episode.name}",
        "seed": summary.get("seed"),
        "speed_mps": summary.get("belt_speed_mps", run.get("speed_mps")),
        "duration_s": round(float(duration), 4),
        "dataset": str(dataset) if dataset else None,
        "cell": _cell_data(cell) if cell else None,
        "classes": {c: rgb_hex(colour(c)) for c in classes},
        "highlight": HIGHLIGHT_HEX,
        "station_colours": list(STATION_HEX),
        "flag_bits": list(FLAG_BITS),
        "absent_bit": ABSENT_BIT,
        "frames": [round(t, 4) for t in times],
        "belt_mm": belt,
        "objects": objects,
        "tcp": tcps,
        "targets": targets,
        "events": events,
        "notes": notes,
    }
    return data, notes


# -- the page -----------------------------------------------------------------------------------
ASSETS = Path(__file__).with_name("player_assets")
"""The page's style, body and script (inlined into every page: it must open with no files)."""


def page_sources() -> list[Path]:
    """The files a player's page is made from: this module and every asset (a page older than
    any of them is stale)."""
    return [Path(__file__).resolve(), *sorted(p for p in ASSETS.rglob("*") if p.is_file())]


def _asset(name: str) -> str:
    return (ASSETS / name).read_text(encoding="utf-8")


def render_page(data: dict[str, Any]) -> str:
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
