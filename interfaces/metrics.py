"""The metric table: every score the benchmark reports, its unit and its formula, defined once.

The twin's ``summary.json`` scores, ``cdw-twin run``'s per-episode metrics, the sweep's
intervals, the offline recomputation from a recording and the report all compute from here;
``docs/metrics.md`` lists the table (a test keeps the two equal).

Counts come from the sorting events alone (:func:`count_events`), as the environment, not the
competitor, computes them; ``targeted`` comes from the controllers' statistics, the one figure
only the controller knows. An object's fate is its last deciding event: ``pick_success`` makes
it picked, a later ``pick_dropped`` or ``fell_off`` makes it lost (until it is picked again),
``missed`` makes it missed unless it is picked afterwards; *processed* objects are those with
a fate. For one station, the same rules apply to the events that name that station (their
``data["station"]``); for one class, to the events about objects of that class.

Every metric has *scopes*: ``line`` (the whole cell), ``station`` (one station's events and
controller), ``class`` (the objects of one class) and ``bin`` (the objects that came to rest in
one bin of one station). A rate (``kind`` ``rate``) is the ratio
of two counts of the table (``ratio_of``); pooled over episodes it is the ratio of the summed
counts (with a Wilson interval), never the mean of the ratios.

The reference's equations: (1) success rate = picked / processed, (2) miss rate = missed /
processed, (3) throughput = picked per minute. Every ratio is 0 when its denominator is 0.

Line scores: ``recovery_takeable``, the recovery over the pieces some station of the cell could
take (by the controllers' static rules, judged as each piece spawned: the ``spawned`` event's
``takeable``), beside ``recovery_rate`` per class and for the line, ``recovered`` / ``entered``:
objects placed in their class's bin / objects that entered, over the *complete cohort*
(:func:`complete_cohort`): in spawn order, every object spawned before the first one still
undecided when the episode ends, so every one of them has a fate (or lies in a bin, knocked
there unpicked). An object still on its way
along the belt, and every one spawned after it, is left out of both counts: the figure neither
falls with the share of the stream still in flight at the end (``placed_correct`` /
``spawned`` would) nor rises with it (with ``processed`` as denominator the objects in flight
an upstream station already picked would count, those it let pass would not). Per class, the
cohort's objects of that class, the cut taken over the whole stream. Then ``purity`` (of each
bin, :func:`bin_scores`; per class over the line: the share of the class's own objects among
all objects that came to rest in the bins sorting it), the line's ``miss_rate`` (the most
downstream station's misses), ``pick_throughput_per_min`` per station and for the line; drops
by reason (``dropped_by_reason``, :data:`DROP_REASONS`) and the controllers' allocation
decisions per station (``untargeted`` by reason, :func:`untargeted_scores`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from interfaces.events import Event, EventType
from interfaces.run_records import MetricValue, PickStats, TrackingSummary

Scope = Literal["line", "station", "class", "bin"]
"""Where a metric is given: for the whole line, per station, per object class, per bin."""

EVENT_SCOPES: tuple[Scope, ...] = ("line", "station", "class")
CELL_SCOPES: tuple[Scope, ...] = ("line", "station")
BIN_SCOPES: tuple[Scope, ...] = ("line", "station", "class", "bin")

DROP_REASONS: tuple[str, ...] = ("released", "slipped", "suction_overload", "seal_lost")
"""Why a held object dropped (``pick_dropped`` ``data["reason"]``): the tool opened away from
every bin, the jaws' friction could not carry it, the cup's holding force could not, the cup's
seal was lost. An event without a reason (logs written before drops carried one) counts as
``released``, the only kind of drop then."""

UNFIT_REASONS: tuple[str, ...] = ("too_wide", "too_flat", "too_small", "too_tilted")
"""The controllers' ``untargeted`` reasons that say the station's tool cannot take the object
(wider than the jaws open, too flat for the pads, a top face smaller than the suction cup or
tilted more than its lip seals on)."""


@dataclass(frozen=True, kw_only=True)
class Metric:
    """One metric: ``name`` (the key in every table), unit, formula, what the reference calls
    it, how it pools over episodes (``count``: summed; ``rate``: a ratio of two counts, also
    given as a Wilson interval over pooled counts; ``time``: averaged) and where it is given
    (``scopes``)."""

    name: str
    unit: str
    formula: str
    reference: str = ""
    kind: Literal["count", "rate", "time"]
    ratio_of: tuple[str, str] | None = None
    scopes: tuple[Scope, ...] = CELL_SCOPES


METRICS: tuple[Metric, ...] = (
    Metric(
        name="spawned",
        unit="objects",
        formula="objects that entered the belt (for a station: that entered its pick window)",
        kind="count",
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="entered",
        unit="objects",
        formula="objects of the complete cohort: in spawn order (for a station: the order they "
        "entered its pick window), every object before the first one still undecided (no fate, "
        "in no bin) when the episode ended, or every spawned object when none is; for a class, the "
        "cohort's objects of that class, the cut taken over every class",
        kind="count",
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="processed",
        unit="objects",
        formula="objects whose fate is decided: picked + missed + lost",
        reference="processed objects (eq. 1, 2)",
        kind="count",
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="picked",
        unit="objects",
        formula="objects whose fate is picked",
        kind="count",
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="missed",
        unit="objects",
        formula="objects that left the pick window downstream unpicked (for the line: the "
        "most downstream station's) and were not picked later",
        kind="count",
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="lost",
        unit="objects",
        formula="objects dropped away from every bin or fallen off, not picked again",
        kind="count",
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="placed",
        unit="objects",
        formula="objects that came to rest in a bin (for a station: in one of its bins)",
        kind="count",
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="placed_correct",
        unit="objects",
        formula="objects that came to rest in their class's bin",
        kind="count",
        scopes=BIN_SCOPES,
    ),
    Metric(
        name="sorted",
        unit="objects",
        formula="objects a tool picked (`pick_success`) and let go into their class's bin "
        "(`placed_correct` less the pieces that got there unpicked, with another or knocked in, "
        "and the ones dropped on the way that fell in)",
        kind="count",
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="recovered",
        unit="objects",
        formula="objects of the complete cohort (`entered`) that came to rest in their class's "
        "bin; one picked but still carried or falling into a bin at the end counts in "
        "`entered`, not here",
        kind="count",
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="entered_takeable",
        unit="objects",
        formula="objects of the complete cohort (`entered`) that some station of the cell could "
        "take, by its controller's static rules, when they spawned (the `spawned` event's "
        "`takeable`; an object whose `spawned` event does not say counts as takeable)",
        kind="count",
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="recovered_takeable",
        unit="objects",
        formula="objects of `entered_takeable` that came to rest in their class's bin",
        kind="count",
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="binned",
        unit="objects",
        formula="objects of any class that came to rest in the scope's bins: every bin (line), "
        "the station's (station), those sorting the class (class), the bin itself (bin)",
        kind="count",
        scopes=BIN_SCOPES,
    ),
    Metric(
        name="dropped",
        unit="drops",
        formula="held objects that dropped (`pick_dropped` events), by reason in "
        "`dropped_by_reason`: released, slipped, suction_overload, seal_lost",
        kind="count",
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="targeted",
        unit="objects",
        formula="objects a controller committed to and finished with (completed or aborted), "
        "less those released into a bin still falling when the episode ended",
        kind="count",
    ),
    Metric(
        name="untargeted_total",
        unit="objects",
        formula="objects a controller never targeted (by reason in `untargeted`)",
        kind="count",
    ),
    Metric(
        name="considered",
        unit="objects",
        formula="objects a station's controller decided about: those it targeted (its `pick` "
        "counter `targeted`) and those it never targeted (`untargeted_total`)",
        kind="count",
        scopes=("station",),
    ),
    Metric(
        name="untargeted_unfit",
        unit="objects",
        formula="objects a station's controller never targeted because its tool cannot take "
        "them (`untargeted` reasons too_wide, too_flat, too_small, too_tilted)",
        kind="count",
        scopes=("station",),
    ),
    Metric(
        name="unintended_contacts",
        unit="contacts",
        formula="robot links touching an object the robot is not picking",
        kind="count",
    ),
    Metric(
        name="pick_success_rate",
        unit="1",
        formula="picked / processed",
        reference="eq. 1, success rate",
        kind="rate",
        ratio_of=("picked", "processed"),
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="miss_rate",
        unit="1",
        formula="missed / processed",
        reference="eq. 2, miss rate",
        kind="rate",
        ratio_of=("missed", "processed"),
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="pick_throughput_per_min",
        unit="1/min",
        formula="picked / simulated minutes",
        reference="eq. 3, throughput",
        kind="time",
    ),
    Metric(
        name="success_rate",
        unit="1",
        formula="sorted / targeted",
        kind="rate",
        ratio_of=("sorted", "targeted"),
    ),
    Metric(
        name="throughput_per_min",
        unit="1/min",
        formula="placed_correct / simulated minutes",
        kind="time",
    ),
    Metric(
        name="recovery_rate",
        unit="1",
        formula="recovered / entered",
        kind="rate",
        ratio_of=("recovered", "entered"),
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="recovery_takeable",
        unit="1",
        formula="recovered_takeable / entered_takeable",
        kind="rate",
        ratio_of=("recovered_takeable", "entered_takeable"),
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="correct_bin_ratio",
        unit="1",
        formula="placed_correct / placed",
        kind="rate",
        ratio_of=("placed_correct", "placed"),
        scopes=EVENT_SCOPES,
    ),
    Metric(
        name="purity",
        unit="1",
        formula="placed_correct / binned",
        kind="rate",
        ratio_of=("placed_correct", "binned"),
        scopes=BIN_SCOPES,
    ),
    Metric(
        name="unfit_share",
        unit="1",
        formula="untargeted_unfit / considered",
        kind="rate",
        ratio_of=("untargeted_unfit", "considered"),
        scopes=("station",),
    ),
    Metric(
        name="time_per_object_s",
        unit="s",
        formula="simulated seconds / picked (0 without a pick)",
        kind="time",
    ),
    Metric(
        name="tracking_time_4mm_mean_s",
        unit="s",
        formula="mean over settled pursuits of the time from a target's start until the TCP "
        "stays within 4 mm of its true grasp point until the pursuit ends",
        kind="time",
    ),
    Metric(
        name="tracking_time_4mm_p95_s",
        unit="s",
        formula="95th percentile of the same",
        kind="time",
    ),
    Metric(
        name="tracking_pursuits",
        unit="pursuits",
        formula="targets the twin measured a tracking time for (settled or not)",
        kind="count",
    ),
    Metric(
        name="tracking_unsettled",
        unit="pursuits",
        formula="pursuits whose TCP never stayed within 4 mm until they ended",
        kind="count",
    ),
    Metric(
        name="real_time_factor",
        unit="1",
        formula="simulated seconds / wall seconds of the twin's step loop",
        kind="time",
        scopes=("line",),
    ),
    Metric(
        name="faults",
        unit="faults",
        formula="fault events other than injected ones (rejected commands, controller timeouts)",
        kind="count",
    ),
    Metric(
        name="injected_faults",
        unit="faults",
        formula="the scenario's injected-fault window edges (fault events of kind `injected_*`)",
        kind="count",
        scopes=("line",),
    ),
    Metric(
        name="controller_restarts",
        unit="restarts",
        formula="controller processes started after the first (the scenario's planned restarts)",
        kind="count",
    ),
)
"""Every metric, in the order tables list them."""

BY_NAME: dict[str, Metric] = {m.name: m for m in METRICS}
"""The metric table by name."""

RATES: tuple[Metric, ...] = tuple(m for m in METRICS if m.kind == "rate" and m.ratio_of)
"""The rates: each the ratio of two counts of the table."""


def in_scope(scope: Scope) -> tuple[str, ...]:
    """The names of the metrics given for ``scope``, in table order."""
    return tuple(m.name for m in METRICS if scope in m.scopes)


@dataclass(frozen=True, kw_only=True)
class Counts:
    """What the events of one episode (of one station, or of one class) add up to.

    ``entered`` and ``recovered`` count the complete cohort (:func:`complete_cohort`), their
    ``_by_class`` mappings the same per object class; ``entered_takeable`` and
    ``recovered_takeable`` those of them some station could take (:func:`untakeable`);
    ``spawned`` and ``placed_correct`` count every object.
    """

    spawned: int = 0
    entered: int = 0
    processed: int = 0
    picked: int = 0
    missed: int = 0
    lost: int = 0
    placed: int = 0
    placed_correct: int = 0
    sorted: int = 0
    recovered: int = 0
    entered_takeable: int = 0
    recovered_takeable: int = 0
    binned: int = 0
    dropped: int = 0
    unintended_contacts: int = 0
    duration_s: float = 0.0
    placed_correct_by_class: Mapping[str, int] = field(default_factory=dict)
    spawned_by_class: Mapping[str, int] = field(default_factory=dict)
    entered_by_class: Mapping[str, int] = field(default_factory=dict)
    recovered_by_class: Mapping[str, int] = field(default_factory=dict)
    dropped_by_reason: Mapping[str, int] = field(default_factory=dict)


def untakeable(event: Event) -> bool:
    """Whether a ``spawned`` event says no station of the cell could take its object (its
    ``takeable`` is false: :mod:`twin.spawn_fit`); an event that does not say is takeable."""
    return event.type is EventType.SPAWNED and event.data.get("takeable") is False


def station_of(event: Event) -> str | None:
    """The station an event names (its ``data["station"]``), None for a cell-wide event."""
    station = event.data.get("station")
    return None if station is None else str(station)


def drop_reason(event: Event) -> str:
    """Why a ``pick_dropped`` event's object dropped (:data:`DROP_REASONS`; ``released`` when
    the event names no reason)."""
    return str(event.data.get("reason") or "released")


def _selected(
    events: Iterable[Event], station: str | None, class_name: str | None
) -> Iterable[Event]:
    for event in events:
        if station is not None and station_of(event) != station:
            continue
        if class_name is not None and event.class_name != class_name:
            continue
        yield event


def exit_station(stations: Iterable[Any]) -> str:
    """The name of the station whose pick window ends the line (the most downstream one): an
    object it misses is missed by the line. ``stations`` are a cell's
    (:class:`interfaces.cell.StationSpec`: ``name``, ``pick_window_x_m``)."""
    return str(max(stations, key=lambda s: s.pick_window_x_m[1]).name)


@dataclass
class _Tally:
    """The running state of :func:`count_events`."""

    spawned: dict[int, str] = field(default_factory=dict)
    spawned_at_s: dict[int, float] = field(default_factory=dict)
    fate: dict[int, str] = field(default_factory=dict)
    placed: set[int] = field(default_factory=set)
    placed_correct: dict[int, str] = field(default_factory=dict)
    carried: set[int] = field(default_factory=set)
    sorted: set[int] = field(default_factory=set)
    binned: set[int] = field(default_factory=set)
    drops: list[str] = field(default_factory=list)
    unintended: int = 0


def _count_fate(tally: _Tally, event: Event, *, station: str | None, line_exit: str | None) -> None:
    """Apply one event (already selected) to the objects' fates and the counters."""
    oid, kind = event.object_id, event.type
    if kind is EventType.SPAWNED and station is None:
        tally.spawned[oid] = event.class_name
        tally.spawned_at_s.setdefault(oid, event.time_s)
    elif kind is EventType.ENTERED_WORKSPACE and station is not None:
        tally.spawned.setdefault(oid, event.class_name)
        tally.spawned_at_s.setdefault(oid, event.time_s)
    elif kind is EventType.PICK_SUCCESS:
        tally.fate[oid] = "picked"
        tally.carried.add(oid)
    elif kind is EventType.MISSED:
        if station is not None or line_exit is None or station_of(event) in (None, line_exit):
            tally.fate.setdefault(oid, "missed")
    elif kind in (EventType.FELL_OFF, EventType.PICK_DROPPED):
        if tally.fate.get(oid) != "missed":
            tally.fate[oid] = "lost"
        if kind is EventType.PICK_DROPPED:
            tally.drops.append(drop_reason(event))
            tally.carried.discard(oid)
    elif kind is EventType.PLACED_IN_BIN:
        tally.placed.add(oid)
        if event.data.get("correct"):
            tally.placed_correct[oid] = event.class_name
            if oid in tally.carried:
                tally.sorted.add(oid)
    elif kind is EventType.UNINTENDED_CONTACT:
        tally.unintended += 1


