"""Tools a station's robot carries: what the twin simulates and a controller plans with.

Each kind of tool is one frozen dataclass here (its physical model documented on it), one
module on the twin's side (``twin/tools/``) and one on the controller's (``control/tools/``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

from interfaces.catalog import entry, is_part_name, missing_fields
from interfaces.dataclass_io import from_data
from interfaces.errors import ConfigError, cut, require

if TYPE_CHECKING:
    from interfaces.materials import ClassTable


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

    ``mount``: ``builtin`` grippers come with the robot's URDF (the Panda hand, the xArm
    gripper); a ``flange`` gripper is added to the robot's flange by
    :func:`interfaces.urdf.station_urdf`: a palm ``hand_width_m`` x ``hand_depth_m`` x
    ``palm_height_m``, two fingers ``finger_length_m`` long on prismatic joints along the TCP's
    y axis (0 closed, ``max_opening_m / 2`` each open), the TCP between the fingertips, half a
    pad height above their tips. ``grip_force_N``: the force the fingers press with. With it, a
    held object slips out (``pick_dropped``, reason ``slipped``) once the friction the two pads
    can carry, ``2 mu grip_force_N``, is less than ``mass (g + |a|)`` (``mu`` the object's
    friction coefficient, ``a`` the TCP's measured acceleration); without it (None) a grasp
    holds whatever the object, as the reference's rule does.
    """

    kind: Literal["parallel_jaw"] = "parallel_jaw"
    name: str
    mount: Literal["builtin", "flange"] = "builtin"
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
    grip_force_N: float | None = None
    palm_height_m: float = 0.06
    finger_length_m: float = 0.08

    def __post_init__(self) -> None:
        _check_name(self.name)
        n = len(self.joints)
        if self.grip_force_N is not None:
            require(
                0 < self.grip_force_N <= MAX_FORCE_N,
                "tool.grip_force_N",
                self.grip_force_N,
                f"must be in (0, {MAX_FORCE_N:g}] N",
            )
        require(
            0 < self.min_finger_force_N <= MAX_FORCE_N,
            "tool.min_finger_force_N",
            self.min_finger_force_N,
            f"must be in (0, {MAX_FORCE_N:g}] N",
        )
        if self.mount == "flange":
            for key in ("palm_height_m", "finger_length_m", "finger_width_m", "finger_depth_m"):
                size: float = getattr(self, key)
                require(size > 0, f"tool.{key}", size, "must be > 0 (a flange gripper's part)")
            require(n == 2, "tool.joints", self.joints, "a flange-mounted jaw has two fingers")
            require(len(self.links) == 2, "tool.links", self.links, "two finger links")
        require(n > 0, "tool.joints", self.joints, "must not be empty")
        require(len(self.joint_open) == n, "tool.joint_open", self.joint_open, "one per joint")
        require(
            len(self.joint_closed) == n, "tool.joint_closed", self.joint_closed, "one per joint"
        )
        require(
            0 < self.max_opening_m <= MAX_SIZE_M,
            "tool.max_opening_m",
            self.max_opening_m,
            f"must be in (0, {MAX_SIZE_M:g}] m",
        )
        require(
            0 <= self.dwell_s <= MAX_TIME_S,
            "tool.dwell_s",
            self.dwell_s,
            f"must be in [0, {MAX_TIME_S:g}] s",
        )
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
            require(
                0 <= value <= MAX_SIZE_M, f"tool.{key}", value, f"must be in [0, {MAX_SIZE_M:g}] m"
            )


