"""Why a station's controller left an object untargeted: the one list of reasons.

The controller's scheduler (:mod:`control.scheduler`) gives one of these for every object it did
not choose; the controller counts them (``PickStats.untargeted``, each controller's stats file),
and the metric table (:mod:`interfaces.metrics`) and ``docs/metrics.md`` read them by name.
"""

from __future__ import annotations

STATIC_REASONS: tuple[str, ...] = (
    "no_bin",
    "too_wide",
    "too_flat",
    "too_small",
    "too_tilted",
    "too_heavy",
)
"""The reasons a station refuses a piece whatever the timing, clutter or other stations
(:func:`control.scheduler.static_reason`), in the order they are checked."""

UNFIT_REASONS: tuple[str, ...] = ("too_wide", "too_flat", "too_small", "too_tilted")
"""The static reasons that say the station's tool does not fit the piece (``untargeted_unfit``
of the metric table)."""

UNTARGETED_REASONS: tuple[str, ...] = (
    "low_confidence",
    *STATIC_REASONS,
    "excluded",
    "unsettled",
    "claimed_by_other",
    "left_for_downstream",
    "too_late",
    "upstream",
    "out_of_reach",
    "blocked",
    "lower_priority",
)
"""Every reason an object can be left untargeted, in the order the scheduler checks them."""


__all__ = ["STATIC_REASONS", "UNFIT_REASONS", "UNTARGETED_REASONS"]