def _cohort_of(tally: _Tally) -> set[int]:
    """The complete cohort of a tally's spawned objects (:func:`complete_cohort`)."""
    order = sorted(tally.spawned, key=tally.spawned_at_s.__getitem__)
    for position, oid in enumerate(order):
        if oid not in tally.fate and oid not in tally.placed:
            return set(order[:position])
    return set(order)


def complete_cohort(
    events: Iterable[Event], *, station: str | None = None, line_exit: str | None = None
) -> set[int]:
    """The objects of the complete cohort: those whose recovery an episode can judge.

    The spawned objects (with ``station``: those that entered its pick window) in spawn order
    (the time of their ``spawned`` event, or of their first ``entered_workspace`` at the
    station; equal times in the order of the events), up to, not including, the first one that
    is undecided when the events end (no fate, by the rules of :func:`count_events`, with
    ``line_exit`` for the line, and in no bin: an object knocked into a bin unpicked is out of
    the stream, and cutting there left an episode with no cohort and a recovery of 0). Every
    object of the cohort has a fate or lies in a bin; none after the cut
    counts, even one already placed. Every spawned object when none is undecided. Taken over
    every class, so a class's share of the cohort is consistent with the line's.
    """
    tally = _Tally()
    for event in _selected(events, station, None):
        _count_fate(tally, event, station=station, line_exit=line_exit)
    return _cohort_of(tally)


