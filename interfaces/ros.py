"""The contract's values as rclpy objects: QoS profiles, message classes, time messages.

Only ROS nodes import this module (it imports rclpy); :mod:`interfaces.contract` stays free of
ROS so that pure code and tests can use it.
"""

from __future__ import annotations

import importlib
from functools import cache
from typing import Any

from builtin_interfaces.msg import Time
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from interfaces.contract import Qos, Topic, stamp_ns, stamp_s, time_parts


@cache
def qos_profile(qos: Qos) -> QoSProfile:
    """The rclpy profile of a contract QoS."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=qos.depth,
        reliability=ReliabilityPolicy.RELIABLE if qos.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if qos.latched else DurabilityPolicy.VOLATILE,
    )


@cache
def message_class(topic: Topic) -> Any:
    """The Python message class of a topic (``sensor_msgs.msg.JointState``)."""
    module = importlib.import_module(f"{topic.package}.msg")
    return getattr(module, topic.type_name)


def time_msg(t_s: float) -> Time:
    """A ``builtin_interfaces/Time`` of ``t_s >= 0`` seconds (:func:`time_parts`)."""
    sec, nanosec = time_parts(t_s)
    return Time(sec=sec, nanosec=nanosec)


def msg_stamp_ns(stamp: Any) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time``."""
    return stamp_ns(stamp.sec, stamp.nanosec)


def msg_stamp_s(stamp: Any) -> float:
    """Seconds of a ``builtin_interfaces/Time``."""
    return stamp_s(stamp.sec, stamp.nanosec)


class RosWire:
    """A node's endpoints on DDS, behind the surface :class:`interfaces.inproc.Bus` also has:
    the twin's and the controller's node logic creates its publishers and subscriptions,
    and counts the graph's endpoints through a wire, so the same logic runs over ROS 2
    and in process (``--transport inproc``)."""

    def __init__(self, node: Any) -> None:
        self.node = node

    def create_publisher(self, msg_type: Any, name: str, qos: Qos) -> Any:
        """``Node.create_publisher`` with the contract's QoS."""
        return self.node.create_publisher(msg_type, name, qos_profile(qos))

    def create_subscription(
        self, msg_type: Any, name: str, callback: Any, qos: Qos, *, raw: bool = False
    ) -> Any:
        """``Node.create_subscription`` with the contract's QoS (``raw``: CDR bytes)."""
        return self.node.create_subscription(msg_type, name, callback, qos_profile(qos), raw=raw)

    def count_publishers(self, name: str) -> int:
        """Publishers of ``name`` in the ROS graph."""
        return int(self.node.count_publishers(name))

    def count_subscribers(self, name: str) -> int:
        """Subscriptions of ``name`` in the ROS graph."""
        return int(self.node.count_subscribers(name))
