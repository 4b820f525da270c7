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
import csv
import html
import os
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from experiments import stats
from experiments.report_data import (
    Episode,
    ReportError,
    RunData,
    Unavailable,
    find_run_dirs,
    load_runs,
    percentile,
    read_json,
    wilson_interval,
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
from experiments.report_plot import new_figure, speed_colour
from interfaces.errors import CdwTwinError
from interfaces.fileio import write_atomic
from interfaces.metrics import BY_NAME, rate
from interfaces.run_folder import EpisodeFolder

if TYPE_CHECKING:
    from matplotlib.figure import Figure

REFERENCE_MS_PER_IMAGE = 24.0
REFERENCE_MS_PER_OBJECT = 5.3
STEP_RATE_WINDOW_S = 60.0
FOOTPRINT_IMAGES = 4


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


def _rtt(ep: Episode) -> list[float]:
    return [float(v) for v in ((ep.telemetry or {}).get("rtt") or {}).get("rtt_ms", [])]


def _tracking_times(ep: Episode) -> list[float]:
    tracking = (ep.summary or {}).get("tracking") or {}
    times = tracking.get("tracking_times_s")
    if times is None and tracking.get("tracking_time_4mm_mean_s") is not None:
        times = [tracking["tracking_time_4mm_mean_s"]]
    return [float(t) for t in times or []]


def episode_rows(data: RunData) -> list[dict[str, Any]]:
    """One row per episode: counts, rates, tracking, RTT p50/p99 (ms), step rate, RTF."""
    rows = []
    for ep in data.episodes:
        counts = _counts(ep) or {}
        latency = (ep.summary or {}).get("latency") or {}
        rtt = _rtt(ep)
        rows.append(
            {
                "episode": ep.name,
                "speed_mps": ep.speed_mps,
                "seed": ep.seed,
                "complete": (ep.summary or {}).get("complete"),
                **counts,
                "success_rate": _pooled_rate("success_rate", counts),
                "miss_rate": _pooled_rate("miss_rate", counts),
                "tracking_time_4mm_mean_s": stats.mean_of(_tracking_times(ep)),
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
        rtt = [v for ep in eps for v in _rtt(ep)]
        latencies = [_latency(ep) for ep in eps]
        p50s = [float(x["rtt_ms_p50"]) for x in latencies if x.get("rtt_ms_p50") is not None]
        p99s = [float(x["rtt_ms_p99"]) for x in latencies if x.get("rtt_ms_p99") is not None]
        times = [t for ep in eps for t in _tracking_times(ep)]
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
def _with(data: RunData, key: str, what: str) -> list[Episode]:
    eps = [e for e in data.episodes if ((e.telemetry or {}).get(key) or {}).get(what)]
    if not eps:
        missing = sum(1 for e in data.episodes if e.telemetry is None)
        msg = (
            f"no episode has telemetry '{key}' samples ({missing} of {len(data.episodes)} "
            "episodes have no twin/telemetry.json)"
        )
        raise Unavailable(msg)
    return eps


def fig_step_rate(data: RunData) -> Figure:
    """Steps per wall second over the first 60 s of wall time, per episode, coloured by speed."""
    eps = _with(data, "step_rate", "wall_s")
    fig = new_figure()
    ax = fig.add_subplot()
    seen: set[float | None] = set()
    for ep in eps:
        rate = ep.telemetry["step_rate"]  # type: ignore[index]
        pairs = [(t, r) for t, r in zip(rate["wall_s"], rate["steps_per_s"], strict=True)]
        pairs = [(t, r) for t, r in pairs if t <= STEP_RATE_WINDOW_S]
        label = None if ep.speed_mps in seen else f"{ep.speed_mps} m/s"
        seen.add(ep.speed_mps)
        ax.plot(
            *zip(*pairs, strict=True),
            marker=".",
            color=speed_colour(data, ep.speed_mps),
            label=label,
        )
    ax.set_xlim(0, STEP_RATE_WINDOW_S)
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("simulated steps per wall second")
    ax.set_title("Step rate over the first 60 s (1 s windows)")
    ax.legend(title="belt speed")
    ax.grid(alpha=0.3)
    return fig


def fig_belt(data: RunData) -> Figure:
    """Belt setpoint (dashed) and measured speed (solid) over sim time, one episode per speed."""
    eps = _with(data, "belt", "sim_s")
    fig = new_figure()
    ax = fig.add_subplot()
    done: set[float | None] = set()
    for ep in eps:
        if ep.speed_mps in done:
            continue
        done.add(ep.speed_mps)
        belt = ep.telemetry["belt"]  # type: ignore[index]
        colour = speed_colour(data, ep.speed_mps)
        ax.plot(
            belt["sim_s"], belt["setpoint_mps"], "--", color=colour, label=f"setpoint {ep.name}"
        )
        ax.plot(belt["sim_s"], belt["speed_mps"], "-", color=colour, label=f"actual {ep.name}")
    ax.set_xlabel("sim time (s)")
    ax.set_ylabel("belt speed (m/s)")
    ax.set_title("Belt velocity: setpoint against actual")
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    return fig


def fig_rtt_time(data: RunData) -> Figure:
    """Round-trip latency of every command over wall time, coloured by speed."""
    eps = _with(data, "rtt", "rtt_ms")
    fig = new_figure()
    ax = fig.add_subplot()
    seen: set[float | None] = set()
    for ep in eps:
        rtt = ep.telemetry["rtt"]  # type: ignore[index]
        label = None if ep.speed_mps in seen else f"{ep.speed_mps} m/s"
        seen.add(ep.speed_mps)
        colour = speed_colour(data, ep.speed_mps)
        ax.plot(rtt["wall_s"], rtt["rtt_ms"], ".", ms=2, color=colour, label=label)
    ax.set_yscale("log")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("round-trip latency (ms)")
    ax.set_title("Round trip /joint_states -> /arm_controller/joint_trajectory")
    ax.legend(title="belt speed", markerscale=4)
    ax.grid(alpha=0.3, which="both")
    return fig


def fig_rtt_hist(data: RunData) -> Figure:
    """Histogram of the pooled round-trip latency per speed, p50 and p99 marked."""
    import numpy as np

    _with(data, "rtt", "rtt_ms")
    fig = new_figure()
    ax = fig.add_subplot()
    everything = [v for ep in data.episodes for v in _rtt(ep)]
    low, high = max(min(everything), 1e-3), max(everything)
    bins: list[float] | int = np.geomspace(low, high * 1.0001, 50).tolist() if high > low else 10
    for speed in data.speeds():
        values = [v for ep in data.at_speed(speed) for v in _rtt(ep)]
        if not values:
            continue
        colour = speed_colour(data, speed)
        ax.hist(values, bins=bins, histtype="step", color=colour, label=f"{speed} m/s")
        for q, style in ((50, "-"), (99, ":")):
            ax.axvline(float(np.percentile(values, q)), color=colour, ls=style, lw=1)
    ax.set_xscale("log")
    ax.set_xlabel("round-trip latency (ms); solid line p50, dotted p99")
    ax.set_ylabel("commands")
    ax.set_title("Round-trip latency distribution")
    ax.legend(title="belt speed")
    return fig


def fig_tracking(data: RunData) -> Figure:
    """Tracking time to 4 mm per speed: one dot per settled pursuit, box over them."""
    import numpy as np

    speeds = data.speeds()
    pursuits = {
        s: sum(
            int(((e.summary or {}).get("tracking") or {}).get("pursuits", 0))
            for e in data.at_speed(s)
        )
        for s in speeds
    }
    if not any(pursuits.values()):
        msg = "no pursuit was measured in any episode (no twin/summary.json tracking block)"
        raise Unavailable(msg)
    fig = new_figure()
    ax = fig.add_subplot()
    rng = np.random.default_rng(0)
    for i, speed in enumerate(speeds):
        times = [t for ep in data.at_speed(speed) for t in _tracking_times(ep)]
        if times:
            ax.boxplot([times], positions=[i], widths=0.5, showfliers=False)
            jitter = rng.uniform(-0.15, 0.15, len(times))
            ax.plot(i + jitter, times, ".", color=speed_colour(data, speed), alpha=0.7)
        ax.annotate(
            f"{len(times)}/{pursuits[speed]} settled",
            (i, 1.0),
            xycoords=("data", "axes fraction"),
            ha="center",
            va="top",
            fontsize="small",
        )
    ax.set_xticks(range(len(speeds)), [f"{s} m/s" for s in speeds])
    ax.set_xlim(-0.6, len(speeds) - 0.4)
    ax.set_ylabel("time to stay within 4 mm (s)")
    ax.set_xlabel("belt speed")
    ax.set_title("Tracking time to 4 mm (ground truth), per pursuit")
    ax.grid(alpha=0.3, axis="y")
    return fig


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


def fig_meshgen(data: RunData) -> Figure:
    """Meshgen ms per image and per object of each dataset against the reference."""
    found = []
    reasons = []
    for dataset in data.datasets:
        path = dataset / "summary.json"
        if not path.is_file():
            reasons.append(f"{path} missing")
            continue
        summary = read_json(path)
        found.append((dataset, float(summary["ms_per_image"]), float(summary["ms_per_object"])))
    if not found:
        raise Unavailable("; ".join(reasons) or "no dataset")
    fig = new_figure()
    ax = fig.add_subplot()
    labels = ["ms / image", "ms / object"]
    width = 0.8 / (len(found) + 1)
    ref = (REFERENCE_MS_PER_IMAGE, REFERENCE_MS_PER_OBJECT)
    ax.bar([i - 0.4 + width / 2 for i in range(2)], ref, width, color="grey", label="reference")
    for k, (dataset, per_image, per_object) in enumerate(found, start=1):
        xs = [i - 0.4 + width * (k + 0.5) for i in range(2)]
        bars = ax.bar(
            xs, (per_image, per_object), width, label=f"{dataset.parent.name}/{dataset.name}"
        )
        ax.bar_label(bars, fmt="%.2f", fontsize=7)
    ax.set_xticks(range(2), labels)
    ax.set_ylabel("wall-clock milliseconds (whole-run mean)")
    ax.set_title("Mesh generation timing (meshgen summary.json)")
    ax.legend(fontsize="small")
    return fig


@dataclass(frozen=True)
class _Outline:
    class_name: str
    source_m: list[tuple[float, float]] | None
    footprint_m: list[tuple[float, float]]


def _source_root(dataset: Path, source: str) -> Path | None:
    for root in (dataset.parent / "sample", dataset.parent, dataset.parent.parent):
        if (root / source).is_file():
            return root
    return None


def _source_polygon_px(path: Path, where: str, size: tuple[int, int]) -> list[tuple[float, float]]:
    kind, _, number = where.partition(" ")
    index = int(number)
    if path.suffix == ".txt" and kind == "line":
        tokens = path.read_text(encoding="utf-8").splitlines()[index - 1].split()[1:]
        values = [float(t) for t in tokens]
        return [(values[i] * size[0], values[i + 1] * size[1]) for i in range(0, len(values), 2)]
    if path.suffix == ".json" and kind == "shape":
        shape = read_json(path)["shapes"][index]
        return [(float(u), float(v)) for u, v in shape["points"]]
    msg = f"{path}: cannot read {where!r}"
    raise ValueError(msg)


def _bottom_face(mesh: Path, up: str) -> list[tuple[float, float]]:
    """The vertices of a mesh's lowest face in the belt frame (x travel, y across)."""
    from meshgen.objfile import read_obj

    vertices = read_obj(mesh).vertices
    axis = 2 if up == "z" else 1
    low = float(vertices[:, axis].min())
    bottom = vertices[abs(vertices[:, axis] - low) < 1e-9]
    return [(float(v[0]), float(v[1]) if up == "z" else -float(v[2])) for v in bottom]


def _image_outlines(dataset: Path, stem: str) -> tuple[list[_Outline], str]:
    """Outlines of one meshed image in the belt frame (x travel, y across), and the source used."""
    scene = read_json(dataset / stem / "scene.json")
    with (dataset / stem / "scene.csv").open(encoding="utf-8", newline="") as handle:
        placed = {row["object_id"]: row for row in csv.DictReader(handle)}
    size = (int(scene["width_px"]), int(scene["height_px"]))
    m_per_px = float(scene["m_per_px"])
    root = _source_root(dataset, str(scene["source"]))
    outlines = []
    for obj in scene["objects"]:
        row = placed[obj["object_id"]]
        if root is not None:
            polygon = _source_polygon_px(root / obj["source_image"], obj["source_where"], size)
        else:
            polygon = [(float(u), float(v)) for u, v in obj["polygon_px"]]
        source = [((v - size[1] / 2) * m_per_px, (u - size[0] / 2) * m_per_px) for u, v in polygon]
        cx, cy = float(row["centroid_x_m"]), float(row["centroid_y_m"])
        bottom = _bottom_face(dataset / stem / row["mesh_path"], str(scene.get("up", "z")))
        footprint = [(x + cx, y + cy) for x, y in bottom]
        outlines.append(_Outline(str(row["class_name"]), source, footprint))
    used = f"annotations in {root}" if root else "polygon_px recorded in scene.json"
    return outlines, used


def fig_footprints(data: RunData) -> Figure:
    """Source polygons (black dashed) over the generated footprints for up to 4 images, each
    footprint in its class's colour (the dataset's class table)."""
    from matplotlib.patches import Polygon

    if not data.datasets:
        raise Unavailable("no dataset")
    dataset = data.datasets[0]
    index = dataset / "index.csv"
    if not index.is_file():
        msg = f"{index} missing"
        raise Unavailable(msg)
    with index.open(encoding="utf-8", newline="") as handle:
        stems = [r["image"] for r in csv.DictReader(handle) if int(r["objects"]) > 0]
    stems = stems[:FOOTPRINT_IMAGES]
    if not stems:
        msg = f"{index}: no image with meshed objects"
        raise Unavailable(msg)
    import matplotlib as mpl

    fig = new_figure(9.0, 8.0)
    axes = fig.subplots(2, 2, squeeze=False).ravel()
    colours: dict[str, Any] = {}
    from interfaces.class_colours import dataset_colour

    colour_of = dataset_colour(dataset)
    used = ""
    for ax, stem in zip(axes, stems, strict=False):
        outlines, used = _image_outlines(dataset, stem)
        for o in outlines:
            colour = colours.setdefault(o.class_name, colour_of(o.class_name))
            ring = [(y, x) for x, y in o.footprint_m]
            ax.add_patch(Polygon(ring, closed=True, color=colour, alpha=0.45))
            if o.source_m:
                src = [(y, x) for x, y in o.source_m]
                ax.add_patch(Polygon(src, closed=True, fill=False, ec="black", ls="--", lw=0.8))
        ax.autoscale_view()
        ax.set_aspect("equal")
        ax.invert_yaxis()
        ax.set_title(stem, fontsize="small")
        ax.set_xlabel("y (m, image right)", fontsize="small")
        ax.set_ylabel("x (m, travel / image down)", fontsize="small")
    for ax in axes[len(stems) :]:
        ax.set_axis_off()
    handles: list[Any] = [
        mpl.patches.Patch(color=c, alpha=0.45, label=n) for n, c in colours.items()
    ]
    handles.append(mpl.lines.Line2D([], [], color="black", ls="--", label="source polygon"))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize="small")
    fig.suptitle(f"Source polygons over generated footprints ({used})", fontsize="medium")
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


# -- output -----------------------------------------------------------------------------------
def _save_png(fig: Figure, path: Path) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            fig.savefig(handle, format="png")
        Path(tmp).chmod(0o644)
        Path(tmp).replace(path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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
            _save_png(fig, png)
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
