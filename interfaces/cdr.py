"""CDR bytes of the twin's high-rate messages, written directly.

The twin publishes a clock, each station's joint states and TCP pose and the lockstep tick
every physics step, and the ground truth and the scene 30 times a second. Building those as
rclpy message objects and serializing them cost more than the rest of a step's publishing;
over ROS 2 the node publishes these bytes as they are, and an episode's recording stores them.
Each encoder gives plain little-endian CDR with its 4-byte encapsulation header (alignment
counted from after the header) and no trailing padding, as a DDS writer sends it and as strict
readers (``rosbags``) expect: the tests check that rclpy deserializes it to the message of the
same values and that ``rosbags`` serializes that message to the same bytes.
(``rclpy.serialization.serialize_message`` pads some messages at the end, which ``rosbags``
refuses.) Pure Python (``struct``), no ROS import.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import lru_cache

CDR_HEADER = b"\x00\x01\x00\x00"
"""CDR little-endian encapsulation, no options."""

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_U64 = struct.Struct("<Q")
_I64 = struct.Struct("<q")


class CdrWriter:
    """Appends CDR values to a buffer, aligning each to its size from after the header."""

    def __init__(self) -> None:
        self.out = bytearray(CDR_HEADER)

    def align(self, size: int) -> None:
        """Pad to a multiple of ``size`` bytes (counted from after the header)."""
        self.out += b"\x00" * (-(len(self.out) - 4) % size)

    def u32(self, value: int) -> None:
        """A ``uint32`` (also a sequence's length)."""
        self.align(4)
        self.out += _U32.pack(value)

    def u64(self, value: int) -> None:
        """A ``uint64``."""
        self.align(8)
        self.out += _U64.pack(value)

    def i64(self, value: int) -> None:
        """An ``int64``."""
        self.align(8)
        self.out += _I64.pack(value)

    def stamp(self, sec: int, nanosec: int) -> None:
        """A ``builtin_interfaces/Time``."""
        self.align(4)
        self.out += _STAMP.pack(sec, nanosec)

    def string(self, text: str) -> None:
        """A ``string``: its length with the terminating NUL, the UTF-8 bytes, the NUL."""
        self.align(4)
        self.out += _string_bytes(text)

    def header(self, sec: int, nanosec: int, frame_id: str) -> None:
        """A ``std_msgs/Header``."""
        self.stamp(sec, nanosec)
        self.string(frame_id)

    def strings(self, texts: Sequence[str]) -> None:
        """A ``sequence<string>``."""
        self.u32(len(texts))
        for text in texts:
            self.string(text)

    def f64s(self, values: Sequence[float]) -> None:
        """``float64`` values one after the other (a fixed block such as a pose)."""
        self.align(8)
        self.out += struct.pack(f"<{len(values)}d", *values)

    def f64_sequence(self, values: Sequence[float]) -> None:
        """A ``sequence<float64>`` (no padding after the length of an empty one)."""
        self.u32(len(values))
        if values:
            self.f64s(values)

    def bools(self, values: Sequence[bool]) -> None:
        """``bool`` values, one byte each."""
        self.out += bytes(1 if v else 0 for v in values)

    def bytes(self) -> bytes:
        """The message so far."""
        return bytes(self.out)


@lru_cache(maxsize=4096)
def _string_bytes(text: str) -> bytes:
    data = text.encode("utf-8")
    return _U32.pack(len(data) + 1) + data + b"\x00"


def clock_cdr(sec: int, nanosec: int) -> bytes:
    """``rosgraph_msgs/msg/Clock``."""
    return CDR_HEADER + _STAMP.pack(sec, nanosec)


def pose_stamped_cdr(sec: int, nanosec: int, frame_id: str, position: Vec3, quat: Quat) -> bytes:
    """``geometry_msgs/msg/PoseStamped``."""
    w = CdrWriter()
    w.header(sec, nanosec, frame_id)
    w.f64s((*position, *quat))
    return w.bytes()


def joint_state_cdr(
    sec: int,
    nanosec: int,
    names: Sequence[str],
    positions: Sequence[float],
    velocities: Sequence[float],
) -> bytes:
    """``sensor_msgs/msg/JointState`` with an empty ``frame_id`` and no efforts."""
    w = CdrWriter()
    w.header(sec, nanosec, "")
    w.strings(names)
    w.f64_sequence(positions)
    w.f64_sequence(velocities)
    w.f64_sequence(())  # effort
    return w.bytes()


@dataclass(frozen=True, kw_only=True)
class TickValues:
    """The fields of one ``cdw_interfaces/msg/LockstepTick``."""

    tick: int
    sec: int
    nanosec: int
    n_joint_states: int
    n_belt_states: int
    n_detections: int
    last_joint_state_ns: int
    last_belt_state_ns: int
    last_detections_ns: int
    n_claims: int
    last_claims_ns: int


def lockstep_tick_cdr(t: TickValues) -> bytes:
    """``cdw_interfaces/msg/LockstepTick``."""
    w = CdrWriter()
    w.u64(t.tick)
    w.stamp(t.sec, t.nanosec)
    w.u32(t.n_joint_states)
    w.u32(t.n_belt_states)
    w.u32(t.n_detections)
    w.i64(t.last_joint_state_ns)
    w.i64(t.last_belt_state_ns)
    w.i64(t.last_detections_ns)
    w.u32(t.n_claims)
    w.i64(t.last_claims_ns)
    return w.bytes()


_F32 = struct.Struct("<f")


def float32(value: float) -> float:
    """``value`` as a ``float32`` field carries it (rounded to single precision)."""
    return float(_F32.unpack(_F32.pack(value))[0])


@dataclass(frozen=True, kw_only=True)
class DetectionValues:
    """The fields of one ``cdw_interfaces/msg/Detection``, in the message's order."""

    class_name: str
    confidence: float
    position_m: Vec3
    yaw_rad: float
    length_m: float
    width_m: float
    height_m: float
    suction_point_m: Vec3 = (0.0, 0.0, 0.0)
    suction_radius_m: float = 0.0
    suction_tilt_rad: float = 0.0


def detection_array_cdr(
    sec: int, nanosec: int, frame_id: str, detections: Iterable[DetectionValues]
) -> bytes:
    """``cdw_interfaces/msg/DetectionArray`` (``confidence`` is a ``float32``)."""
    w = CdrWriter()
    w.header(sec, nanosec, frame_id)
    items = list(detections)
    w.u32(len(items))
    for d in items:
        w.string(d.class_name)
        w.align(4)
        w.out += _F32.pack(d.confidence)
        w.f64s((*d.position_m, d.yaw_rad, d.length_m, d.width_m, d.height_m))
        w.f64s((*d.suction_point_m, d.suction_radius_m, d.suction_tilt_rad))
    return w.bytes()


@dataclass(frozen=True, kw_only=True)
class ObjectStateValues:
    """The fields of one ``cdw_interfaces/msg/ObjectState``, in the message's order."""

    id: int
    class_name: str
    position_m: Vec3
    orientation_xyzw: Quat
    linear_velocity_mps: Vec3
    angular_velocity_radps: Vec3
    length_m: float
    width_m: float
    height_m: float
    area_m2: float
    volume_m3: float
    mass_kg: float
    on_belt: bool
    in_workspace: bool
    held: bool
    in_bin: bool


def object_state_array_cdr(
    sec: int, nanosec: int, frame_id: str, objects: Iterable[ObjectStateValues]
) -> bytes:
    """``cdw_interfaces/msg/ObjectStateArray``."""
    w = CdrWriter()
    w.header(sec, nanosec, frame_id)
    items = list(objects)
    w.u32(len(items))
    for o in items:
        w.u32(o.id)
        w.string(o.class_name)
        w.f64s(
            (
                *o.position_m,
                *o.orientation_xyzw,
                *o.linear_velocity_mps,
                *o.angular_velocity_radps,
                o.length_m,
                o.width_m,
                o.height_m,
                o.area_m2,
                o.volume_m3,
                o.mass_kg,
            )
        )
        w.bools((o.on_belt, o.in_workspace, o.held, o.in_bin))
    return w.bytes()


__all__ = [
    "CDR_HEADER",
    "CdrWriter",
    "DetectionValues",
    "ObjectStateValues",
    "TickValues",
    "clock_cdr",
    "detection_array_cdr",
    "float32",
    "joint_state_cdr",
    "lockstep_tick_cdr",
    "object_state_array_cdr",
    "pose_stamped_cdr",
]