@dataclass(frozen=True, kw_only=True)
class SuctionCupSpec:
    """A single vacuum suction cup on the robot's flange, what industrial waste pickers mostly
    use.

    Geometry (added to the flange by :func:`interfaces.urdf.station_urdf`): a stem of radius
    ``body_radius_m`` from the flange to the cup's lip, ``stem_length_m`` along the flange's z
    axis; the TCP is the centre of the lip; the cup's lip is a disc of ``cup_diameter_m``.

    Seal: with the vacuum on, the cup seals on an object when its lip lies on the object's
    upturned face (within ``contact_tolerance_m`` of it), the whole lip disc lies within that
    face at the contact point (the extruded proxies have flat tops; a tipped object is judged
    by the face turned up), and the face is tilted by at most ``max_tilt_rad``. The vacuum then
    builds up for ``build_up_s`` (generator and hose volume) and the object is held: this is
    the suction cup's grasp rule (it replaces the fingers' contacts and dwell).

    Holding force (the theoretical holding force of a suction cup, F = dp A, Schmalz, "Holding
    force", and "Theoretical holding force of a suction cup", schmalz.com): ``F = vacuum_kPa *
    1000 * pi (cup_diameter_m / 2)^2 * eta``, ``eta`` the seal efficiency of the object's class
    (:meth:`efficiency`): the fraction of the vacuum a cup keeps on that surface, a fact of the
    class table (:mod:`interfaces.materials`: porous, rough and heterogeneous surfaces leak,
    so concrete and brick keep less than rubber) unless this tool overrides it per class
    (``seal_efficiency``) or for every class it does not name (``default_seal_efficiency``;
    None: the table's). Every physics step of the carry, ``F`` is
    checked against ``mass (g + |a|)`` with ``a`` the TCP's measured acceleration: exceeded,
    the object drops (``pick_dropped``, reason ``suction_overload``). Vacuum off vents the cup
    in ``vent_s``; the object is released.

    Command (``gripper/command``): 1 turns the vacuum on, 0 off. Measured (``joint_states``,
    joint ``<name>_vacuum``): the vacuum reached, as a fraction of ``vacuum_kPa`` (0 to 1), as a
    vacuum switch would report it.
    """

    kind: Literal["suction_cup"] = "suction_cup"
    name: str
    mount: Literal["flange"] = "flange"
    tcp_link: str
    tcp_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    cup_diameter_m: float = 0.04
    stem_length_m: float = 0.15
    body_radius_m: float = 0.025
    vacuum_kPa: float = 60.0
    seal_efficiency: dict[str, float] = field(default_factory=dict)
    default_seal_efficiency: float | None = None
    build_up_s: float = 0.15
    vent_s: float = 0.05
    max_tilt_rad: float = 0.35
    contact_tolerance_m: float = 0.004
    tcp_half_extents_m: tuple[float, float, float] = (0.01, 0.01, 0.01)

    def __post_init__(self) -> None:
        _check_name(self.name)
        for key, high in (
            ("cup_diameter_m", MAX_SIZE_M),
            ("stem_length_m", MAX_SIZE_M),
            ("body_radius_m", MAX_SIZE_M),
            ("vacuum_kPa", ATMOSPHERE_KPA),
            ("build_up_s", MAX_TIME_S),
            ("vent_s", MAX_TIME_S),
            ("max_tilt_rad", 0.5 * math.pi),
            ("contact_tolerance_m", MAX_SIZE_M),
        ):
            value: float = getattr(self, key)
            require(0 < value <= high, f"tool.{key}", value, f"must be in (0, {high:g}]")
        require(
            all(v > 0 for v in self.tcp_half_extents_m),
            "tool.tcp_half_extents_m",
            self.tcp_half_extents_m,
            "must be positive",
        )
        for name, eta in self.seal_efficiency.items():
            require(0 < eta <= 1, f"tool.seal_efficiency.{name}", eta, "must be in (0, 1]")
        if self.default_seal_efficiency is not None:
            require(
                0 < self.default_seal_efficiency <= 1,
                "tool.default_seal_efficiency",
                self.default_seal_efficiency,
                "must be in (0, 1] (or null: the class table's)",
            )

    @property
    def cup_area_m2(self) -> float:
        """Area of the cup's lip disc."""
        return math.pi * (0.5 * self.cup_diameter_m) ** 2

    def efficiency(self, class_name: str, materials: ClassTable) -> float:
        """The seal efficiency on objects of ``class_name``: this tool's ``seal_efficiency``
        for it, else its ``default_seal_efficiency``, else the class table's
        (``materials``, :meth:`interfaces.materials.ClassTable.material`)."""
        if class_name in self.seal_efficiency:
            return self.seal_efficiency[class_name]
        if self.default_seal_efficiency is not None:
            return self.default_seal_efficiency
        return materials.material(class_name).seal_efficiency

    def holding_force(self, class_name: str, materials: ClassTable) -> float:
        """The force (N) the sealed cup holds an object of ``class_name`` with (its seal
        efficiency from :meth:`efficiency`)."""
        eta = self.efficiency(class_name, materials)
        return self.vacuum_kPa * 1000.0 * self.cup_area_m2 * eta

    @property
    def vacuum_joint(self) -> str:
        """The name ``joint_states`` reports the measured vacuum fraction under."""
        return f"{self.name}_vacuum"


MAX_SIZE_M = 1.0
"""Largest length of a tool's part (an opening, a cup, a stem, a finger), m."""

MAX_TIME_S = 60.0
"""Longest time constant of a tool (dwell, vacuum build-up, venting), s."""

MAX_FORCE_N = 10_000.0
"""Largest force of a tool's finger or grip, N."""

ATMOSPHERE_KPA = 101.325
"""Standard atmospheric pressure: a vacuum below ambient cannot exceed it."""


def _check_name(name: str) -> None:
    require(
        is_part_name(name),
        "tool.name",
        name,
        "1 to 64 letters, digits, '_', '-' or '.', not starting with '.'",
    )


ToolSpec = ParallelJawSpec | SuctionCupSpec
"""Every kind of tool a station may carry."""

TOOL_KINDS: dict[str, type[ParallelJawSpec] | type[SuctionCupSpec]] = {
    "parallel_jaw": ParallelJawSpec,
    "suction_cup": SuctionCupSpec,
}
"""Tool classes by their ``kind``."""


def tool_from_data(value: object, where: str) -> ToolSpec:
    """A tool from a catalogue name or a mapping; ``kind`` chooses its class."""
    data = entry(value, "tools", where)
    if not isinstance(data, dict):
        msg = f"{where} = {cut(data)}: expected a tool name or a mapping"
        raise ConfigError(msg)
    kind = data.get("kind", "parallel_jaw")
    if not isinstance(kind, str) or kind not in TOOL_KINDS:
        msg = f"{where}.kind = {cut(kind)}: unknown tool kind (known: {', '.join(TOOL_KINDS)})"
        raise ConfigError(msg)
    missing_fields(TOOL_KINDS[kind], data, where, "tool")
    tool: ToolSpec = from_data(TOOL_KINDS[kind], data, where)
    return tool
