"""What the monitor (:mod:`twin.monitor`) keeps between steps: one record per object, one
watch per station, and the emitter of a step's events. Mutable state, no behaviour beyond
reading it; kept apart so that the monitor's module holds only its rules.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pybullet as pb

from interfaces.events import Event, EventType
from twin.ground_truth import GroundTruth
from twin.placement import Placement
from twin.station import Station
from twin.tools import Normal, Pose


@dataclass
class AtStation:
    """One object's state with respect to one station."""

    in_window: bool = False
    missed: bool = False
    overlap_since: float | None = None
    fingers: frozenset[int] = frozenset()
    arm_links: frozenset[int] = frozenset()


@dataclass
class ObjectRecord:
    """What the monitor keeps of one object: its placement and body, its state at each station
    (``at``), its last polled pose and its fate so far."""

    id: int
    placement: Placement
    body: int
    mass_kg: float
    height_m: float
    inertial_inv: tuple[float, float, float, float]
    at: list[AtStation]
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    active: bool = True
    on_belt: bool = False
    held_by: int | None = None
    picked: bool = False
    in_bin: bool = False
    busy: bool = False
    """Some station overlaps it or touches it (it stays off the fast path)."""
    constraint: int | None = None
    polled_step: int = -1
    next_poll_step: int = 0
    released_step: int = -1
    final_truth: GroundTruth | None = None
    """Once it is no longer simulated (it lies in a bin), its ground truth does not change."""

    @property
    def held(self) -> bool:
        """Held by some station's tool."""
        return self.held_by is not None

    @property
    def in_workspace(self) -> bool:
        """In some station's pick window."""
        return any(a.in_window for a in self.at)

    @property
    def class_name(self) -> str:
        """The object's class."""
        return self.placement.spec.class_name


@dataclass
class StationWatch:
    """What the monitor keeps of one station between steps."""

    station: Station
    tcp_shape: int
    lo_x_m: float
    hi_x_m: float
    tcp_pose: Pose
    held: ObjectRecord | None = None
    fingers: dict[int, dict[int, Normal]] = field(default_factory=dict)
    arm: dict[int, set[int]] = field(default_factory=dict)
    grasped: list[tuple[float, ObjectRecord, float]] = field(default_factory=list)
    """This step's objects the tool grasps in the pick window: (squared horizontal distance
    from the TCP, record, overlap time)."""

    @classmethod
    def of(cls, station: Station, client: int) -> StationWatch:
        """A station's watch, its TCP box a collision shape of PyBullet's ``client``."""
        return cls(
            station=station,
            tcp_shape=pb.createCollisionShape(
                pb.GEOM_BOX,
                halfExtents=list(station.tool.spec.tcp_half_extents_m),
                physicsClientId=client,
            ),
            lo_x_m=station.spec.pick_window_x_m[0],
            hi_x_m=station.spec.pick_window_x_m[1],
            tcp_pose=station.tool.tcp_pose(),
        )

    @property
    def name(self) -> str:
        """The station's name."""
        return self.station.spec.name


TcpZone = tuple[float, float, float, float, int]
"""A station's TCP x and y, its pick window's limits and its index (for the fast path)."""


class Emitter:
    """Appends one step's events (time and step fixed) to a list."""

    def __init__(self, events: list[Event], step: int, time_s: float) -> None:
        self.events = events
        self.step = step
        self.time_s = time_s

    def __call__(self, kind: EventType, record: ObjectRecord, **data: object) -> None:
        self.events.append(
            Event(
                time_s=self.time_s,
                step=self.step,
                type=kind,
                object_id=record.id,
                class_name=record.class_name,
                data=data,
            )
        )


def station_contacts(
    watch: StationWatch, at: AtStation, record: ObjectRecord, engaged: bool, emit: Emitter
) -> dict[int, Normal]:
    """New tool-link contacts (``finger_contact``) and unintended contacts of the robot;
    returns the tool's contacts with the object (contact link index -> normal)."""
    tool = watch.station.tool
    touching = watch.fingers.get(record.id, {})
    for finger in sorted(set(touching) - at.fingers):
        name = tool.contact_name(finger)
        emit(EventType.FINGER_CONTACT, record, finger=name, station=watch.name)
        if not engaged:
            emit(EventType.UNINTENDED_CONTACT, record, link=name, station=watch.name)
    at.fingers = frozenset(touching)
    links = frozenset(watch.arm.get(record.id, set()))
    if not engaged:
        robot = watch.station.robot
        for link in sorted(links - at.arm_links):
            emit(
                EventType.UNINTENDED_CONTACT,
                record,
                link=robot.link_name(link),
                station=watch.name,
            )
    at.arm_links = links
    return touching


__all__ = ["AtStation", "Emitter", "ObjectRecord", "StationWatch", "TcpZone", "station_contacts"]
