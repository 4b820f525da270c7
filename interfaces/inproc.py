"""An in-process message bus with the surface of rclpy's publishers and subscriptions.

``--transport inproc`` runs the twin and every station's controller in one process: their
nodes publish and subscribe here instead of through DDS, and the same step loop serves both
(:meth:`Bus.spin_once` plays the executor's part). A subscriber receives exactly what it would
receive over DDS in lockstep: every message of its topic, in publish order, as the value
deserialization of the wire bytes gives (a message type with a ``float32`` field anywhere goes
through CDR; others are handed over as the object published, which no publisher changes after
publishing); transient-local topics keep their last ``depth`` messages for late subscribers.
Delivery is queued, not nested: a callback runs from :meth:`Bus.spin_once`, never from inside
``publish``, as an executor would run it.

Nothing here touches DDS or needs ``rclpy.init``; only rclpy's serialization is used.
"""

from __future__ import annotations

import sys
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rclpy.serialization import deserialize_message, serialize_message

from interfaces.contract import Qos

Callback = Callable[[Any], None]


@dataclass(frozen=True)
class WireExact:
    """A message its publisher built with the values its wire bytes carry (``float32`` fields
    already rounded): subscribers take it as it is, with no CDR round trip."""

    msg: Any


_WIRE_COPY: dict[Any, bool] = {}


def needs_wire_copy(msg_type: Any) -> bool:
    """Whether a message type holds a ``float32`` anywhere (nested types included): its values
    change on the wire (rounded to single precision), so a subscriber gets the CDR round trip."""
    known = _WIRE_COPY.get(msg_type)
    if known is None:
        known = _WIRE_COPY[msg_type] = _has_float32(msg_type)
    return known


def _has_float32(msg_type: Any) -> bool:
    fields = msg_type.get_fields_and_field_types()
    for type_name in fields.values():
        base = type_name.removeprefix("sequence<").split(",", 1)[0].rstrip(">").split("[", 1)[0]
        if base == "float":
            return True
        if "/" in base:
            package, name = base.split("/", 1)
            module = __import__(f"{package}.msg", fromlist=[name])
            if needs_wire_copy(getattr(module, name)):
                return True
    return False


@dataclass(eq=False)
class _Sub:
    """One subscription: its callback, whether it takes serialized bytes, its type."""

    name: str
    msg_type: Any
    callback: Callback
    raw: bool


@dataclass(eq=False)
class _Topic:
    """A topic's endpoints and, when transient local, its last ``depth`` messages."""

    msg_type: Any
    latched_depth: int = 0
    publishers: int = 0
    subs: list[_Sub] = field(default_factory=list)
    history: deque[Any] = field(default_factory=deque)


class InprocPublisher:
    """``rclpy.publisher.Publisher``'s surface: ``publish`` (a message or its CDR bytes),
    ``topic_name``, ``get_subscription_count``."""

    def __init__(self, bus: Bus, name: str) -> None:
        self._bus = bus
        self.topic_name = name

    def publish(self, msg: Any) -> None:
        """Queue ``msg`` (a message, or ``bytes`` of one serialized) for every subscriber."""
        self._bus.publish(self.topic_name, msg)

    def get_subscription_count(self) -> int:
        """Subscriptions of this topic on the bus."""
        return len(self._bus.topic(self.topic_name).subs)


class InprocSubscription:
    """``rclpy.subscription.Subscription``'s surface: ``topic_name``, ``get_publisher_count``,
    ``destroy``."""

    def __init__(self, bus: Bus, sub: _Sub) -> None:
        self._bus = bus
        self._sub = sub
        self.topic_name = sub.name

    def get_publisher_count(self) -> int:
        """Publishers of this topic on the bus."""
        return self._bus.topic(self.topic_name).publishers

    def destroy(self) -> None:
        """Unsubscribe: nothing more is delivered to it, queued deliveries included."""
        self._bus.unsubscribe(self._sub)