def count_events(
    events: Iterable[Event],
    duration_s: float,
    *,
    station: str | None = None,
    class_name: str | None = None,
    line_exit: str | None = None,
) -> Counts:
    """The counts of an episode of ``duration_s`` simulated seconds from its events.

    With ``station``, only events that name that station count, and ``spawned`` is the number
    of objects that entered its pick window. With ``class_name``, only events about objects of
    that class count, except ``binned``: the objects of any class that came to rest in a bin
    sorting ``class_name`` (so ``purity`` is the share of that class in its bins).

    ``line_exit`` (for the line, ``station`` None) names the station whose window ends the line
    (:func:`exit_station`): then only its ``missed`` events (and those naming no station) make
    an object missed for the line; an object an upstream station missed is still on its way to
    the next window (undecided) unless it is picked, lost or missed there. Without it every
    ``missed`` event counts, which is exact for a cell of one station.

    ``entered`` and ``recovered`` count the complete cohort (:func:`complete_cohort`, its cut
    taken over every class even with ``class_name``): its objects, and those of them that came
    to rest in their class's bin. An object picked but still carried, or still falling into a
    bin, when the episode ends is decided (picked): it counts in ``entered``, not in
    ``recovered``. ``entered_takeable`` and ``recovered_takeable`` count those of them whose
    ``spawned`` event does not say that no station could take them (:func:`untakeable`; at
    every scope, a station's too, though its events do not include the ``spawned`` ones).
    """
    tally = _Tally()
    stream = tally if class_name is None else _Tally()
    refused: set[int] = set()
    for event in events:
        if untakeable(event):
            refused.add(event.object_id)
        if station is not None and station_of(event) != station:
            continue
        if event.type is EventType.PLACED_IN_BIN and (
            class_name is None or event.data.get("bin") == class_name
        ):
            tally.binned.add(event.object_id)
        if stream is not tally:
            _count_fate(stream, event, station=station, line_exit=line_exit)
        if class_name is not None and event.class_name != class_name:
            continue
        _count_fate(tally, event, station=station, line_exit=line_exit)
    cohort = _cohort_of(stream)
    entered = {oid: name for oid, name in tally.spawned.items() if oid in cohort}
    recovered = [name for oid, name in tally.placed_correct.items() if oid in entered]
    takeable = {oid for oid in entered if oid not in refused}
    recovered_takeable = [oid for oid in tally.placed_correct if oid in takeable]
    outcomes = list(tally.fate.values())
    return Counts(
        spawned=len(tally.spawned),
        entered=len(entered),
        processed=len(tally.fate),
        picked=outcomes.count("picked"),
        missed=outcomes.count("missed"),
        lost=outcomes.count("lost"),
        placed=len(tally.placed),
        placed_correct=len(tally.placed_correct),
        sorted=len(tally.sorted),
        recovered=len(recovered),
        entered_takeable=len(takeable),
        recovered_takeable=len(recovered_takeable),
        binned=len(tally.binned),
        dropped=len(tally.drops),
        unintended_contacts=tally.unintended,
        duration_s=duration_s,
        placed_correct_by_class=_tally(tally.placed_correct.values()),
        spawned_by_class=_tally(tally.spawned.values()),
        entered_by_class=_tally(entered.values()),
        recovered_by_class=_tally(recovered),
        dropped_by_reason=_tally(tally.drops),
    )


