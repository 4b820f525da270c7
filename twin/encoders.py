"""The twin's outgoing messages, each built once from its values, in the form its wire takes.

A high-rate message (clock, joint states, TCP pose, lockstep tick, detections, ground truth) is
an :class:`Outgoing`: its values, written on demand either as CDR bytes (:mod:`interfaces.cdr`:
what DDS and the recording take, several times cheaper than ``serialize_message`` of an rclpy
object) or as the rclpy message of the same values (what the in-process bus hands over, several
times cheaper than decoding those bytes: ``deserialize_message`` of the CDR costs 4 to 7 times
building the object, measured on ``JointState`` and ``LockstepTick``). Both forms come from the
one value record here, side by side, and ``tests/interfaces/test_cdr.py`` checks that rclpy
decodes the bytes to the message of the same values; the ground truth, at 30 Hz, has no
hand-written builder: its message is the decoded bytes. The low-rate messages (belt, bins,
events, markers) are rclpy objects only.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

from builtin_interfaces.msg import Time
from cdw_interfaces.msg import (
    BeltState,
    Detection,
    DetectionArray,
    LockstepTick,
    ObjectStateArray,
    SortingBin,
    SortingBins,
    SortingEvent,
)
from geometry_msgs.msg import Point, PoseStamped
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from visualization_msgs.msg import Marker

from interfaces import cdr
from interfaces.detections import Detection as PerceivedDetection
from interfaces.events import Event
from interfaces.ros import time_msg
from twin import scene as sc
from twin.ground_truth import GroundTruth
from twin.station import Station

WORLD = "world"
"""The frame every world-fixed message is stamped in."""


@dataclass(frozen=True, kw_only=True)
class Outgoing:
    """One message in both the forms a wire takes: ``encode()`` its CDR bytes, ``build()`` the
    rclpy message of the same values (``float32`` fields already rounded). Neither is computed
    until asked for."""

    encode: Callable[[], bytes]
    build: Callable[[], Any]


def clock(stamp: Time) -> Outgoing:
    """``/clock``."""
    return Outgoing(
        encode=partial(cdr.clock_cdr, stamp.sec, stamp.nanosec),
        build=lambda: Clock(clock=stamp),
    )


def joint_state(
    stamp: Time, names: list[str], position: list[float], velocity: list[float]
) -> Outgoing:
    """A station's ``joint_states``: ``names``, ``position`` and ``velocity`` of equal length."""

    def build() -> JointState:
        joints = JointState(name=names, position=position, velocity=velocity)
        joints.header.stamp = stamp
        return joints

    return Outgoing(
        encode=partial(cdr.joint_state_cdr, stamp.sec, stamp.nanosec, names, position, velocity),
        build=build,
    )


def pose_stamped(stamp: Time, position_m: cdr.Vec3, quat_xyzw: cdr.Quat) -> Outgoing:
    """A station's ``tcp_pose`` in ``world``."""

    def build() -> PoseStamped:
        pose = PoseStamped()
        pose.header.stamp = stamp
        pose.header.frame_id = WORLD
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = position_m
        o = pose.pose.orientation
        o.x, o.y, o.z, o.w = quat_xyzw
        return pose

    encode = partial(cdr.pose_stamped_cdr, stamp.sec, stamp.nanosec, WORLD, position_m, quat_xyzw)
    return Outgoing(encode=encode, build=build)


def lockstep_tick(stamp: Time, values: cdr.TickValues) -> Outgoing:
    """``/lockstep/tick`` of ``values`` (stamped ``stamp``, the same time as its fields)."""

    def build() -> LockstepTick:
        v = values
        return LockstepTick(
            tick=v.tick,
            stamp=stamp,
            n_joint_states=v.n_joint_states,
            n_belt_states=v.n_belt_states,
            n_detections=v.n_detections,
            n_claims=v.n_claims,
            last_joint_state_ns=v.last_joint_state_ns,
            last_belt_state_ns=v.last_belt_state_ns,
            last_detections_ns=v.last_detections_ns,
            last_claims_ns=v.last_claims_ns,
        )

    return Outgoing(encode=partial(cdr.lockstep_tick_cdr, values), build=build)


def detection_values(d: PerceivedDetection) -> cdr.DetectionValues:
    """One perceived detection as the message carries it: a suction point only with a radius
    above 0 (else the message's default, zeros: none)."""
    has_point = d.suction_radius_m > 0.0  # False for NaN
    return cdr.DetectionValues(
        class_name=d.class_name,
        confidence=cdr.float32(d.confidence),  # the field is a float32
        position_m=(d.x_m, d.y_m, d.z_m),
        yaw_rad=d.yaw_rad,
        length_m=d.length_m,
        width_m=d.width_m,
        height_m=d.height_m,
        suction_point_m=d.suction_point_m if has_point else (0.0, 0.0, 0.0),
        suction_radius_m=d.suction_radius_m if has_point else 0.0,
        suction_tilt_rad=d.suction_tilt_rad if has_point else 0.0,
    )


