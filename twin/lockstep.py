"""The lockstep protocol's bookkeeping, one station at a time: pure logic, free of ROS.

In lockstep the twin steps tick k+1 only when every station's controller has acknowledged tick k
(``StepAck``: the tick it handled, how many commands it sent for it, its next control tick) and
all the commands that acknowledgement announces have arrived (see the LockstepTick/StepAck
handshake in ``docs/interfaces.md``). :class:`AckBook` keeps one station's side of it: the
commands received and not yet consumed, the acknowledgements ahead of the twin, whether the
station's controller is alive, and when it was lost; it decides whether a tick is ready, how long
the twin waits for it, and what a wait that ended means (:class:`Settled`). The node
(:mod:`twin.ros_node`) feeds it the messages and the step loop (:mod:`twin.step_loop`) acts on
its decisions: the wall clock and the callbacks stay out of here.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from interfaces import cdr
from interfaces.contract import COUNTED

MAX_ACKS_AHEAD = 10_000
"""Farthest ahead of the current tick an acknowledgement is kept (a controller acknowledges the
tick it handled); beyond, it is refused (``bad_ack``)."""

RESYNC_WAIT_S = 10.0
"""Longest wait (wall s) for a lost controller that acknowledges again (a restarted one) to
catch up before it is counted in step again."""


@dataclass(frozen=True, kw_only=True)
class Settled:
    """What a wait for one station's acknowledgement of a tick came to.

    ``ready``: the ack and all its commands arrived; ``resumed_after_s``: sim seconds the
    station's controller had been lost, when it is back in step with this tick (else None);
    ``timed_out``: a live controller did not answer in time (it is lost from now on).
    """

    ready: bool
    resumed_after_s: float | None = None
    timed_out: bool = False


@dataclass
class AckBook:
    """One station's lockstep bookkeeping.

    ``pending`` counts commands received and not yet consumed by an acknowledged tick; ``acks``
    maps each acknowledged tick not yet consumed to the commands its ack announces;
    ``next_tick`` is the controller's next control tick (no command comes for the ticks before
    it, so they are not waited for); ``alive``, ``acks_at_loss`` and ``lost_at_s`` (sim s)
    follow the controller's losses.
    """

    pending: int = 0
    acks: dict[int, int] = field(default_factory=dict)
    last_ack_tick: int = -1
    next_tick: int = 0
    alive: bool = True
    acks_at_loss: int = -1
    lost_at_s: float | None = None

    def command_received(self) -> None:
        """A command of this station arrived (whether or not it was valid: its controller
        counted it in its ack)."""
        self.pending += 1

    def take_ack(self, tick: int, n_commands: int, next_tick: int, *, current_tick: int) -> str:
        """Record an acknowledgement; ``""`` when it was taken, else why it was refused (too
        far ahead of ``current_tick``, or too many kept: :data:`MAX_ACKS_AHEAD`)."""
        if tick > current_tick + MAX_ACKS_AHEAD or len(self.acks) > MAX_ACKS_AHEAD:
            return f"tick {tick} while the twin is at tick {current_tick}"
        self.acks[tick] = n_commands
        self.last_ack_tick = max(self.last_ack_tick, tick)
        self.next_tick = max(self.next_tick, next_tick)
        return ""

    def tick_ready(self, tick: int) -> bool:
        """The ack of ``tick`` and all the commands it announces have arrived."""
        n = self.acks.get(tick)
        return n is not None and self.pending >= n

    def consume_tick(self, tick: int) -> None:
        """The commands of ``tick`` are applied; forget it and older acks.

        The pending count never goes below zero: a command lost at a controller's start must
        not make every later tick wait for one more command than it announces.
        """
        self.pending = max(self.pending - self.acks.pop(tick, 0), 0)
        for old in [t for t in self.acks if t < tick]:
            del self.acks[old]

    def start(self, *, matched: bool) -> bool:
        """At the first step: the station is alive when its controller has matched; returns
        whether it is lost from the start (then lost since sim time 0)."""
        self.alive = matched
        if not matched:
            self.lost_at_s = 0.0
        return not matched

    def patience_s(
        self, tick: int, *, ack_timeout_s: float, start_timeout_s: float
    ) -> float | None:
        """How long (wall s) tick ``tick`` waits for this station, or None when it does not:
        a live controller whose last ack announced a later control tick, or a lost one that
        has not acknowledged since (a lost one acknowledging again is waited for up to
        :data:`RESYNC_WAIT_S`; the first tick up to ``start_timeout_s``)."""
        resync = not self.alive and self.last_ack_tick > self.acks_at_loss
        if self.alive and tick < self.next_tick:
            return None
        if not (self.alive or resync):
            return None
        if tick == 0:
            return start_timeout_s
        return RESYNC_WAIT_S if resync else ack_timeout_s

    def settle(self, tick: int, *, time_s: float) -> Settled:
        """After the wait for ``tick`` (sim time ``time_s``): the controller resumed, was lost
        or is still in step; the tick is consumed either way.

        A controller that missed the tick is not alive; every command received so far counts
        as applied (a restarted controller's acks count only its own commands).
        """
        ready = self.tick_ready(tick)
        resumed_after_s = None
        timed_out = False
        if ready and self.lost_at_s is not None:
            resumed_after_s = time_s - self.lost_at_s
            self.lost_at_s = None
        if not ready and self.alive:
            timed_out = True
            self.lost_at_s = time_s
        if not ready:
            self.acks_at_loss = self.last_ack_tick
            self.pending = 0
        self.alive = ready
        self.consume_tick(tick)
        return Settled(ready=ready, resumed_after_s=resumed_after_s, timed_out=timed_out)


class TickCounter:
    """The counted topics' messages published since the last tick, and the newest stamp of
    each ever published: what ``LockstepTick`` announces, so that a controller knows what it
    must have received before it handles the tick (the counted topics: ``COUNTED`` of
    :mod:`interfaces.contract`, by contract name)."""

    def __init__(self) -> None:
        self.counts: Counter[str] = Counter()
        self.last_stamp_ns: dict[str, int] = {}

    def count(self, name: str, stamp_ns: int) -> None:
        """One message of the counted topic ``name`` (contract name), stamped ``stamp_ns``."""
        self.counts[name] += 1
        self.last_stamp_ns[name] = max(self.last_stamp_ns.get(name, -1), stamp_ns)

    def take(self, tick: int, sec: int, nanosec: int) -> cdr.TickValues:
        """The tick's values (stamped ``sec``, ``nanosec``); the counts start again from zero."""
        counts, last = self.counts, self.last_stamp_ns
        joints, belt, detections, claims = (t.name for t in COUNTED)
        self.counts = Counter()
        return cdr.TickValues(
            tick=tick,
            sec=sec,
            nanosec=nanosec,
            n_joint_states=counts[joints],
            n_belt_states=counts[belt],
            n_detections=counts[detections],
            n_claims=counts[claims],
            last_joint_state_ns=last.get(joints, -1),
            last_belt_state_ns=last.get(belt, -1),
            last_detections_ns=last.get(detections, -1),
            last_claims_ns=last.get(claims, -1),
        )


__all__ = ["MAX_ACKS_AHEAD", "RESYNC_WAIT_S", "AckBook", "Settled", "TickCounter"]