def _tally(names: Iterable[str]) -> dict[str, int]:
    out: dict[str, int] = {}
    for name in names:
        out[name] = out.get(name, 0) + 1
    return out


def ratio(numerator: float, denominator: float) -> float:
    """``numerator / denominator``, 0 when the denominator is 0 (the table's convention)."""
    return numerator / denominator if denominator else 0.0


def rate(name: str, counts: Mapping[str, float]) -> float:
    """The rate ``name`` of the table from ``counts`` (its two counts by name, e.g. summed
    over episodes): ``ratio(counts[numerator], counts[denominator])``."""
    metric = BY_NAME[name]
    if metric.ratio_of is None:
        msg = f"metric {name!r} is not a ratio of two counts"
        raise KeyError(msg)
    numerator, denominator = metric.ratio_of
    return ratio(counts[numerator], counts[denominator])


def _count_values(counts: Counts) -> dict[str, float]:
    return {
        "spawned": counts.spawned,
        "entered": counts.entered,
        "processed": counts.processed,
        "picked": counts.picked,
        "missed": counts.missed,
        "lost": counts.lost,
        "placed": counts.placed,
        "placed_correct": counts.placed_correct,
        "sorted": counts.sorted,
        "recovered": counts.recovered,
        "entered_takeable": counts.entered_takeable,
        "recovered_takeable": counts.recovered_takeable,
        "binned": counts.binned,
    }


