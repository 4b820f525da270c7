"""The live view: every message of the cell contract served over Foxglove's WebSocket protocol.

``cdw-twin twin-node ... --foxglove`` (and ``cdw-twin run ... --foxglove``) hands the twin
node's tap to a :class:`LiveView` as well as to the recording: a WebSocket server of the
``foxglove-sdk`` package, on loopback unless told otherwise, with one channel per contract
topic (schema name the ROS type, schema encoding ``ros2msg`` with the same text the recording
embeds, message encoding ``cdr``), each message the bytes on the wire. Open Foxglove, choose
*Open connection*, ``ws://127.0.0.1:8765``::

    from interfaces.contract import resolved_topics
    from twin.live_view import LiveView

    view = LiveView(resolved_topics(("",)), port=8765)
    view.write("/clock", data, time.time_ns())
    view.close()

Without a client nothing is sent: :meth:`write` asks the channel whether any client subscribed
(the SDK keeps that per channel) before it logs.

Latched topics (QoS ``transient local``: the bins, ``/events``, the static transforms and the
scene markers) reach a client that subscribes late: the view keeps each such topic's last
``depth`` messages (its QoS history depth, as DDS does) and logs them again, at the next
:meth:`write`, when a client has subscribed to its channel. The Python SDK does not say which sink
a client is, so the repeat goes to every client subscribed to that channel; for the scene it is
harmless (a marker or a static transform sent twice is the same marker or transform), a second
client watching ``/events`` sees the kept events twice.
"""

from __future__ import annotations

import errno
import socket
from collections import deque
from collections.abc import Iterable, Sequence
from pathlib import Path

import foxglove
from foxglove.websocket import ChannelView, Client, ServerListener

from interfaces.contract import Topic
from twin.errors import CdwTwinError

DEFAULT_PORT = 8765
"""Foxglove's default WebSocket port."""

DEFAULT_HOST = "127.0.0.1"
"""Loopback: only this machine sees the episode unless ``--foxglove-host`` says otherwise."""


class LiveViewError(CdwTwinError):
    """The live view cannot start (the port is in use, the host cannot be bound)."""


def check_port(host: str, port: int) -> None:
    """Raise :class:`LiveViewError` when ``host:port`` cannot be listened on now (a runner's
    check before it starts episodes whose twin nodes serve there in turn)."""
    if not 0 <= port <= 65535:
        msg = f"--foxglove: port {port} is not a TCP port (0 to 65535)"
        raise LiveViewError(msg)
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except (OSError, OverflowError, UnicodeError) as exc:
            in_use = isinstance(exc, OSError) and exc.errno == errno.EADDRINUSE
            reason = "in use" if in_use else f"not available ({exc})"
            msg = f"--foxglove: port {port} on {host} is {reason}"
            raise LiveViewError(msg) from None


class _Subscriptions(ServerListener):
    """Server listener: notes each channel a client subscribes to, for :meth:`LiveView.write`
    to send its kept messages again from the node's own thread (logging from the server's
    thread, inside its callback, could wait on the thread that is logging)."""

    def __init__(self) -> None:
        self.pending: list[int] = []

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        """A client subscribed to ``channel`` (its subscription is live by now)."""
        del client
        self.pending.append(int(channel.id))


class LiveView:
    """A Foxglove WebSocket server taking raw CDR messages, like
    :class:`twin.recording.McapRecording`.

    ``topics`` are ``(wire name, contract topic)`` pairs
    (:func:`interfaces.contract.resolved_topics`). Raises :class:`LiveViewError` naming the
    address when the server cannot listen on ``host:port`` (``port`` 0: any free port; the one
    taken is :attr:`port`).
    """

    def __init__(
        self,
        topics: Iterable[tuple[str, Topic]],
        *,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        dirs: Sequence[Path] | None = None,
        name: str = "cdw-twin",
    ) -> None:
        from twin.recording import message_definition

        self._context = foxglove.Context()
        self._channels: dict[str, foxglove.Channel] = {}
        self._kept: dict[str, deque[tuple[bytes, int]]] = {}
        self._by_id: dict[int, str] = {}
        definitions: dict[str, bytes] = {}
        for wire, topic in topics:
            if wire in self._channels:
                continue
            if topic.msgtype not in definitions:
                definitions[topic.msgtype] = message_definition(topic.msgtype, dirs).encode()
            schema = foxglove.Schema(
                name=topic.msgtype, encoding="ros2msg", data=definitions[topic.msgtype]
            )
            channel = foxglove.Channel(
                wire, schema=schema, message_encoding="cdr", context=self._context
            )
            self._channels[wire] = channel
            self._by_id[channel.id()] = wire
            if topic.qos.latched:
                self._kept[wire] = deque(maxlen=max(1, topic.qos.depth))
        self._subscriptions = _Subscriptions()
        if not 0 <= port <= 65535:
            msg = f"--foxglove: port {port} is not a TCP port (0 to 65535)"
            raise LiveViewError(msg)
        try:
            self._server = foxglove.start_server(
                name=name,
                host=host,
                port=port,
                context=self._context,
                server_listener=self._subscriptions,
            )
        except RuntimeError as exc:
            reason = "in use" if "in use" in str(exc) else f"not available ({exc})"
            msg = f"--foxglove: port {port} on {host} is {reason}"
            raise LiveViewError(msg) from None
        self.host = host
        self.port = int(self._server.port)

    @property
    def url(self) -> str:
        """The address a Foxglove client opens."""
        return f"ws://{self.host}:{self.port}"

    def wants(self, topic: str) -> bool:
        """Whether some client subscribed to ``topic`` (its wire name): a node serving only
        the view may skip building what nobody watches (the ground truth, the scene)."""
        channel = self._channels.get(topic)
        return channel is not None and bool(channel.has_sinks())

    def write(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Send one serialized message on ``topic`` (its wire name) to every client subscribed
        to it (nothing is sent without one); keep it when the topic is latched."""
        if self._subscriptions.pending:
            self._replay()
        channel = self._channels.get(topic)
        if channel is None:
            msg = f"live view: topic {topic!r} is not one of the served channels"
            raise LiveViewError(msg)
        kept = self._kept.get(topic)
        if kept is not None:
            kept.append((data, log_time_ns))
        if channel.has_sinks():
            channel.log(data, log_time=log_time_ns)

    def _replay(self) -> None:
        """Send the kept messages of every latched channel a client subscribed to since the
        last call."""
        pending = self._subscriptions.pending
        while pending:
            wire = self._by_id.get(pending.pop(0))
            kept = None if wire is None else self._kept.get(wire)
            if wire is None or kept is None:
                continue
            channel = self._channels[wire]
            for data, log_time_ns in kept:
                channel.log(data, log_time=log_time_ns)

    def close(self) -> None:
        """Stop the server (clients are disconnected) and close the channels."""
        self._server.stop()
        for channel in self._channels.values():
            channel.close()


__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "LiveView", "LiveViewError", "check_port"]
