"""Sorting events: what happened to which object, and when (simulation time).

The twin emits these from its step loop; scores are computed from them alone
(:mod:`interfaces.metrics`), so an event log is enough to recompute every metric offline.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any


class EventType(StrEnum):
    """Every kind of event the twin reports (each with its ``data`` keys and when it fires:
    ``docs/interfaces.md``, section Events)."""

    SPAWNED = "spawned"
    ENTERED_WORKSPACE = "entered_workspace"
    LEFT_WORKSPACE = "left_workspace"
    FINGER_CONTACT = "finger_contact"
    TCP_OVERLAP_START = "tcp_overlap_start"
    TCP_OVERLAP_END = "tcp_overlap_end"
    PICK_SUCCESS = "pick_success"
    PICK_DROPPED = "pick_dropped"
    PLACED_IN_BIN = "placed_in_bin"
    FELL_OFF = "fell_off"
    UNINTENDED_CONTACT = "unintended_contact"
    MISSED = "missed"
    FAULT = "fault"
    CONTROLLER_RESUMED = "controller_resumed"


@dataclass(frozen=True)
class Event:
    """One event. ``object_id`` is the twin's integer id (0 for events about no object)."""

    time_s: float
    step: int
    type: EventType
    object_id: int
    class_name: str = ""
    data: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> str:
        """One JSON line (the event log format)."""
        return json.dumps(
            {
                "time_s": self.time_s,
                "step": self.step,
                "type": str(self.type),
                "object_id": self.object_id,
                "class_name": self.class_name,
                "data": self.data,
            },
            sort_keys=True,
        )

    @classmethod
    def from_json(cls, line: str) -> Event:
        """Parse one line written by :meth:`to_json`."""
        raw = json.loads(line)
        return cls(
            time_s=float(raw["time_s"]),
            step=int(raw["step"]),
            type=EventType(raw["type"]),
            object_id=int(raw["object_id"]),
            class_name=str(raw.get("class_name", "")),
            data=dict(raw.get("data", {})),
        )