def event_scores(counts: Counts) -> dict[str, Any]:
    """The metrics the events alone give (the twin's ``summary.json`` ``scores``), with
    ``recovery_by_class``: ``recovery_rate`` of every class that spawned (0 for one with
    nothing in the complete cohort) and ``dropped_by_reason``."""
    minutes = counts.duration_s / 60.0
    values = _count_values(counts)
    return {
        "spawned": counts.spawned,
        "entered": counts.entered,
        "processed": counts.processed,
        "picked": counts.picked,
        "missed": counts.missed,
        "lost": counts.lost,
        "placed": counts.placed,
        "placed_correct": counts.placed_correct,
        "sorted": counts.sorted,
        "recovered": counts.recovered,
        "entered_takeable": counts.entered_takeable,
        "recovered_takeable": counts.recovered_takeable,
        "binned": counts.binned,
        "dropped": counts.dropped,
        "pick_success_rate": rate("pick_success_rate", values),
        "miss_rate": rate("miss_rate", values),
        "pick_throughput_per_min": ratio(counts.picked, minutes),
        "recovery_rate": rate("recovery_rate", values),
        "recovery_takeable": rate("recovery_takeable", values),
        "correct_bin_ratio": rate("correct_bin_ratio", values),
        "purity": rate("purity", values),
        "time_per_object_s": ratio(counts.duration_s, counts.picked),
        "unintended_contacts": counts.unintended_contacts,
        "duration_s": counts.duration_s,
        "recovery_by_class": {
            name: rate(
                "recovery_rate",
                {
                    "recovered": counts.recovered_by_class.get(name, 0),
                    "entered": counts.entered_by_class.get(name, 0),
                },
            )
            for name in sorted(counts.spawned_by_class)
        },
        "dropped_by_reason": dict(sorted(counts.dropped_by_reason.items())),
    }