def detections(stamp: Time, detected: Sequence[PerceivedDetection]) -> Outgoing:
    """``/objects/detections``: one frame of detections, stamped ``stamp``."""
    values = [detection_values(d) for d in detected]

    def build() -> DetectionArray:
        msg = DetectionArray()
        msg.header.stamp = stamp
        msg.header.frame_id = WORLD
        for v in values:
            det = Detection(
                class_name=v.class_name,
                confidence=v.confidence,
                yaw_rad=v.yaw_rad,
                length_m=v.length_m,
                width_m=v.width_m,
                height_m=v.height_m,
                suction_radius_m=v.suction_radius_m,
                suction_tilt_rad=v.suction_tilt_rad,
            )
            det.position.x, det.position.y, det.position.z = v.position_m
            point = det.suction_point
            point.x, point.y, point.z = v.suction_point_m
            msg.detections.append(det)
        return msg

    encode = partial(cdr.detection_array_cdr, stamp.sec, stamp.nanosec, WORLD, values)
    return Outgoing(encode=encode, build=build)


def ground_truth(stamp: Time, objects: Iterable[GroundTruth]) -> Outgoing:
    """``/objects/ground_truth`` (evaluation only) of ``objects``: written as CDR at once; its
    message is those bytes decoded."""
    values = [
        cdr.ObjectStateValues(
            id=gt.id,
            class_name=gt.class_name,
            position_m=gt.position_m,
            orientation_xyzw=gt.orientation_xyzw,
            linear_velocity_mps=gt.linear_velocity_mps,
            angular_velocity_radps=gt.angular_velocity_radps,
            length_m=gt.length_m,
            width_m=gt.width_m,
            height_m=gt.height_m,
            area_m2=gt.area_m2,
            volume_m3=gt.volume_m3,
            mass_kg=gt.mass_kg,
            on_belt=gt.on_belt,
            in_workspace=gt.in_workspace,
            held=gt.held,
            in_bin=gt.in_bin,
        )
        for gt in objects
    ]
    data = cdr.object_state_array_cdr(stamp.sec, stamp.nanosec, WORLD, values)
    return Outgoing(encode=lambda: data, build=lambda: deserialize_message(data, ObjectStateArray))


def bins(station: Station, stamp: Time) -> SortingBins:
    """A station's ``cell/bins``: its bins (``StationSpec.bins``), stamped ``stamp``."""
    msg = SortingBins()
    msg.header.stamp = stamp
    msg.header.frame_id = WORLD
    for b in station.spec.bins:
        msg.bins.append(
            SortingBin(
                class_name=b.class_name,
                position=Point(x=b.centre_x_m, y=b.centre_y_m, z=b.top_z_m),
                inner_half_m=b.inner_half_m,
                size_m=b.size_m,
                floor_z_m=b.floor_z_m,
            )
        )
    return msg


@dataclass(frozen=True, kw_only=True)
class BeltValues:
    """The fields of one ``/conveyor/state``."""

    setpoint_mps: float
    speed_mps: float
    position_m: float
    motor_torque_nm: float
    motor_current_a: float
    load_mass_kg: float


def belt_state(stamp: Time, v: BeltValues) -> BeltState:
    """``/conveyor/state``."""
    msg = BeltState(
        setpoint_mps=v.setpoint_mps,
        speed_mps=v.speed_mps,
        position_m=v.position_m,
        motor_torque_nm=v.motor_torque_nm,
        motor_current_a=v.motor_current_a,
        load_mass_kg=v.load_mass_kg,
    )
    msg.header.stamp = stamp
    msg.header.frame_id = WORLD
    return msg


def sorting_event(event: Event) -> SortingEvent:
    """``/events``: one logged event, its data as JSON."""
    msg = SortingEvent(
        type=str(event.type),
        object_id=event.object_id,
        class_name=event.class_name,
        detail=json.dumps(event.data),
    )
    msg.header.stamp = time_msg(event.time_s)
    return msg


def marker(m: sc.SceneMarker, stamp: Time) -> Marker:
    """A ``visualization_msgs/Marker`` of a scene marker."""
    msg = Marker()
    msg.header.stamp = stamp
    msg.header.frame_id = m.frame_id
    msg.ns = m.ns
    msg.id = m.id
    msg.type = int(m.kind)
    msg.action = int(m.action)
    if m.action is sc.MarkerAction.DELETE:
        return msg
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z = m.position_m
    o.x, o.y, o.z, o.w = m.orientation_xyzw
    msg.scale.x, msg.scale.y, msg.scale.z = m.scale
    col = msg.color
    col.r, col.g, col.b, col.a = m.rgba
    msg.frame_locked = m.frame_locked
    if m.points_m is not None:
        msg.points = [Point(x=x, y=y, z=z) for x, y, z in m.points_m.tolist()]
    return msg


__all__ = [
    "WORLD",
    "BeltValues",
    "Outgoing",
    "belt_state",
    "bins",
    "clock",
    "detection_values",
    "detections",
    "ground_truth",
    "joint_state",
    "lockstep_tick",
    "marker",
    "pose_stamped",
    "sorting_event",
]
