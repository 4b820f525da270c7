"""Validation of commands arriving from outside (ROS), free of ROS so it is tested without it.

A command is accepted whole or rejected whole with a reason; the physics never sees a rejected
one. Reasons are short stable strings used as counter keys in the episode log.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from interfaces.errors import cut


@dataclass(frozen=True)
class Rejected:
    """Why a command was refused: ``reason`` is a counter key, ``detail`` says what was wrong."""

    reason: str
    detail: str


@dataclass(frozen=True)
class JointTarget:
    """Accepted arm targets in the arm's joint order, ``(n,)`` each."""

    positions: tuple[float, ...]
    velocities: tuple[float, ...] | None


def validate_joint_command(
    names: Sequence[str],
    positions: Sequence[float],
    velocities: Sequence[float],
    *,
    arm_joints: Sequence[str],
    lower: np.ndarray,
    upper: np.ndarray,
    velocity_limit: np.ndarray,
) -> JointTarget | Rejected:
    """Check a one-point joint trajectory against the arm; reorder it to the arm's joints.

    Every arm joint named exactly once (any order, no other joint), as many positions, and
    velocities either absent or one per joint; all finite; each position within
    ``[lower, upper]`` and each velocity within ``[-velocity_limit, velocity_limit]`` (1e-6
    tolerance). The first violation rejects the whole command, its detail naming the joint,
    the value and the limit.
    """
    if len(names) != len(arm_joints) or len(positions) != len(arm_joints):
        return Rejected(
            "wrong_joint_count",
            f"{len(names)} names and {len(positions)} positions for {len(arm_joints)} arm joints",
        )
    seen: set[str] = set()
    for name in names:
        if name in seen:
            return Rejected("duplicate_joint", f"duplicate joint name {name!r}")
        seen.add(name)
    if seen != set(arm_joints):
        unknown = sorted(seen - set(arm_joints))
        return Rejected(
            "unknown_joint",
            f"joint names {unknown} are not the arm's (the arm's are {list(arm_joints)})",
        )
    if velocities and len(velocities) != len(positions):
        return Rejected(
            "wrong_joint_count", f"{len(velocities)} velocities for {len(positions)} positions"
        )
    # plain floats, not numpy: a 7-joint check at the control rate costs more in numpy's calls
    index = {name: i for i, name in enumerate(names)}
    q = [float(positions[index[j]]) for j in arm_joints]
    if not all(math.isfinite(v) for v in q):
        return Rejected("not_finite", f"positions {q} contain NaN or inf")
    tol = 1e-6
    for j, v in enumerate(q):
        if v < lower[j] - tol or v > upper[j] + tol:
            return Rejected(
                "beyond_limits",
                f"{arm_joints[j]} position {v:.4f} rad outside its limits"
                f" [{lower[j]:.4f}, {upper[j]:.4f}]",
            )
    qd: tuple[float, ...] | None = None
    if velocities:
        v_all = [float(velocities[index[j]]) for j in arm_joints]
        if not all(math.isfinite(v) for v in v_all):
            return Rejected("not_finite", f"velocities {v_all} contain NaN or inf")
        for j, v in enumerate(v_all):
            if abs(v) > velocity_limit[j] + tol:
                return Rejected(
                    "beyond_limits",
                    f"{arm_joints[j]} velocity {v:.4f} rad/s outside its limit"
                    f" [-{velocity_limit[j]:.4f}, {velocity_limit[j]:.4f}]",
                )
        qd = tuple(v_all)
    return JointTarget(positions=tuple(q), velocities=qd)


def validate_gripper(width_m: float, max_opening_m: float) -> float | Rejected:
    """A gripper opening in [0, max_opening_m]."""
    if not math.isfinite(width_m):
        return Rejected("not_finite", f"gripper width {width_m!r}")
    if not -1e-9 <= width_m <= max_opening_m + 1e-9:
        return Rejected(
            "beyond_limits", f"gripper width {width_m:.4f} m outside [0, {max_opening_m:.4f}]"
        )
    return min(max(width_m, 0.0), max_opening_m)


def validate_setpoint(speed_mps: float, max_mps: float = 2.0) -> float | Rejected:
    """A belt speed setpoint in [0, max_mps]."""
    if not math.isfinite(speed_mps):
        return Rejected("not_finite", f"belt setpoint {speed_mps!r}")
    if not 0.0 <= speed_mps <= max_mps:
        return Rejected("bad_setpoint", f"belt setpoint {speed_mps} m/s outside [0, {max_mps}]")
    return speed_mps


def validate_priorities(classes: Sequence[str], known: Sequence[str]) -> tuple[str, ...] | Rejected:
    """A class order naming only known classes, each once."""
    unknown = [c for c in classes if c not in known]
    if unknown:
        return Rejected("unknown_class", f"priorities name unknown classes {unknown}")
    if len(set(classes)) != len(classes):
        return Rejected("duplicate_class", f"priorities repeat a class: {list(classes)}")
    return tuple(classes)


def command_age_s(stamp_s: float, now_s: float) -> float:
    """How long before ``now_s`` a command stamped ``stamp_s`` was meant for (s): 0 for an
    unset stamp (0, "now", as ``JointTrajectory`` has it) or one not in the past. Stamps are
    step times, so the age is rounded to the nanosecond: a command of this step has age 0."""
    if stamp_s <= 0.0:
        return 0.0
    return max(round(now_s - stamp_s, 9), 0.0)


MAX_PHASE_CHARS = 64
"""Longest ``PickTarget.phase`` the twin takes."""


def validate_target(values: Sequence[float], phase: str) -> Rejected | None:
    """A pick target's grasp point and velocity (``values``: x, y, z, vx, vy, vz) all finite
    and its phase at most :data:`MAX_PHASE_CHARS` long; None when it is valid."""
    if all(math.isfinite(x) for x in values) and len(phase) <= MAX_PHASE_CHARS:
        return None
    detail = f"grasp point and velocity {cut(tuple(values))}, phase {cut(phase, 70)}"
    return Rejected("not_finite", detail)


MAX_FAULT_EVENTS_PER_S = 20
"""Refusals of one topic logged as ``fault`` events per second of sim time (the rest are
counted only)."""


class FaultBudget:
    """How many refusals of each topic are logged as faults: the first ``per_s`` of each sim
    second, so a client flooding the twin with bad messages cannot flood its event log."""

    def __init__(self, per_s: int = MAX_FAULT_EVENTS_PER_S) -> None:
        self.per_s = per_s
        self._logged: dict[str, tuple[int, int]] = {}  # topic -> (sim second, logged)

    def admit(self, topic: str, time_s: float) -> bool:
        """Whether a refusal of ``topic`` at sim time ``time_s`` is logged (and count it)."""
        second = int(time_s)
        start, logged = self._logged.get(topic, (second, 0))
        if start != second:
            logged = 0
        if logged >= self.per_s:
            return False
        self._logged[topic] = (second, logged + 1)
        return True


def cut_text(text: str, limit: int = 300) -> str:
    """``text``, at most ``limit`` characters (a refusal's detail may quote a client's
    string)."""
    return text if len(text) <= limit else text[: limit - 3] + "..."
