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
