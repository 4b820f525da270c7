"""Tools a station's robot carries: what the twin simulates and a controller plans with.

Each kind of tool is one frozen dataclass here (its physical model documented on it), one
module on the twin's side (``twin/tools/``) and one on the controller's (``control/tools/``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from interfaces.catalog import entry
from interfaces.dataclass_io import from_data
from interfaces.errors import ConfigError, require


@dataclass(frozen=True, kw_only=True)
class ParallelJawSpec:
    """A parallel-jaw gripper built into the robot's URDF (the Panda hand, the xArm gripper).

    Fingers: ``joints`` (one per finger) move linearly from ``joint_closed`` to ``joint_open`` as
    the opening goes from 0 to ``max_opening_m``; ``links`` are the finger links whose contacts
    decide a grasp. The TCP is ``tcp_link`` (plus ``tcp_offset_m`` in that link's frame).
    Grasp rule (the reference's): both fingers touch the object from opposite sides while the
    gripper presses and a box of half extents ``tcp_half_extents_m`` about the TCP has overlapped
    the object for ``dwell_s``. What the controller plans with: objects lower than
    ``pad_height_m`` are too flat for the finger pads; the fingers are ``finger_width_m`` wide
    and ``finger_depth_m`` thick; the hand is ``hand_width_m`` by ``hand_depth_m`` with its palm
    ``palm_above_tcp_m`` above the TCP. ``min_finger_force_N`` is the least motor force of a
    finger joint (URDFs that give none).
    """

    kind: Literal["parallel_jaw"] = "parallel_jaw"
    name: str
    tcp_link: str
    tcp_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    joints: tuple[str, ...]
    links: tuple[str, ...]
    joint_open: tuple[float, ...]
    joint_closed: tuple[float, ...]
    max_opening_m: float
    dwell_s: float = 0.6
    tcp_half_extents_m: tuple[float, float, float] = (0.01, 0.01, 0.02)
    pad_height_m: float = 0.02
    finger_width_m: float = 0.02
    finger_depth_m: float = 0.012
    hand_width_m: float = 0.21
    hand_depth_m: float = 0.072
    palm_above_tcp_m: float = 0.035
    min_finger_force_N: float = 20.0

    def __post_init__(self) -> None:
        n = len(self.joints)
        require(n > 0, "tool.joints", self.joints, "must not be empty")
        require(len(self.joint_open) == n, "tool.joint_open", self.joint_open, "one per joint")
        require(
            len(self.joint_closed) == n, "tool.joint_closed", self.joint_closed, "one per joint"
        )
        require(self.max_opening_m > 0, "tool.max_opening_m", self.max_opening_m, "must be > 0")
        require(self.dwell_s >= 0, "tool.dwell_s", self.dwell_s, "must be >= 0")
        require(
            all(v > 0 for v in self.tcp_half_extents_m),
            "tool.tcp_half_extents_m",
            self.tcp_half_extents_m,
            "must be positive",
        )
        for key in (
            "pad_height_m",
            "finger_width_m",
            "finger_depth_m",
            "hand_width_m",
            "hand_depth_m",
            "palm_above_tcp_m",
        ):
            value: float = getattr(self, key)
            require(value >= 0, f"tool.{key}", value, "must be >= 0")


ToolSpec = ParallelJawSpec
"""Every kind of tool a station may carry (a union as more kinds are added)."""

TOOL_KINDS: dict[str, type[ToolSpec]] = {"parallel_jaw": ParallelJawSpec}
"""Tool classes by their ``kind``."""


def tool_from_data(value: object, where: str) -> ToolSpec:
    """A tool from a catalogue name or a mapping; ``kind`` chooses its class."""
    data = entry(value, "tools", where)
    if not isinstance(data, dict):
        msg = f"{where} = {data!r}: expected a tool name or a mapping"
        raise ConfigError(msg)
    kind = data.get("kind", "parallel_jaw")
    if kind not in TOOL_KINDS:
        msg = f"{where}.kind = {kind!r}: unknown tool kind (known: {', '.join(TOOL_KINDS)})"
        raise ConfigError(msg)
    return from_data(TOOL_KINDS[kind], data, where)
