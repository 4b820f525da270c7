"""The pick sequence's phases: the one vocabulary of ``PickTarget.phase`` on both sides.

A station's controller runs its pick through these phases and announces the current one on
``controller/target`` (``cdw_interfaces/PickTarget.phase``, the enum's string value, see
``docs/interfaces.md``); the twin reads that string to measure the tracking time. The two sides
ask different questions of the same vocabulary, so two sets are defined here, side by side:

- :data:`PURSUIT_PHASES` (the controller): the phases that pursue a target, in which its
  predicted grasp point leads by the command latency; ``close`` is one (the TCP still follows
  the object while the gripper closes).
- :data:`TRACKED_PHASES` (the twin): the announced phases in which the twin measures a pursuit
  (:mod:`twin.target_metric`); ``close`` is not one, since the tracking time ends when the
  gripper starts closing, and :data:`TRACK` is (a client that follows an object without this
  pick sequence may announce it).
"""

from __future__ import annotations

from enum import StrEnum


class Phase(StrEnum):
    """Phases of the pick sequence (their values are ``PickTarget.phase`` on the wire)."""

    IDLE = "idle"
    APPROACH = "approach"
    DESCEND = "descend"
    DWELL = "dwell"
    CLOSE = "close"
    LIFT = "lift"
    CARRY = "carry"
    RELEASE = "release"
    RETURN = "return"


TRACK = "track"
"""A ``PickTarget.phase`` outside the pick sequence: a client following its target."""

FOLLOWING_PHASES = frozenset({Phase.DESCEND, Phase.DWELL, Phase.CLOSE})
"""Phases in which the TCP moves with the object and the feedback term is active."""

PURSUIT_PHASES = frozenset({Phase.APPROACH, *FOLLOWING_PHASES})
"""Phases that pursue a target: its predicted grasp point leads by ``command_latency_s``."""

TRACKED_PHASES: frozenset[str] = frozenset(
    {str(Phase.APPROACH), str(Phase.DESCEND), str(Phase.DWELL), TRACK}
)
"""``PickTarget.phase`` values in which the twin measures a pursuit (tracking time); any other
(``close`` first of all) ends it."""


__all__ = ["FOLLOWING_PHASES", "PURSUIT_PHASES", "TRACK", "TRACKED_PHASES", "Phase"]
