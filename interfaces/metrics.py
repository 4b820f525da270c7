"""The metric table: every score the benchmark reports, its unit and its formula, defined once.

The twin's ``summary.json`` scores, ``cdw-twin run``'s per-episode metrics, the sweep's
intervals, the offline recomputation from a recording and the report all compute from here;
``docs/metrics.md`` lists the table (a test keeps the two equal).

Counts come from the sorting events alone (:func:`count_events`), as the environment, not the
competitor, computes them; ``targeted`` comes from the controllers' statistics, the one figure
only the controller knows. An object's fate is its last deciding event: ``pick_success`` makes
it picked, a later ``pick_dropped`` or ``fell_off`` makes it lost (until it is picked again),
``missed`` makes it missed unless it is picked afterwards; *processed* objects are those with
a fate. For one station, the same rules apply to the events that station's ``detail`` names.

The reference's equations: (1) success rate = picked / processed, (2) miss rate = missed /
processed, (3) throughput = picked per minute. Every rate is 0 when its denominator is 0.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from interfaces.events import Event, EventType


@dataclass(frozen=True, kw_only=True)
class Metric:
    """One metric: ``name`` (the key in every table), unit, formula, what the reference calls
    it, and how it pools over episodes (``count``: summed; ``rate``: a ratio of two counts, also
    given as a Wilson interval over pooled counts; ``time``: averaged)."""

    name: str
    unit: str
    formula: str
    reference: str = ""
    kind: Literal["count", "rate", "time"]
    ratio_of: tuple[str, str] | None = None


METRICS: tuple[Metric, ...] = (
    Metric(name="spawned", unit="objects", formula="objects that entered the belt", kind="count"),
    Metric(
        name="processed",
        unit="objects",
        formula="objects whose fate is decided: picked + missed + lost",
        reference="processed objects (eq. 1, 2)",
        kind="count",
    ),
    Metric(name="picked", unit="objects", formula="objects whose fate is picked", kind="count"),
    Metric(
        name="missed",
        unit="objects",
        formula="objects that left the (last) pick window downstream unpicked",
        kind="count",
    ),
    Metric(
        name="lost",
        unit="objects",
        formula="objects dropped away from every bin or fallen off, not picked again",
        kind="count",
    ),
    Metric(
        name="placed", unit="objects", formula="objects that came to rest in a bin", kind="count"
    ),
    Metric(
        name="placed_correct",
        unit="objects",
        formula="objects that came to rest in their class's bin",
        kind="count",
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
        formula="objects a controller never targeted (by reason in untargeted)",
        kind="count",
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
    ),
    Metric(
        name="miss_rate",
        unit="1",
        formula="missed / processed",
        reference="eq. 2, miss rate",
        kind="rate",
        ratio_of=("missed", "processed"),
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
        formula="placed_correct / targeted",
        kind="rate",
        ratio_of=("placed_correct", "targeted"),
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
        formula="placed_correct / spawned",
        kind="rate",
        ratio_of=("placed_correct", "spawned"),
    ),
    Metric(
        name="correct_bin_ratio",
        unit="1",
        formula="placed_correct / placed",
        kind="rate",
        ratio_of=("placed_correct", "placed"),
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
        name="real_time_factor",
        unit="1",
        formula="simulated seconds / wall seconds of the twin's step loop",
        kind="time",
    ),
)
"""Every metric, in the order tables list them."""

BY_NAME: dict[str, Metric] = {m.name: m for m in METRICS}
"""The metric table by name."""


@dataclass(frozen=True, kw_only=True)
class Counts:
    """What the events of one episode (of one station, or of one class) add up to."""

    spawned: int = 0
    processed: int = 0
    picked: int = 0
    missed: int = 0
    lost: int = 0
    placed: int = 0
    placed_correct: int = 0
    unintended_contacts: int = 0
    duration_s: float = 0.0
    placed_correct_by_class: Mapping[str, int] = field(default_factory=dict)
    spawned_by_class: Mapping[str, int] = field(default_factory=dict)


def _station_of(event: Event) -> str | None:
    station = event.data.get("station")
    return None if station is None else str(station)


def count_events(
    events: Iterable[Event], duration_s: float, *, station: str | None = None
) -> Counts:
    """The counts of an episode of ``duration_s`` simulated seconds from its events.

    With ``station``, only events that name that station count, and ``spawned`` is the number
    of objects that entered its pick window.
    """
    spawned: dict[int, str] = {}
    fate: dict[int, str] = {}
    placed: set[int] = set()
    placed_correct: dict[int, str] = {}
    unintended = 0
    for event in events:
        if station is not None and _station_of(event) != station:
            continue
        oid, kind = event.object_id, event.type
        if kind is EventType.SPAWNED and station is None:
            spawned[oid] = event.class_name
        elif kind is EventType.ENTERED_WORKSPACE and station is not None:
            spawned.setdefault(oid, event.class_name)
        elif kind is EventType.PICK_SUCCESS:
            fate[oid] = "picked"
        elif kind is EventType.MISSED:
            fate.setdefault(oid, "missed")
        elif kind in (EventType.FELL_OFF, EventType.PICK_DROPPED):
            if fate.get(oid) != "missed":
                fate[oid] = "lost"
        elif kind is EventType.PLACED_IN_BIN:
            placed.add(oid)
            if event.data.get("correct"):
                placed_correct[oid] = event.class_name
        elif kind is EventType.UNINTENDED_CONTACT:
            unintended += 1
    outcomes = list(fate.values())
    return Counts(
        spawned=len(spawned),
        processed=len(fate),
        picked=outcomes.count("picked"),
        missed=outcomes.count("missed"),
        lost=outcomes.count("lost"),
        placed=len(placed),
        placed_correct=len(placed_correct),
        unintended_contacts=unintended,
        duration_s=duration_s,
        placed_correct_by_class=_tally(placed_correct.values()),
        spawned_by_class=_tally(spawned.values()),
    )


def _tally(names: Iterable[str]) -> dict[str, int]:
    out: dict[str, int] = {}
    for name in names:
        out[name] = out.get(name, 0) + 1
    return out


def ratio(numerator: float, denominator: float) -> float:
    """``numerator / denominator``, 0 when the denominator is 0 (the table's convention)."""
    return numerator / denominator if denominator else 0.0


def event_scores(counts: Counts) -> dict[str, Any]:
    """The metrics the events alone give (the twin's ``summary.json`` ``scores``)."""
    minutes = counts.duration_s / 60.0
    return {
        "spawned": counts.spawned,
        "processed": counts.processed,
        "picked": counts.picked,
        "missed": counts.missed,
        "lost": counts.lost,
        "placed": counts.placed,
        "placed_correct": counts.placed_correct,
        "pick_success_rate": ratio(counts.picked, counts.processed),
        "miss_rate": ratio(counts.missed, counts.processed),
        "pick_throughput_per_min": ratio(counts.picked, minutes),
        "recovery_rate": ratio(counts.placed_correct, counts.spawned),
        "correct_bin_ratio": ratio(counts.placed_correct, counts.placed),
        "time_per_object_s": ratio(counts.duration_s, counts.picked),
        "unintended_contacts": counts.unintended_contacts,
        "duration_s": counts.duration_s,
        "recovery_by_class": {
            name: ratio(counts.placed_correct_by_class.get(name, 0), n)
            for name, n in sorted(counts.spawned_by_class.items())
        },
    }


def targeted_objects(controller_stats: Sequence[Mapping[str, Any]], landing: int) -> int:
    """Objects the controllers committed to and finished with (completed or aborted), summed
    over controller instances, less the ``landing`` objects still falling into a bin at the end
    (their fate is undecided)."""
    targeted = 0
    for ctl in controller_stats:
        pick = ctl.get("pick") or {}
        targeted += int(pick.get("completed", 0))
        targeted += sum(int(v) for v in (pick.get("aborted") or {}).values())
    return max(0, targeted - landing)


def untargeted_objects(controller_stats: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    """Objects never targeted, by the controllers' last reason, summed over instances."""
    out: dict[str, int] = {}
    for ctl in controller_stats:
        pick = ctl.get("pick") or {}
        for key, value in (pick.get("untargeted") or {}).items():
            out[str(key)] = out.get(str(key), 0) + int(value)
    return out


def controller_scores(counts: Counts, targeted: int) -> dict[str, float]:
    """The metrics that need the controllers' ``targeted`` count."""
    minutes = counts.duration_s / 60.0
    return {
        "success_rate": ratio(counts.placed_correct, targeted),
        "throughput_per_min": ratio(counts.placed_correct, minutes),
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
