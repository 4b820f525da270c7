"""What carries a node's messages: the one protocol the twin's and the controllers' nodes share.

A node's logic creates its publishers and subscriptions and counts the graph's endpoints through
a :class:`Wire`, so the same logic runs over DDS (:class:`interfaces.ros.RosWire` around an rclpy
node) and in process (:class:`interfaces.inproc.Bus`, ``--transport inproc``). Free of ROS: a
protocol only.
"""

from __future__ import annotations

from typing import Any, Protocol

from interfaces.contract import Qos


class Wire(Protocol):
    """What carries a node's messages: DDS (:class:`interfaces.ros.RosWire` around the rclpy
    node) or the in-process bus (:class:`interfaces.inproc.Bus`)."""

    def create_publisher(self, msg_type: Any, name: str, qos: Qos) -> Any:
        """A publisher (``publish``, ``topic_name``, ``get_subscription_count``)."""
        ...

    def create_subscription(
        self, msg_type: Any, name: str, callback: Any, qos: Qos, *, raw: bool = False
    ) -> Any:
        """A subscription (``topic_name``, ``get_publisher_count``)."""
        ...

    def count_publishers(self, name: str) -> int:
        """Publishers of ``name`` in the graph."""
        ...

    def count_subscribers(self, name: str) -> int:
        """Subscriptions of ``name`` in the graph."""
        ...


__all__ = ["Wire"]
