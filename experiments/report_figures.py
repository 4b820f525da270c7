"""The report's figures: step rate, belt speed, round-trip latency, tracking time, rates with
their intervals, recovery against the number of stations, meshgen timing and footprints against
the source photos. Each takes the report's data (:class:`experiments.report_data.RunData`) and
gives a matplotlib figure, or raises :class:`experiments.report_data.Unavailable` saying what is
missing; :data:`FIGURES` lists them in the page's order.
"""

from __future__ import annotations

import csv
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from experiments.report_data import Episode, RunData, Telemetry, Unavailable, read_json
from experiments.report_line import recovery_by_stations
from experiments.report_plot import new_figure, speed_colour
from experiments.report_tables import speed_rows

if TYPE_CHECKING:
    from matplotlib.figure import Figure

REFERENCE_MS_PER_IMAGE = 24.0


REFERENCE_MS_PER_OBJECT = 5.3


STEP_RATE_WINDOW_S = 60.0


FOOTPRINT_IMAGES = 4


def _with(
    data: RunData, key: str, has: Callable[[Telemetry], bool]
) -> list[tuple[Episode, Telemetry]]:
    """The episodes whose telemetry has series ``key`` (``has`` says whether it has), each
    with its telemetry; :class:`Unavailable` when none has."""
    eps = [(e, e.telemetry) for e in data.episodes if e.telemetry is not None and has(e.telemetry)]
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
    eps = _with(data, "step_rate", lambda t: bool(t.step_rate.wall_s))
    fig = new_figure()
    ax = fig.add_subplot()
    seen: set[float | None] = set()
    for ep, telemetry in eps:
        rate = telemetry.step_rate
        pairs = [(t, r) for t, r in zip(rate.wall_s, rate.steps_per_s, strict=True)]
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
    eps = _with(data, "belt", lambda t: bool(t.belt.sim_s))
    fig = new_figure()
    ax = fig.add_subplot()
    done: set[float | None] = set()
    for ep, telemetry in eps:
        if ep.speed_mps in done:
            continue
        done.add(ep.speed_mps)
        belt = telemetry.belt
        colour = speed_colour(data, ep.speed_mps)
        ax.plot(belt.sim_s, belt.setpoint_mps, "--", color=colour, label=f"setpoint {ep.name}")
        ax.plot(belt.sim_s, belt.speed_mps, "-", color=colour, label=f"actual {ep.name}")
    ax.set_xlabel("sim time (s)")
    ax.set_ylabel("belt speed (m/s)")
    ax.set_title("Belt velocity: setpoint against actual")
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    return fig


def fig_rtt_time(data: RunData) -> Figure:
    """Round-trip latency of every command over wall time, coloured by speed."""
    eps = _with(data, "rtt", lambda t: bool(t.rtt.rtt_ms))
    fig = new_figure()
    ax = fig.add_subplot()
    seen: set[float | None] = set()
    for ep, telemetry in eps:
        rtt = telemetry.rtt
        label = None if ep.speed_mps in seen else f"{ep.speed_mps} m/s"
        seen.add(ep.speed_mps)
        colour = speed_colour(data, ep.speed_mps)
        ax.plot(rtt.wall_s, rtt.rtt_ms, ".", ms=2, color=colour, label=label)
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

    _with(data, "rtt", lambda t: bool(t.rtt.rtt_ms))
    fig = new_figure()
    ax = fig.add_subplot()
    everything = [v for ep in data.episodes for v in ep.rtt_ms]
    low, high = max(min(everything), 1e-3), max(everything)
    bins: list[float] | int = np.geomspace(low, high * 1.0001, 50).tolist() if high > low else 10
    for speed in data.speeds():
        values = [v for ep in data.at_speed(speed) for v in ep.rtt_ms]
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


def _pursuits(ep: Episode) -> int:
    tracking = ep.summary.tracking if ep.summary is not None else None
    return tracking.pursuits if tracking is not None else 0