class Bus:
    """Topics by name, and the queue of deliveries not yet made."""

    def __init__(self) -> None:
        self._topics: dict[str, _Topic] = {}
        self._queue: deque[tuple[_Sub, Any]] = deque()
        self.delivered = 0
        """Callbacks run so far."""

    def topic(self, name: str, msg_type: Any = None) -> _Topic:
        """The topic ``name`` (created on first use with ``msg_type``)."""
        topic = self._topics.get(name)
        if topic is None:
            topic = self._topics[name] = _Topic(msg_type=msg_type)
        elif msg_type is not None and topic.msg_type is None:
            topic.msg_type = msg_type
        return topic

    def create_publisher(self, msg_type: Any, name: str, qos: Qos) -> InprocPublisher:
        """A publisher of ``name``; ``qos.latched`` keeps the last ``qos.depth`` messages."""
        topic = self.topic(name, msg_type)
        topic.publishers += 1
        if qos.latched:
            topic.latched_depth = max(topic.latched_depth, qos.depth)
        return InprocPublisher(self, name)

    def create_subscription(
        self, msg_type: Any, name: str, callback: Callback, qos: Qos, *, raw: bool = False
    ) -> InprocSubscription:
        """Subscribe ``callback`` to ``name`` (``raw``: it takes the CDR bytes); a latched
        topic's kept messages are queued for it at once (``qos`` as the subscriber asks:
        reliable keep-last, which in one process never drops)."""
        del qos
        topic = self.topic(name, msg_type)
        sub = _Sub(name=name, msg_type=msg_type, callback=callback, raw=raw)
        topic.subs.append(sub)
        for msg in topic.history:
            self._queue.append((sub, msg))
        return InprocSubscription(self, sub)

    def unsubscribe(self, sub: _Sub) -> None:
        """Remove ``sub`` and its queued deliveries."""
        topic = self.topic(sub.name)
        topic.subs = [s for s in topic.subs if s is not sub]
        self._queue = deque((s, m) for s, m in self._queue if s is not sub)

    def count_publishers(self, name: str) -> int:
        """Publishers of ``name`` (``Node.count_publishers``)."""
        return self.topic(name).publishers

    def count_subscribers(self, name: str) -> int:
        """Subscriptions of ``name`` (``Node.count_subscribers``)."""
        return len(self.topic(name).subs)

    def publish(self, name: str, msg: Any) -> None:
        """Queue ``msg`` (a message or CDR ``bytes``) for every subscription of ``name``."""
        topic = self.topic(name)
        if topic.latched_depth:
            topic.history.append(msg)
            while len(topic.history) > topic.latched_depth:
                topic.history.popleft()
        for sub in topic.subs:
            self._queue.append((sub, msg))

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Run every queued delivery, those queued meanwhile included, in order: the
        executor's ``spin_once``. With nothing queued it waits ``timeout_sec``, as an executor
        with nothing to serve does (nothing arrives from outside meanwhile)."""
        queue = self._queue
        if not queue:
            if timeout_sec:
                time.sleep(timeout_sec)
            return
        while queue:
            sub, msg = queue.popleft()
            sub.callback(_as_received(sub, msg))
            self.delivered += 1

    @property
    def idle(self) -> bool:
        """No delivery is queued."""
        return not self._queue


class InprocLogger:
    """``warning``, ``error`` and ``info`` lines on stderr, in rclpy's console format."""

    def __init__(self, name: str) -> None:
        self.name = name

    def _line(self, level: str, text: str) -> None:
        print(f"[{level}] [{time.time():.9f}] [{self.name}]: {text}", file=sys.stderr, flush=True)

    def info(self, text: str) -> None:
        """An information line."""
        self._line("INFO", text)

    def warning(self, text: str) -> None:
        """A warning line."""
        self._line("WARN", text)

    def error(self, text: str) -> None:
        """An error line."""
        self._line("ERROR", text)


def _as_received(sub: _Sub, msg: Any) -> Any:
    """``msg`` as ``sub`` receives it over DDS: bytes for a raw subscription, otherwise the
    message (deserialized from bytes, or through CDR where the wire changes values)."""
    if isinstance(msg, bytes | bytearray | memoryview):
        return bytes(msg) if sub.raw else deserialize_message(bytes(msg), sub.msg_type)
    if isinstance(msg, WireExact):
        return serialize_message(msg.msg) if sub.raw else msg.msg
    if sub.raw:
        return serialize_message(msg)
    if needs_wire_copy(type(msg)):
        return deserialize_message(serialize_message(msg), sub.msg_type)
    return msg


__all__ = [
    "Bus",
    "InprocLogger",
    "InprocPublisher",
    "InprocSubscription",
    "WireExact",
    "needs_wire_copy",
]
