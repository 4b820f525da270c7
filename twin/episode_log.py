"""The episode log a twin run leaves behind: events, scores, counters, tracking results.

Files (each written atomically, so a file that exists is complete):
``events.jsonl`` (one event per line), ``summary.json`` (scores, tracking, counters, timing).
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from twin.events import Event
from twin.fileio import write_atomic
from twin.target_metric import TrackingResult


def tracking_summary(results: Iterable[TrackingResult]) -> dict[str, Any]:
    """Mean and 95th percentile of the settled pursuits; unsettled ones counted apart."""
    results = list(results)
    times = [r.time_to_threshold_s for r in results if r.time_to_threshold_s is not None]
    return {
        "pursuits": len(results),
        "settled": len(times),
        "unsettled": len(results) - len(times),
        "tracking_time_4mm_mean_s": float(np.mean(times)) if times else None,
        "tracking_time_4mm_p95_s": float(np.percentile(times, 95)) if times else None,
        "tracking_times_s": [round(t, 6) for t in times],
    }


def write_episode(out: Path, events: Iterable[Event], summary: dict[str, Any]) -> None:
    """Write ``events.jsonl`` and ``summary.json`` into ``out``."""
    write_atomic(out / "events.jsonl", "".join(e.to_json() + "\n" for e in events))
    write_atomic(out / "summary.json", json.dumps(summary, indent=2, sort_keys=True) + "\n")