def class_names(events: Iterable[Event]) -> list[str]:
    """The object classes the events name, sorted (events about no object left out)."""
    return sorted({e.class_name for e in events if e.class_name})


def class_scores(
    events: Sequence[Event],
    duration_s: float,
    *,
    station: str | None = None,
    line_exit: str | None = None,
) -> dict[str, dict[str, Any]]:
    """Per object class, the metrics of scope ``class`` (of the line, or of one station;
    ``line_exit`` as for :func:`count_events`)."""
    names = in_scope("class")
    out: dict[str, dict[str, Any]] = {}
    for class_name in class_names(events):
        counts = count_events(
            events, duration_s, station=station, class_name=class_name, line_exit=line_exit
        )
        scores = event_scores(counts)
        out[class_name] = {name: scores[name] for name in names}
    return out


def bin_scores(
    events: Iterable[Event], *, station: str | None = None
) -> dict[str, dict[str, dict[str, Any]]]:
    """Per station and bin (by the class it sorts), the metrics of scope ``bin``: ``binned``
    (objects of any class that came to rest in it), ``placed_correct`` (those of its class) and
    ``purity``; only bins something came to rest in, stations in order of first appearance
    (``""`` for events that name no station). With ``station``, that station's bins only."""
    binned: dict[str, dict[str, set[int]]] = {}
    correct: dict[str, dict[str, set[int]]] = {}
    for event in _selected(events, station, None):
        if event.type is not EventType.PLACED_IN_BIN:
            continue
        where, bin_name = station_of(event) or "", str(event.data.get("bin", ""))
        binned.setdefault(where, {}).setdefault(bin_name, set()).add(event.object_id)
        if event.data.get("correct"):
            correct.setdefault(where, {}).setdefault(bin_name, set()).add(event.object_id)
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for where, bins in binned.items():
        out[where] = {}
        for bin_name, objects in bins.items():
            values = {
                "binned": len(objects),
                "placed_correct": len(correct.get(where, {}).get(bin_name, ())),
            }
            out[where][bin_name] = {**values, "purity": rate("purity", values)}
    return out


