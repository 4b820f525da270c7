"""The twin's step loop: physics steps paced by the wall clock or by the controllers' acks.

Free of ROS: it drives any endpoint with the surface of :class:`SteppedEndpoint` (the ROS node
and the in-process endpoint of :mod:`twin.ros_node`) and serves its callbacks through a
``spin_once(timeout_sec=...)`` (an rclpy executor's, or :meth:`interfaces.inproc.Bus.spin_once`).
What lockstep decides per station (ready, patience, lost, resumed) is
:class:`twin.lockstep.AckBook`'s; this module keeps the time.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol, TypeVar

from twin.lockstep import AckBook
from twin.sim import Twin


class SteppedLink(Protocol):
    """One station's side of an endpoint, as the loop sees it."""

    @property
    def name(self) -> str:
        """The station's name."""
        ...

    @property
    def book(self) -> AckBook:
        """The station's lockstep bookkeeping."""
        ...


LinkT = TypeVar("LinkT", bound=SteppedLink)
"""An endpoint's own type of station link."""


class SteppedEndpoint(Protocol[LinkT]):
    """What the loop needs of the twin's endpoint (its links of type ``LinkT``)."""

    @property
    def twin(self) -> Twin:
        """The twin it publishes."""
        ...

    @property
    def lockstep(self) -> bool:
        """Whether the controllers' acks pace the steps."""
        ...

    @property
    def links(self) -> Sequence[LinkT]:
        """Every station's side, in the cell's order."""
        ...

    def peers_matched(self) -> bool:
        """Whether every station's controller is there and has matched."""
        ...

    def link_matched(self, link: LinkT, /) -> bool:
        """Whether one station's controller is there and has matched."""
        ...

    def publish_step(self) -> None:
        """Publish everything due after a physics step."""
        ...

    def publish_new_events(self) -> None:
        """Publish every event logged since the last call."""
        ...

    def count_lockstep_timeout(self) -> None:
        """Count a controller that missed its tick."""
        ...


SpinOnce = Callable[..., None]
"""Serves callbacks for at most ``timeout_sec`` seconds (an executor's ``spin_once``)."""


def run_loop(
    node: SteppedEndpoint[Any],
    executor: object,
    *,
    realtime_factor: float = 1.0,
    ack_timeout_s: float = 2.0,
    start_timeout_s: float = 60.0,
    on_first_step: Callable[[], None] | None = None,
) -> None:
    """Step the twin until its scenario's duration, serving callbacks between steps;
    ``on_first_step`` is called as the first step's messages go out (in lockstep, once the
    controllers have matched). ``executor`` has a ``spin_once(timeout_sec=...)``."""
    spin_once: SpinOnce = executor.spin_once  # type: ignore[attr-defined]
    gc.collect()
    gc.freeze()  # everything built so far is long-lived: keep the collector off it
    try:
        _step_until_done(
            node, spin_once, realtime_factor, ack_timeout_s, start_timeout_s, on_first_step
        )
    finally:
        # back to the collector: a caller that runs episodes in its own process (in-process runs,
        # tests) must get the twin, its robots and their Ruckig objects freed once it lets go
        gc.unfreeze()


def _step_until_done(
    node: SteppedEndpoint[Any],
    spin_once: SpinOnce,
    realtime_factor: float,
    ack_timeout_s: float,
    start_timeout_s: float,
    on_first_step: Callable[[], None] | None,
) -> None:
    twin = node.twin
    duration = twin.scenario.duration_s
    if node.lockstep:
        Lockstep(node, spin_once, ack_timeout_s, start_timeout_s).run(duration, on_first_step)
        return
    if on_first_step is not None:
        on_first_step()
    node.publish_step()
    period = twin.dt_s / realtime_factor
    next_wall = time.perf_counter()
    while twin.time_s < duration - 1e-9:
        spin_once(timeout_sec=0.0)
        serve_until(spin_once, next_wall)
        twin.advance()
        spin_once(timeout_sec=0.0)
        node.publish_step()
        next_wall += period
        if next_wall < time.perf_counter() - 0.25:
            next_wall = time.perf_counter()


def serve_until(spin_once: SpinOnce, wall_s: float) -> None:
    """Serve callbacks until the ``time.perf_counter()`` time ``wall_s``."""
    while (remaining := wall_s - time.perf_counter()) > 0:
        spin_once(timeout_sec=remaining)


