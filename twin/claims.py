"""The line's claims board: what each station's controller claims, checked, bounded, relayed.

A station's controller sends its claims on its own ``line/claim`` (``cdw_interfaces/Claim``);
the twin keeps one entry per station and track and relays the whole board on ``/line/claims``
(see ``docs/interfaces.md``, "Claims"). The twin trusts no client, so every field of a claim is
checked before it reaches the board (:meth:`ClaimsBoard.offer`), and a refused claim is a
:class:`Refusal` the node counts as a fault (``bad_claim``; ``claims_full`` when the board is
full):

- ``state``: one of ``claimed``, ``released``, ``picked``;
- ``station``: empty or the name of the station whose topic it came on: a claim is accepted
  only on its own station's namespace, and the board names the station whatever was written;
- ``class_name`` and ``header.frame_id``: at most :data:`MAX_TEXT_CHARS` printable characters;
  the frame ``world`` (or empty);
- ``header.stamp``: within the episode, ``[0, duration_s + 1]`` s;
- ``position``: finite and on or near the belt (within :attr:`ClaimLimits.margin_m` of its
  surface's rectangle, and of its height);
- ``velocity``: finite, at most :attr:`ClaimLimits.max_speed_mps` (the belt runs at 2 m/s at
  most);
- ``radius_m``: finite, in ``(0, max_radius_m]``.

The board is bounded: at most :attr:`ClaimLimits.max_per_station` entries of one station and
:attr:`ClaimLimits.max_total` in all; a claim that would add an entry beyond either is refused
(a claim replacing an entry its station already has is always taken), so a client flooding the
board costs the relay, and every controller reading it, a bounded amount of work.

Pure logic: no ROS. The node hands in the claim's fields (:class:`ClaimFields`) and an opaque
payload (the message it relays); :meth:`ClaimsBoard.take` gives the payloads to relay, ordered
by station then track, and drops the ``released`` and ``picked`` entries it relayed.

Example::

    board = ClaimsBoard(("upstream", "downstream"), cell.belt, duration_s=60.0)
    refusal = board.offer(0, fields, msg)
    if refusal is None and board.changed:
        relay(board.take())
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

from interfaces.cell import BeltSpec
from interfaces.contract import CLAIM_STATES
from interfaces.errors import cut

MAX_TEXT_CHARS = 64
"""Longest ``class_name`` or ``frame_id`` of a claim."""


@dataclass(frozen=True, kw_only=True)
class ClaimLimits:
    """The bounds a claim and the board keep (see the module's docstring)."""

    max_per_station: int = 32
    max_total: int = 256
    max_radius_m: float = 1.0
    max_speed_mps: float = 10.0
    margin_m: float = 1.0


@dataclass(frozen=True, kw_only=True)
class ClaimFields:
    """The fields of a ``Claim`` message as plain values (world frame, m, m/s, s)."""

    station: str
    track_id: int
    class_name: str
    frame_id: str
    stamp_s: float
    position_m: tuple[float, float, float]
    velocity_mps: tuple[float, float, float]
    radius_m: float
    state: str


@dataclass(frozen=True)
class Refusal:
    """Why a claim was refused: the fault ``reason`` (``bad_claim``, ``claims_full``) and a
    one-line ``detail`` naming the field and its (cut) value."""

    reason: str
    detail: str


def _bad(field: str, value: object, what: str) -> Refusal:
    return Refusal("bad_claim", f"{field} {cut(value, 80)} {what}")


def _finite(values: Sequence[float]) -> bool:
    return all(math.isfinite(v) for v in values)


def _text_ok(text: str) -> bool:
    return len(text) <= MAX_TEXT_CHARS and text.isprintable()


class ClaimsBoard:
    """The claims of every station of a line (one entry per station and track), each checked
    against the belt, the episode and the :class:`ClaimLimits` before it is taken."""

    def __init__(
        self,
        stations: Sequence[str],
        belt: BeltSpec,
        *,
        duration_s: float,
        limits: ClaimLimits | None = None,
    ) -> None:
        self.stations = tuple(stations)
        self.belt = belt
        self.duration_s = duration_s
        self.limits = limits or ClaimLimits()
        self._entries: dict[tuple[int, int], tuple[str, object]] = {}
        self._per_station: Counter[int] = Counter()
        self.changed = False
        """Whether the board changed since the last :meth:`take`."""

    def __len__(self) -> int:
        return len(self._entries)

    def check(self, station: int, claim: ClaimFields) -> Refusal | None:
        """Why ``claim``, received on station ``station``'s topic, is refused (None: it is
        fine). Checks every field; the board's bounds are :meth:`offer`'s."""
        own = self.stations[station]
        if claim.state not in CLAIM_STATES:
            return _bad("state", claim.state, f"is not one of {', '.join(CLAIM_STATES)}")
        if claim.station not in ("", own):
            return _bad(
                "station",
                claim.station,
                f"is not this topic's station {own!r}: a claim is taken only on its own "
                "station's namespace",
            )
        if not _text_ok(claim.class_name):
            what = f"is over {MAX_TEXT_CHARS} characters or not printable"
            return _bad("class_name", claim.class_name, what)
        if claim.frame_id not in ("", "world"):
            return _bad("header.frame_id", claim.frame_id, "is not 'world' (claims are in it)")
        if not (math.isfinite(claim.stamp_s) and 0.0 <= claim.stamp_s <= self.duration_s + 1.0):
            return _bad(
                "header.stamp",
                claim.stamp_s,
                f"s is outside the episode, [0, {self.duration_s:g}] s",
            )
        return self._check_motion(claim)

    def _check_motion(self, claim: ClaimFields) -> Refusal | None:
        limits, belt = self.limits, self.belt
        if not _finite(claim.position_m):
            return _bad("position", claim.position_m, "is not finite")
        x, y, z = claim.position_m
        margin = limits.margin_m
        on_belt = (
            belt.start_x_m - margin <= x <= belt.end_x_m + margin
            and abs(y - belt.centre_y_m) <= 0.5 * belt.width_m + margin
            and abs(z - belt.surface_z_m) <= margin
        )
        if not on_belt:
            return _bad("position", claim.position_m, f"is not within {margin:g} m of the belt")
        if not _finite(claim.velocity_mps):
            return _bad("velocity", claim.velocity_mps, "is not finite")
        if math.hypot(*claim.velocity_mps) > limits.max_speed_mps:
            what = f"is faster than {limits.max_speed_mps:g} m/s"
            return _bad("velocity", claim.velocity_mps, what)
        if not (math.isfinite(claim.radius_m) and 0.0 < claim.radius_m <= limits.max_radius_m):
            return _bad("radius_m", claim.radius_m, f"is not in (0, {limits.max_radius_m:g}] m")
        return None

    def offer(self, station: int, claim: ClaimFields, payload: object) -> Refusal | None:
        """Put ``claim`` (from station ``station``'s topic; ``payload`` is what is relayed for
        it) on the board, replacing that station's entry for the track; or say why not."""
        refusal = self.check(station, claim)
        if refusal is not None:
            return refusal
        key = (station, claim.track_id)
        if key not in self._entries:
            limits = self.limits
            if self._per_station[station] >= limits.max_per_station:
                return Refusal(
                    "claims_full",
                    f"station {self.stations[station]!r} has {limits.max_per_station} claims "
                    "on the board already (its limit): track "
                    f"{claim.track_id} refused",
                )
            if len(self._entries) >= limits.max_total:
                return Refusal(
                    "claims_full",
                    f"the board holds {limits.max_total} claims already (its limit): track "
                    f"{claim.track_id} of station {self.stations[station]!r} refused",
                )
            self._per_station[station] += 1
        self._entries[key] = (claim.state, payload)
        self.changed = True
        return None

    def take(self) -> list[object]:
        """The payloads of the whole board, ordered by station then track; the ``released``
        and ``picked`` entries are then dropped (relayed once), and :attr:`changed` reset."""
        out = [self._entries[key][1] for key in sorted(self._entries)]
        for key in [k for k, (state, _) in self._entries.items() if state != "claimed"]:
            del self._entries[key]
            self._per_station[key[0]] -= 1
        self.changed = False
        return out