def considered_objects(picks: Sequence[PickStats | None]) -> int:
    """Objects the controllers decided about, summed over instances: each one's ``targeted``
    (objects it committed to at least once) and ``untargeted`` (objects it never targeted, by
    reason); the two are disjoint."""
    return sum(p.targeted + sum(p.untargeted.values()) for p in picks if p is not None)


def untargeted_scores(untargeted: Mapping[str, int], considered: int) -> dict[str, Any]:
    """The allocation figures of one station from its controllers' ``untargeted`` counts (by
    reason, :func:`untargeted_objects`) and the objects they decided about
    (:func:`considered_objects`): ``untargeted_total``, ``considered``, ``untargeted_unfit``
    (:data:`UNFIT_REASONS`), ``unfit_share`` and ``untargeted_share`` (each reason's count /
    ``considered``)."""
    unfit = sum(int(untargeted.get(reason, 0)) for reason in UNFIT_REASONS)
    return {
        "untargeted_total": sum(int(v) for v in untargeted.values()),
        "considered": considered,
        "untargeted_unfit": unfit,
        "unfit_share": rate("unfit_share", {"untargeted_unfit": unfit, "considered": considered}),
        "untargeted_share": {
            reason: ratio(int(n), considered) for reason, n in sorted(untargeted.items())
        },
    }


def station_names(events: Iterable[Event]) -> list[str]:
    """The stations the events name, in order of first appearance."""
    seen: dict[str, None] = {}
    for event in events:
        station = station_of(event)
        if station is not None:
            seen.setdefault(station)
    return list(seen)


def targeted_objects(picks: Sequence[PickStats | None], landing: int) -> int:
    """Objects the controllers committed to and finished with (completed or aborted), summed
    over controller instances, less the ``landing`` objects still falling into a bin at the end
    (their fate is undecided)."""
    targeted = sum(p.completed + sum(p.aborted.values()) for p in picks if p is not None)
    return max(0, targeted - landing)


