"""Queued input messages, attributed to lockstep ticks by their stamps (pure, no ROS).

The twin's ``LockstepTick`` k names, per counted topic, the newest header stamp it has
published there up to tick k (-1 while none). Stamps increase strictly on each topic and DDS
delivers each topic in order, so the messages of ticks up to k are exactly those stamped at or
before that stamp. This holds for a controller that started late (a restart): it never saw
the beginning of the streams, so counting messages from its own start would misplace them,
and a count that runs ahead makes it wait for messages that never come.

A tick's messages have all arrived once, on each topic, one stamped at or after the named
stamp is here, or the first message this node received is newer than it (the older ones were
published before this node listened and will not come).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import Generic, TypeVar

Msg = TypeVar("Msg")


class _Stream(Generic[Msg]):
    __slots__ = ("first_ns", "newest_ns", "queue")

    def __init__(self) -> None:
        self.queue: deque[tuple[int, Msg]] = deque()
        self.first_ns: int | None = None
        self.newest_ns: int | None = None


class StampedInbox(Generic[Msg]):
    """Per-topic queues of ``(stamp_ns, message)``, oldest first."""

    def __init__(self, topics: Sequence[str]) -> None:
        if len(set(topics)) != len(topics):
            raise ValueError(f"StampedInbox: topics repeat: {list(topics)}")
        self._streams: dict[str, _Stream[Msg]] = {t: _Stream() for t in topics}

    def add(self, topic: str, stamp_ns: int, msg: Msg) -> None:
        """Queue a message as it arrives."""
        stream = self._stream(topic)
        if stream.first_ns is None:
            stream.first_ns = stamp_ns
        if stream.newest_ns is None or stamp_ns > stream.newest_ns:
            stream.newest_ns = stamp_ns
        stream.queue.append((stamp_ns, msg))

    def has_through(self, topic: str, last_ns: int) -> bool:
        """Whether every message on ``topic`` stamped up to ``last_ns`` that will ever arrive
        is here (``last_ns`` < 0: nothing was published)."""
        if last_ns < 0:
            return True
        stream = self._stream(topic)
        if stream.newest_ns is None or stream.first_ns is None:
            return False
        return stream.newest_ns >= last_ns or stream.first_ns > last_ns

    def complete(self, last_ns: Sequence[int]) -> bool:
        """:meth:`has_through` on every topic, ``last_ns`` in the order the topics were given."""
        if len(last_ns) != len(self._streams):
            raise ValueError(f"StampedInbox: {len(last_ns)} stamps for {len(self._streams)} topics")
        return all(self.has_through(t, n) for t, n in zip(self._streams, last_ns, strict=True))

    def take(self, topic: str, last_ns: int | None = None) -> list[Msg]:
        """Remove and return the queued messages stamped at or before ``last_ns`` (None: all),
        in arrival order (a message with an out-of-order stamp waits for those ahead of it)."""
        queue = self._stream(topic).queue
        out: list[Msg] = []
        while queue and (last_ns is None or queue[0][0] <= last_ns):
            out.append(queue.popleft()[1])
        return out

    def _stream(self, topic: str) -> _Stream[Msg]:
        try:
            return self._streams[topic]
        except KeyError:
            raise KeyError(f"StampedInbox: unknown topic {topic!r}") from None


__all__ = ["StampedInbox"]
