"""The controller's messages as its values and back: joint states, detections, claims, priorities.

The node (:mod:`control.node`) converts each message it takes with these and hands the values to
the pure tracker and pick controller; a claim of the controller's goes out as a ``Claim``
message. The messages are duck-typed (any object with the message's fields, rclpy's or the
in-process bus's); nothing here subscribes or publishes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from control.allocation import Claim, ClaimState
from control.tools import ControllerTool
from control.tracking import Detection
from interfaces.contract import (
    CLAIM,
    CLAIM_STATES,
)
from interfaces.ros import message_class, msg_stamp_s, time_msg

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True, eq=False)
class JointSample:
    """Measured arm joints at ``stamp_s``: ``positions_rad`` ``(n_arm,) float``, and the
    tool's measured command value ``tool_measured`` (NaN when not measured)."""

    stamp_s: float
    positions_rad: FloatArray
    tool_measured: float = math.nan


def joint_sample(
    msg: Any, arm_joint_names: Sequence[str], tool: ControllerTool | None = None
) -> JointSample | None:
    """The arm joints of a ``JointState`` in ``arm_joint_names`` order; None if any is missing
    or not finite.

    The tool's measured value comes from its joints
    (:meth:`~control.tools.ControllerTool.measured_m`): NaN without a tool, or when its joints
    are missing.
    """
    index = {name: i for i, name in enumerate(msg.name)}
    if len(msg.position) != len(msg.name) or any(n not in index for n in arm_joint_names):
        return None
    q = np.array([msg.position[index[n]] for n in arm_joint_names], dtype=np.float64)
    if not np.all(np.isfinite(q)):
        return None
    measured = math.nan
    if tool is not None:
        names = tool.joint_names
        measured = tool.measured({n: float(msg.position[index[n]]) for n in names if n in index})
    return JointSample(
        stamp_s=msg_stamp_s(msg.header.stamp), positions_rad=q, tool_measured=measured
    )


def _suction_point(d: Any) -> tuple[float, float, float, float, float]:
    """A detection's suction point ``(x, y, z)``, radius and face tilt; NaN when its radius is
    not above 0 (a camera that reports none leaves the message's default 0)."""
    radius_m = float(d.suction_radius_m)
    if not radius_m > 0.0:
        return math.nan, math.nan, math.nan, math.nan, math.nan
    point = d.suction_point
    return float(point.x), float(point.y), float(point.z), radius_m, float(d.suction_tilt_rad)


def detections_of(msg: Any) -> tuple[float, list[Detection]]:
    """Capture time and detections of one camera frame (validation is the tracker's job)."""
    stamp_s = msg_stamp_s(msg.header.stamp)
    detections = [_detection(stamp_s, d, *_suction_point(d)) for d in msg.detections]
    return stamp_s, detections


def _detection(
    stamp_s: float,
    d: Any,
    sx_m: float,
    sy_m: float,
    sz_m: float,
    radius_m: float,
    tilt_rad: float,
) -> Detection:
    """One camera detection as the tracker takes it, with its suction point (NaN: none)."""
    return Detection(
        stamp_s=stamp_s,
        class_name=str(d.class_name),
        confidence=float(d.confidence),
        x_m=float(d.position.x),
        y_m=float(d.position.y),
        yaw_rad=float(d.yaw_rad),
        length_m=float(d.length_m),
        width_m=float(d.width_m),
        height_m=float(d.height_m),
        base_z_m=float(d.position.z),
        suction_x_m=sx_m,
        suction_y_m=sy_m,
        suction_z_m=sz_m,
        suction_radius_m=radius_m,
        suction_tilt_rad=tilt_rad,
    )


def claims_of(msg: Any) -> tuple[list[Claim], int]:
    """The claims of a relayed board (``ClaimArray``), and how many entries were malformed (a
    state other than :data:`~interfaces.contract.CLAIM_STATES`, or a position, velocity or
    radius that is not finite)."""
    claims: list[Claim] = []
    bad = 0
    for c in msg.claims:
        values = (c.position.x, c.position.y, c.velocity.x, c.velocity.y, c.radius_m)
        if c.state not in CLAIM_STATES or not all(math.isfinite(float(v)) for v in values):
            bad += 1
            continue
        state: ClaimState = c.state
        claims.append(
            Claim(
                station=str(c.station),
                track_id=int(c.track_id),
                class_name=str(c.class_name),
                stamp_s=msg_stamp_s(c.header.stamp),
                position_m=(float(c.position.x), float(c.position.y)),
                velocity_mps=(float(c.velocity.x), float(c.velocity.y)),
                radius_m=float(c.radius_m),
                state=state,
            )
        )
    return claims, bad


def claim_msg(claim: Claim) -> Any:
    """A ``Claim`` message of ``claim``."""
    msg = message_class(CLAIM)(
        station=claim.station,
        track_id=claim.track_id,
        class_name=claim.class_name,
        radius_m=claim.radius_m,
        state=claim.state,
    )
    msg.header.stamp = time_msg(claim.stamp_s)
    msg.header.frame_id = "world"
    msg.position.x, msg.position.y = claim.position_m
    msg.velocity.x, msg.velocity.y = claim.velocity_mps
    return msg


def priorities_of(
    classes: Sequence[str], known: Sequence[str]
) -> tuple[dict[str, float], list[str]]:
    """Class priorities from an ordered class list (first is highest); unknown names returned.

    Listed classes get ``len(classes) - index``; known classes not listed get 0 (picked last).
    """
    unknown = [name for name in classes if name not in known]
    listed = [name for name in classes if name in known]
    priorities = dict.fromkeys(known, 0.0)
    for i, name in enumerate(listed):
        priorities[name] = max(priorities[name], float(len(listed) - i))
    return priorities, unknown


__all__ = [
    "JointSample",
    "claim_msg",
    "claims_of",
    "detections_of",
    "joint_sample",
    "priorities_of",
]
