"""How the stations of a line share one stream of objects (pure logic, no ROS).

Every station's controller publishes its claims (:class:`Claim`): ``claimed`` when it commits
to a target, ``released`` when it gives it up, ``picked`` once it holds it. The cell relays the
board of every station's current claims to every controller (in lockstep with the tick, so the
same seed gives the same allocation). Each controller reads the whole cell, so it knows the
other stations, their windows, tools and bins (:class:`StationView`), and decides for itself
which objects it may target: its :class:`Allocator` applies the boards and, through the
strategy chosen in the parameter file (``allocation.strategy``, one of :data:`STRATEGIES`),
gives the reason a track must be left to another station, or None:

- ``first_fit`` (default): an object another station has claimed (its track within the claim's
  radius of the claimed position, predicted to the track's time) or picked is
  ``claimed_by_other``; anything else the tool can pick may be targeted, so upstream stations
  take what they can and downstream ones what is left;
- ``class_priority``: also, an object of a class this station does not prefer is
  ``left_for_downstream`` when a station downstream prefers its class and can pick it;
- ``tool_fit``: also, an object is ``left_for_downstream`` when a station downstream can pick
  it with ``allocation.fit_advantage_m`` more room on its tightest dimension
  (:meth:`~control.tools.ControllerTool.fit_margin_m`): a flat tile for a suction cup, a
  narrow stick for a gripper.

Conflicts: two stations may claim the same object before either has seen the other's claim.
The station whose window lies further upstream keeps it (then the one earlier in the cell); the
other gives it up (:meth:`Allocator.must_yield`) unless its tool already acts on the object.
Other stations' fit is judged with this station's ``scheduler.grasp_width_margin_m``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

from control.config import ControllerConfig
from control.tools import ControllerTool, make_tool
from control.tracking import Track

ClaimState = Literal["claimed", "released", "picked"]  # interfaces.contract.CLAIM_STATES

PICKED_MEMORY_S = 1.0
"""How long (s) an object another station picked stays taken here: its track coasts on after
the object left the belt (detections stop) until the tracker drops it."""


@dataclass(frozen=True, kw_only=True)
class Claim:
    """A station's claim on an object: the object's footprint centroid ``position_m`` ``(x, y)``
    at ``stamp_s`` moving with ``velocity_mps``; a track within ``radius_m`` of it (predicted to
    the same time) is the same object."""

    station: str
    track_id: int
    class_name: str
    stamp_s: float
    position_m: tuple[float, float]
    velocity_mps: tuple[float, float]
    radius_m: float
    state: ClaimState = "claimed"

    def position_at(self, t_s: float) -> tuple[float, float]:
        """The claimed object's predicted position at ``t_s``."""
        dt_s = t_s - self.stamp_s
        return (
            self.position_m[0] + self.velocity_mps[0] * dt_s,
            self.position_m[1] + self.velocity_mps[1] * dt_s,
        )

    def covers(self, track: Track) -> bool:
        """Whether ``track`` is the claimed object."""
        x, y = self.position_at(track.stamp_s)
        return math.hypot(track.position_m[0] - x, track.position_m[1] - y) <= self.radius_m


def claim_of(
    station: str, track: Track, t_s: float, state: ClaimState, min_radius_m: float
) -> Claim:
    """``station``'s claim of ``state`` on ``track`` at ``t_s``: radius half the object's
    narrow side, at least ``min_radius_m``."""
    return Claim(
        station=station,
        track_id=track.track_id,
        class_name=track.class_name,
        stamp_s=t_s,
        position_m=track.position_at(t_s),
        velocity_mps=track.velocity_mps,
        radius_m=max(0.5 * min(track.width_m, track.length_m), min_radius_m),
        state=state,
    )


@dataclass(frozen=True, kw_only=True)
class StationView:
    """What a controller knows of a station of its line: ``order`` along the belt (0 the most
    upstream), pick window, tool, the classes it has bins for and those it prefers."""

    name: str
    order: int
    window_x_m: tuple[float, float]
    tool: ControllerTool
    classes: frozenset[str]
    preferred: frozenset[str]

    def fit_margin_m(self, track: Track, width_margin_m: float) -> float:
        """The tool's room on the track's tightest dimension (negative: it does not fit)."""
        return self.tool.fit_margin_m(
            length_m=track.length_m,
            width_m=track.width_m,
            height_m=track.height_m,
            width_margin_m=width_margin_m,
            face_radius_m=track.suction_radius_m,
        )

    def can_take(self, track: Track, width_margin_m: float) -> bool:
        """Whether the station has a bin for the track's class and its tool fits the object."""
        misfit = self.tool.misfit(
            length_m=track.length_m,
            width_m=track.width_m,
            height_m=track.height_m,
            width_margin_m=width_margin_m,
            face_radius_m=track.suction_radius_m,
            face_tilt_rad=track.suction_tilt_rad,
        )
        return track.class_name in self.classes and misfit is None


def line_of(config: ControllerConfig) -> tuple[StationView, ...]:
    """Every station of the cell as this controller sees it, in the cell's order.

    Preferred classes: ``allocation.preferred_classes`` for a station named there, else the
    classes only that station has bins for.
    """
    stations = config.cell.stations
    ranked = sorted(range(len(stations)), key=lambda i: (stations[i].pick_window_x_m[0], i))
    order = {index: rank for rank, index in enumerate(ranked)}
    binned = [frozenset(b.class_name for b in s.bins) for s in stations]
    views = []
    for i, spec in enumerate(stations):
        others = set().union(*(b for j, b in enumerate(binned) if j != i))
        listed = config.allocation.preferred_classes.get(spec.name)
        preferred = frozenset(listed) if listed is not None else binned[i] - others
        views.append(
            StationView(
                name=spec.name,
                order=order[i],
                window_x_m=spec.pick_window_x_m,
                tool=make_tool(spec.tool, config.cell.materials),
                classes=binned[i],
                preferred=preferred,
            )
        )
    return tuple(views)


