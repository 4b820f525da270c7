"""Scores computed from events alone, as the environment (not the competitor) computes them.

Definitions (the reference's equations 1-3, made explicit):

- an object is *processed* once its fate is decided: picked (``pick_success``), missed (left the
  workspace downstream without being picked: ``missed``) or lost (``fell_off`` or
  ``pick_dropped`` without a later pick);
- (1) success rate = picked / processed;
- (2) miss rate = missed / processed;
- (3) throughput = picked objects per minute of simulated time;
- correct-bin ratio = objects placed in their class's bin / objects placed in any bin;
- time per object = simulated seconds per picked object.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from interfaces.events import Event, EventType


@dataclass(frozen=True)
class Scores:
    """Episode scores; rates are in [0, 1] and NaN-free (0 when nothing was processed)."""

    spawned: int
    processed: int
    picked: int
    missed: int
    lost: int
    placed: int
    placed_correct: int
    success_rate: float
    miss_rate: float
    throughput_per_min: float
    correct_bin_ratio: float
    time_per_object_s: float
    unintended_contacts: int
    duration_s: float


def compute_scores(events: Iterable[Event], duration_s: float) -> Scores:
    """Scores of an episode of ``duration_s`` simulated seconds from its events.

    Each object's fate is its last deciding event: ``pick_success`` makes it picked, a later
    ``pick_dropped`` or ``fell_off`` makes it lost (until picked again), ``missed`` makes it
    missed unless it is picked afterwards.
    """
    spawned: set[int] = set()
    fate: dict[int, str] = {}
    placed: set[int] = set()
    placed_correct: set[int] = set()
    unintended = 0
    for event in events:
        oid = event.object_id
        kind = event.type
        if kind is EventType.SPAWNED:
            spawned.add(oid)
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
                placed_correct.add(oid)
        elif kind is EventType.UNINTENDED_CONTACT:
            unintended += 1
    picked = sum(1 for f in fate.values() if f == "picked")
    missed = sum(1 for f in fate.values() if f == "missed")
    lost = sum(1 for f in fate.values() if f == "lost")
    processed = len(fate)
    minutes = duration_s / 60.0
    return Scores(
        spawned=len(spawned),
        processed=processed,
        picked=picked,
        missed=missed,
        lost=lost,
        placed=len(placed),
        placed_correct=len(placed_correct),
        success_rate=picked / processed if processed else 0.0,
        miss_rate=missed / processed if processed else 0.0,
        throughput_per_min=picked / minutes if minutes > 0 else 0.0,
        correct_bin_ratio=len(placed_correct) / len(placed) if placed else 0.0,
        time_per_object_s=duration_s / picked if picked else 0.0,
        unintended_contacts=unintended,
        duration_s=duration_s,
    )