class Lockstep:
    """Step tick k+1 once every station's controller has acknowledged tick k with all its
    commands; a tick before the next control tick a controller's last ack announced
    (``StepAck.next_tick``) is not waited for: no command of it can come.

    A station's controller that does not answer within ``ack_timeout_s`` is lost: a
    ``controller_timeout`` fault naming the station is logged, and the cell goes on in lockstep
    with the other stations' controllers, or at the wall-clock pace when none is left, as a
    real cell would while a controller restarts, so an outage costs about the sim time it
    lasts. When that station's acks come again (a restarted controller), the twin waits up to
    :data:`twin.lockstep.RESYNC_WAIT_S` for it to catch up, logs ``controller_resumed`` and
    waits for it again.
    """

    def __init__(
        self,
        node: SteppedEndpoint[Any],
        spin_once: SpinOnce,
        ack_timeout_s: float,
        start_timeout_s: float,
    ) -> None:
        self.node = node
        self.twin = node.twin
        self.spin_once = spin_once
        self.ack_timeout_s = ack_timeout_s
        self.start_timeout_s = start_timeout_s
        self.next_wall = 0.0

    def run(self, duration: float, on_first_step: Callable[[], None] | None = None) -> None:
        """Match the controllers, then step until ``duration`` (``on_first_step``: see
        :func:`run_loop`)."""
        node, twin = self.node, self.twin
        deadline = time.monotonic() + self.start_timeout_s
        while not node.peers_matched() and time.monotonic() < deadline:
            self.spin_once(timeout_sec=0.05)
        for link in node.links:
            if link.book.start(matched=node.link_matched(link)):
                self._fault(link, "no controller subscribed before the start")
        if on_first_step is not None:
            on_first_step()
        node.publish_step()
        self.next_wall = time.perf_counter()
        while twin.time_s < duration - 1e-9:
            tick = twin.step_count
            waits = self._waits(tick)
            if waits:
                self._wait_for(tick, waits)
                for link, wait_s in waits:
                    self._settle(link, tick, wait_s)
            elif any(link.book.alive for link in node.links):
                self.spin_once(timeout_sec=0.0)  # no controller sends commands for this tick
                self.next_wall = time.perf_counter()
            else:
                self.next_wall += twin.dt_s
                serve_until(self.spin_once, self.next_wall)
                self.spin_once(timeout_sec=0.0)
            twin.advance()
            node.publish_step()

    def _waits(self, tick: int) -> list[tuple[SteppedLink, float]]:
        """The stations whose acks tick ``tick`` waits for, each with its patience (s)."""
        waits = []
        for link in self.node.links:
            wait_s = link.book.patience_s(
                tick, ack_timeout_s=self.ack_timeout_s, start_timeout_s=self.start_timeout_s
            )
            if wait_s is not None:
                waits.append((link, wait_s))
        return waits

    def _wait_for(self, tick: int, waits: list[tuple[SteppedLink, float]]) -> None:
        """Serve callbacks until every waited-for station is ready or past its patience."""
        now = time.monotonic()
        until = [(link.book, now + wait_s) for link, wait_s in waits]
        while True:
            remaining = max(
                (t - time.monotonic() for book, t in until if not book.tick_ready(tick)),
                default=0.0,
            )
            if remaining <= 0:
                return
            self.spin_once(timeout_sec=min(remaining, 0.05))

    def _settle(self, link: SteppedLink, tick: int, wait_s: float) -> None:
        """After the wait: log what :meth:`twin.lockstep.AckBook.settle` decided."""
        twin = self.twin
        settled = link.book.settle(tick, time_s=twin.time_s)
        if settled.resumed_after_s is not None:
            twin.record_controller_resumed(settled.resumed_after_s, link.name)
            self.node.publish_new_events()
        if settled.timed_out:
            self.node.count_lockstep_timeout()
            self._fault(link, f"no acknowledgement of tick {tick} within {wait_s} s")
        if not settled.ready:
            self.next_wall = time.perf_counter()

    def _fault(self, link: SteppedLink, detail: str) -> None:
        self.twin.record_fault("controller_timeout", detail, link.name)
        self.node.publish_new_events()


__all__ = ["Lockstep", "SpinOnce", "SteppedEndpoint", "SteppedLink", "run_loop", "serve_until"]