def untargeted_objects(picks: Sequence[PickStats | None]) -> dict[str, int]:
    """Objects never targeted, by the controllers' last reason, summed over instances."""
    out: dict[str, int] = {}
    for pick in picks:
        for key, value in (pick.untargeted if pick is not None else {}).items():
            out[key] = out.get(key, 0) + value
    return out


def landing_by_station(events: Iterable[Event], landing: Iterable[int]) -> dict[str, int]:
    """How many of the ``landing`` objects (still falling into a bin at the end) each station
    released: the station of each one's last ``pick_success``."""
    last_picker: dict[int, str] = {}
    for event in events:
        station = station_of(event)
        if event.type is EventType.PICK_SUCCESS and station is not None:
            last_picker[event.object_id] = station
    return _tally(last_picker[oid] for oid in landing if oid in last_picker)


def controller_scores(counts: Counts, targeted: int) -> dict[str, float]:
    """The metrics that need the controllers' ``targeted`` count."""
    minutes = counts.duration_s / 60.0
    return {
        "success_rate": rate("success_rate", {"sorted": counts.sorted, "targeted": targeted}),
        "throughput_per_min": ratio(counts.placed_correct, minutes),
    }


def fault_counts(events: Iterable[Event], *, station: str | None = None) -> dict[str, int]:
    """``faults`` (fault events other than injected ones) and ``injected_faults``; with
    ``station``, only the fault events that name it."""
    kinds = [
        str(e.data.get("kind", ""))
        for e in _selected(events, station, None)
        if e.type is EventType.FAULT
    ]
    injected = sum(1 for k in kinds if k.startswith("injected_"))
    return {"faults": len(kinds) - injected, "injected_faults": injected}


def tracking_summary(times_s: Sequence[float | None]) -> TrackingSummary:
    """The tracking block of an episode or a station from each pursuit's time to the threshold
    (None: it never settled): mean and 95th percentile of the settled ones, the unsettled
    counted apart, the times kept (to the microsecond) for the report's figures."""
    import numpy as np

    times = [t for t in times_s if t is not None]
    return TrackingSummary(
        pursuits=len(times_s),
        settled=len(times),
        unsettled=len(times_s) - len(times),
        tracking_time_4mm_mean_s=float(np.mean(times)) if times else None,
        tracking_time_4mm_p95_s=float(np.percentile(times, 95)) if times else None,
        tracking_times_s=tuple(round(t, 6) for t in times),
    )


def tracking_metrics(tracking: TrackingSummary | None) -> dict[str, MetricValue]:
    """The tracking metrics of a tracking block (None values without one)."""
    if tracking is None:
        return dict.fromkeys(
            (
                "tracking_time_4mm_mean_s",
                "tracking_time_4mm_p95_s",
                "tracking_pursuits",
                "tracking_unsettled",
            )
        )
    return {
        "tracking_time_4mm_mean_s": tracking.tracking_time_4mm_mean_s,
        "tracking_time_4mm_p95_s": tracking.tracking_time_4mm_p95_s,
        "tracking_pursuits": tracking.pursuits,
        "tracking_unsettled": tracking.unsettled,
    }


TRACKING_THRESHOLD_M = 0.004
"""The tracking-time metric's threshold: 4 mm from the TCP to the true grasp point."""


class SettleTimer:
    """Time from a pursuit's start until the distance stays below the threshold to its end.

    Fed one distance per sample, in time order; :attr:`settled_after_s` is None while the last
    sample is at or above the threshold (the pursuit has not settled, or left the threshold
    again). The twin measures its tracking time with it every physics step against ground
    truth, the controller's kinematic closed loop every control tick.
    """

    def __init__(self, start_s: float, threshold_m: float = TRACKING_THRESHOLD_M) -> None:
        self.start_s = start_s
        self.threshold_m = threshold_m
        self._below_since: float | None = None

    def update(self, time_s: float, distance_m: float) -> None:
        """One sample: the distance at ``time_s``."""
        if distance_m < self.threshold_m:
            if self._below_since is None:
                self._below_since = time_s
        else:
            self._below_since = None

    @property
    def settled_after_s(self) -> float | None:
        """Seconds from the start to the moment after which every sample stayed below."""
        return None if self._below_since is None else self._below_since - self.start_s