@dataclass(frozen=True, kw_only=True)
class Context:
    """What a strategy decides with: this station, the line, the live claims of the others,
    the objects they picked, and the margins of the parameter file."""

    me: StationView
    downstream: tuple[StationView, ...]
    claims: tuple[Claim, ...]
    picked: tuple[Claim, ...]
    width_margin_m: float
    fit_advantage_m: float

    def claimed(self, track: Track) -> bool:
        """Whether another station claimed or picked the track's object."""
        return any(c.covers(track) for c in self.claims) or any(
            c.covers(track) for c in self.picked
        )


Strategy = Callable[[Context, Track], str | None]
"""A strategy: the reason this station leaves ``track`` to another, or None."""


def first_fit(context: Context, track: Track) -> str | None:
    """Leave what another station claimed; take anything else."""
    return "claimed_by_other" if context.claimed(track) else None


def class_priority(context: Context, track: Track) -> str | None:
    """:func:`first_fit`, and leave an object of a class this station does not prefer to a
    downstream station that prefers it and can pick it."""
    reason = first_fit(context, track)
    if reason is not None or track.class_name in context.me.preferred:
        return reason
    for other in context.downstream:
        if track.class_name in other.preferred and other.can_take(track, context.width_margin_m):
            return "left_for_downstream"
    return None


def tool_fit(context: Context, track: Track) -> str | None:
    """:func:`first_fit`, and leave an object to a downstream station whose tool fits it by
    ``fit_advantage_m`` more."""
    reason = first_fit(context, track)
    if reason is not None:
        return reason
    margin = context.width_margin_m
    mine = context.me.fit_margin_m(track, margin)
    for other in context.downstream:
        if other.can_take(track, margin) and (
            other.fit_margin_m(track, margin) >= mine + context.fit_advantage_m
        ):
            return "left_for_downstream"
    return None


STRATEGIES: dict[str, Strategy] = {
    "first_fit": first_fit,
    "class_priority": class_priority,
    "tool_fit": tool_fit,
}
"""The allocation strategies by their name in ``allocation.strategy``."""


class Allocator:
    """One station's allocation: the line, the strategy, and the board as last relayed."""

    def __init__(self, config: ControllerConfig) -> None:
        """The station ``config`` drives, in its cell's line, with its allocation section."""
        self._cfg = config
        line = line_of(config)
        self._by_name = {view.name: view for view in line}
        self.me = self._by_name[config.station.name]
        """This station."""
        self._downstream = tuple(
            sorted((v for v in line if v.order > self.me.order), key=lambda v: v.order)
        )
        self._strategy = STRATEGIES[config.allocation.strategy]
        self._claims: tuple[Claim, ...] = ()
        self._picked: list[Claim] = []

    def apply_board(self, claims: Sequence[Claim]) -> None:
        """Take a relayed board: the other stations' live claims replace the previous ones;
        their ``picked`` claims are remembered for :data:`PICKED_MEMORY_S`, a ``released``
        one forgets the same station's picked claim of that track. Claims of stations not in
        the cell are ignored."""
        mine = self.me.name
        others = [c for c in claims if c.station != mine and c.station in self._by_name]
        self._claims = tuple(c for c in others if c.state == "claimed")
        for claim in others:
            if claim.state == "picked":
                self._picked.append(claim)
            elif claim.state == "released":
                self._picked = [
                    p
                    for p in self._picked
                    if (p.station, p.track_id) != (claim.station, claim.track_id)
                ]

    def _live(self, now_s: float) -> tuple[tuple[Claim, ...], tuple[Claim, ...]]:
        """The claims that still stand at ``now_s``: not past the claiming station's window by
        more than ``claim_expiry_m``; picked ones for :data:`PICKED_MEMORY_S`."""
        self._picked = [p for p in self._picked if now_s - p.stamp_s <= PICKED_MEMORY_S]
        expiry = self._cfg.allocation.claim_expiry_m
        live = tuple(
            c
            for c in self._claims
            if c.position_at(now_s)[0] <= self._by_name[c.station].window_x_m[1] + expiry
        )
        return live, tuple(self._picked)

    def context(self, now_s: float) -> Context:
        """The strategy's view at ``now_s``."""
        claims, picked = self._live(now_s)
        return Context(
            me=self.me,
            downstream=self._downstream,
            claims=claims,
            picked=picked,
            width_margin_m=self._cfg.scheduler.grasp_width_margin_m,
            fit_advantage_m=self._cfg.allocation.fit_advantage_m,
        )

    def reason(self, track: Track, now_s: float) -> str | None:
        """Why this station must leave ``track`` to another at ``now_s``, or None."""
        return self._strategy(self.context(now_s), track)

    def chooser(self, now_s: float) -> Callable[[Track], str | None]:
        """:meth:`reason` for every track of one scheduling decision at ``now_s``."""
        context = self.context(now_s)
        return lambda track: self._strategy(context, track)

    def must_yield(self, track: Track, now_s: float) -> bool:
        """Whether a station further upstream (or as far, earlier in the cell) claims the
        object of ``track``, this station's target: it keeps it, this station gives it up."""
        claims, _ = self._live(now_s)
        me = self.me.order
        return any(self._by_name[c.station].order < me and c.covers(track) for c in claims)