def fig_tracking(data: RunData) -> Figure:
    """Tracking time to 4 mm per speed: one dot per settled pursuit, box over them."""
    import numpy as np

    speeds = data.speeds()
    pursuits = {s: sum(_pursuits(e) for e in data.at_speed(s)) for s in speeds}
    if not any(pursuits.values()):
        msg = "no pursuit was measured in any episode (no twin/summary.json tracking block)"
        raise Unavailable(msg)
    fig = new_figure()
    ax = fig.add_subplot()
    rng = np.random.default_rng(0)
    for i, speed in enumerate(speeds):
        times = [t for ep in data.at_speed(speed) for t in ep.tracking_times_s]
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
    rows = [r for r in speed_rows(data) if r.success_rate is not None or r.miss_rate is not None]
    if not rows:
        msg = "no episode has both twin/summary.json scores and targeted objects or processed ones"
        raise Unavailable(msg)
    fig = new_figure()
    ax = fig.add_subplot()
    x = list(range(len(rows)))
    for offset, key, total, label, colour in (
        (-0.15, "success", "targeted", "success (correct bin / targeted)", "tab:green"),
        (0.15, "miss", "processed", "miss (missed / processed)", "tab:red"),
    ):
        xs, ys, lo, hi = [], [], [], []
        for i, row in enumerate(rows):
            rate, (a, b) = (
                (row.success_rate, row.success_ci95)
                if key == "success"
                else (row.miss_rate, row.miss_ci95)
            )
            if rate is None:
                continue
            xs.append(i + offset)
            ys.append(rate)
            lo.append(rate - a)
            hi.append(b - rate)
            n = row.totals.get(total)
            ax.annotate(f"n={n}", (i + offset, b), ha="center", va="bottom", fontsize=7)
        ax.errorbar(xs, ys, yerr=[lo, hi], fmt="o", capsize=4, color=colour, label=label)
    several = len({r.cell for r in rows}) > 1
    labels = [f"{r.cell}\n{r.speed_mps} m/s" if several else f"{r.speed_mps} m/s" for r in rows]
    ax.set_xticks(x, labels)
    ax.set_xlim(-0.6, len(rows) - 0.4)
    ax.set_ylim(-0.02, 1.1)
    ax.set_ylabel("rate (95 % Wilson interval, pooled episodes)")
    ax.set_xlabel("cell and belt speed" if several else "belt speed")
    ax.set_title("Success and miss rate per belt speed")
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3, axis="y")
    return fig


def fig_recovery_stations(data: RunData) -> Figure:
    """Line recovery against the number of stations, one line per belt speed: the mean over
    the episodes (seeds) with its 95 % Student t interval."""
    rows = [r for r in recovery_by_stations(data) if r.recovery_mean is not None]
    if not rows:
        msg = "no episode has metrics (events, summary and controller stats)"
        raise Unavailable(msg)
    fig = new_figure()
    ax = fig.add_subplot()
    speeds = sorted({r.speed_mps for r in rows})
    for i, speed in enumerate(speeds):
        line = [r for r in rows if r.speed_mps == speed]
        dx = 0.04 * (i - (len(speeds) - 1) / 2)  # side by side, so equal values stay apart
        xs = [r.stations + dx for r in line]
        ys = [r.recovery_mean or 0.0 for r in line]
        spans = [r.recovery_ci95 or (y, y) for r, y in zip(line, ys, strict=True)]
        lo = [y - a for y, (a, _) in zip(ys, spans, strict=True)]
        hi = [b - y for y, (_, b) in zip(ys, spans, strict=True)]
        colour = speed_colour(data, speed)
        ax.errorbar(xs, ys, yerr=[lo, hi], fmt="o-", capsize=4, color=colour, label=f"{speed} m/s")
        for x, y, r in zip(xs, ys, line, strict=True):
            ax.annotate(
                f"n={r.episodes}",
                (x, y),
                textcoords="offset points",
                xytext=(5, -10),
                fontsize=7,
            )
    ax.set_xticks(sorted({r.stations for r in rows}))
    ax.set_ylim(-0.02, 1.05)
    ax.set_xlabel("stations along the belt")
    ax.set_ylabel("recovery (mean, 95 % t interval over seeds)")
    ax.set_title("Recovery against the number of stations")
    ax.legend(title="belt speed", fontsize="small")
    ax.grid(alpha=0.3)
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
    from interfaces.class_colours import RGB, dataset_colour

    colours: dict[str, RGB] = {}

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


def save_png(fig: Figure, path: Path) -> None:
    """Write ``fig`` as the PNG ``path``, whole (a temporary file renamed in place)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            fig.savefig(handle, format="png")
        Path(tmp).chmod(0o644)
        Path(tmp).replace(path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
