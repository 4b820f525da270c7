"""The tracks a controller tick hands on, extrapolated to the tick only when something reads
them (:class:`PredictedTracks`)."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import overload

from control.tracking import Track, Tracker

__all__ = ["PredictedTracks"]


class PredictedTracks(Sequence[Track]):
    """:meth:`Tracker.predict_to` of ``tracker`` at ``t_s``, computed the first time it is read.

    A controller tick hands its tracks on to the pick logic and the target message, which most
    ticks do not read (an idle station looks for a target at ``scheduler.replan_period_s``, not
    at every tick; the target message is sent when it changes): extrapolating and copying every
    track each tick was a few percent of a line episode. The tracker must not be updated before
    the first read (a tick reads its tracks within the tick)."""

    __slots__ = ("_t_s", "_tracker", "_tracks")

    def __init__(self, tracker: Tracker, t_s: float) -> None:
        self._tracker = tracker
        self._t_s = t_s
        self._tracks: tuple[Track, ...] | None = None

    def _all(self) -> tuple[Track, ...]:
        if self._tracks is None:
            self._tracks = self._tracker.predict_to(self._t_s)
        return self._tracks

    @overload
    def __getitem__(self, index: int) -> Track: ...
    @overload
    def __getitem__(self, index: slice) -> Sequence[Track]: ...
    def __getitem__(self, index: int | slice) -> Track | Sequence[Track]:
        return self._all()[index]

    def __len__(self) -> int:
        return len(self._all())

    def __iter__(self) -> Iterator[Track]:
        return iter(self._all())
