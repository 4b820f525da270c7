"""The twin's endpoints on a wire, every message in or out also handed to the tap.

With a tap (:data:`Tap`), every message the node publishes is serialized once, published as
those bytes and handed to the tap; every message it subscribes to arrives as bytes, goes to the
tap and is deserialized for its callback. Over ROS 2 every subscription takes the serialized
bytes, and a message longer than its topic's bound (:func:`max_message_bytes`) is refused before
it is decoded into Python objects; what a message may cost afterwards is bounded by that size.
On the in-process bus the messages are the peers' own objects, taken as they are.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from rclpy.serialization import deserialize_message, serialize_message

from interfaces import contract as c
from interfaces.contract import Topic
from interfaces.inproc import WireExact
from interfaces.ros import message_class
from interfaces.wire import Wire
from twin.encoders import Outgoing

Tap = Callable[[str, bytes, int], None]
"""Takes every message the node sends or receives: topic, serialized CDR bytes, wall time (ns
since the Unix epoch) of the send or receipt. ``cdw-twin run`` records the episode's MCAP this
way, in the twin's process (see ``twin-node --record``)."""

TapWants = Callable[[str], bool]
"""Whether the tap takes a topic (its wire name) now. The live view alone takes only what a
client subscribed to: the node then builds the ground truth and the scene only for a client."""

OnOversized = Callable[[str, str], None]
"""Called with a topic's wire name and a refusal's detail when a message is over its bound."""

DEFAULT_MAX_MESSAGE_BYTES = 4096
"""Longest serialized message the twin takes on a subscribed topic without its own bound
(a claim, a pick target, an ack, a ping, a gripper command or a setpoint is under 300 bytes)."""

MAX_MESSAGE_BYTES: dict[str, int] = {
    c.ARM_TRAJECTORY.name: 65_536,
    c.PRIORITIES.name: 16_384,
}
"""Longest serialized message per topic (its contract name) where the default is too small:
a one-point trajectory of 7 joints is about 300 bytes, a priority list of every class of a
dataset under 1 kB."""


def max_message_bytes(topic: Topic) -> int:
    """The longest serialized message the twin takes on ``topic``."""
    return MAX_MESSAGE_BYTES.get(topic.name, DEFAULT_MAX_MESSAGE_BYTES)


class TappedWire:
    """Publishers and subscriptions on ``wire``, each message also handed to ``tap``.

    ``takes_bytes``: the wire publishes serialized bytes (DDS) rather than message objects (the
    in-process bus, which hands a message over as it is). Subscriptions made here are kept
    (:attr:`subscriptions`) so that an in-process endpoint can drop them.
    """

    def __init__(
        self, wire: Wire, *, takes_bytes: bool, tap: Tap | None, tap_wants: TapWants | None
    ) -> None:
        self.wire = wire
        self.takes_bytes = takes_bytes
        self.tap = tap
        self.tap_wants = tap_wants
        self.subscriptions: list[Any] = []

    def publisher(self, topic: Topic, namespace: str = "") -> Any:
        """A publisher of ``topic`` under ``namespace`` with the contract's type and QoS."""
        return self.wire.create_publisher(message_class(topic), topic.resolve(namespace), topic.qos)

    def send(self, publisher: Any, msg: Any) -> None:
        """Publish ``msg``; with a tap, serialize it once and hand the same bytes to both."""
        if self.tap is None:
            publisher.publish(msg)
            return
        data = serialize_message(msg)
        publisher.publish(data if self.takes_bytes else msg)
        self.tap(publisher.topic_name, data, time.time_ns())

    def send_outgoing(self, publisher: Any, out: Outgoing) -> None:
        """Publish a message of both forms (:class:`twin.encoders.Outgoing`): over ROS 2 its CDR
        bytes as they are; on the in-process bus the message it builds, for the subscribers
        there are; the tap gets the bytes. Nothing is encoded that nobody takes."""
        data = out.encode() if self.takes_bytes or self.tap is not None else b""
        if self.takes_bytes:
            publisher.publish(data)
        elif publisher.get_subscription_count() > 0:
            publisher.publish(WireExact(out.build()))
        if self.tap is not None:
            self.tap(publisher.topic_name, data, time.time_ns())

    def send_serialized(self, publisher: Any, data: bytes) -> None:
        """Publish a message already serialized (CDR); with a tap, hand it the same bytes."""
        publisher.publish(data)
        if self.tap is not None:
            self.tap(publisher.topic_name, data, time.time_ns())

    def wanted(self, publisher: Any) -> bool:
        """Someone takes ``publisher``'s messages: the tap (:meth:`tapped`) or a matched
        subscriber (:meth:`subscribed`). A message of a volatile topic nobody takes need not be
        built: nobody would ever see it."""
        return self.tapped(publisher) or self.subscribed(publisher)

    def tapped(self, publisher: Any) -> bool:
        """The tap takes ``publisher``'s messages (unless it says it does not want that topic
        now: a live view without a client on it)."""
        return self.tap is not None and (
            self.tap_wants is None or self.tap_wants(publisher.topic_name)
        )

    @staticmethod
    def subscribed(publisher: Any) -> bool:
        """A subscriber on the wire is matched to ``publisher``."""
        return bool(publisher.get_subscription_count() > 0)

    def subscribe(
        self,
        topic: Topic,
        callback: Callable[[Any], None],
        namespace: str = "",
        *,
        on_oversized: OnOversized | None = None,
    ) -> Any:
        """Subscribe ``callback``; with a tap, record the serialized bytes too.

        Over ROS 2 the subscription takes the serialized bytes, and a message longer than
        :func:`max_message_bytes` is refused undecoded: ``on_oversized`` is told instead of
        ``callback``. On the in-process bus the messages are the peers' own objects."""
        msg_type = message_class(topic)
        name = topic.resolve(namespace)
        qos = topic.qos
        tap = self.tap
        if not self.takes_bytes:
            if tap is None:
                return self._kept(self.wire.create_subscription(msg_type, name, callback, qos))

            def on_msg(msg: Any) -> None:
                data = serialize_message(msg)  # as received: a callback may change msg
                received_ns = time.time_ns()
                callback(msg)
                tap(name, data, received_ns)

            return self._kept(self.wire.create_subscription(msg_type, name, on_msg, qos))
        limit = max_message_bytes(topic)

        def on_bytes(data: bytes) -> None:
            received_ns = time.time_ns()
            if len(data) > limit:
                if on_oversized is not None:
                    on_oversized(name, f"{len(data)} bytes, more than the {limit} this topic takes")
                return
            callback(deserialize_message(data, msg_type))  # first: a ping's echo waits for nothing
            if tap is not None:
                tap(name, data, received_ns)

        return self._kept(self.wire.create_subscription(msg_type, name, on_bytes, qos, raw=True))

    def _kept(self, subscription: Any) -> Any:
        self.subscriptions.append(subscription)
        return subscription


__all__ = [
    "DEFAULT_MAX_MESSAGE_BYTES",
    "MAX_MESSAGE_BYTES",
    "OnOversized",
    "Tap",
    "TapWants",
    "TappedWire",
    "max_message_bytes",
]
