"""Event detection, the grasp approximation and ground truth, evaluated after every physics step.

Grasp approximation (as the reference defines it): finger contacts come from the contact points
on each finger link; a small box around the TCP is the overlap volume. A pick succeeds when the
TCP volume has overlapped the object continuously for the dwell time (0.6 s default) *and* the
fingers touch it from opposite sides (contact normals pointing against each other) while the
gripper presses: its commanded opening is narrower than its measured one (by more than
``GRIP_TOLERANCE_M``; the fingers stop on the object while the target lies inside it, whatever
the object's width) *and* the object is in the pick window at that step: on the belt with its
centre of mass's x in ``[min_x_m, max_x_m]`` (``CellConfig.workspace``). A grasp that completes
outside the window (past it, or off the belt, e.g. an object dragged along by the fingers) is
not a pick; an object that left the window downstream unpicked is ``missed``. The object is
then held by a fixed constraint to the TCP link; it is released once the gripper no longer
presses: commanded no narrower than measured, within half the tolerance (so a jaw-wide object,
which holds the fingers at full opening where commanding "open" cannot exceed the measured
opening, is let go too).

Fates and events:

- ``entered_workspace`` / ``left_workspace``: the object's centre of mass crosses the pick window
  while on the belt. Leaving it downstream without having been picked also emits ``missed``.
- ``fell_off``: the object dropped below the belt surface outside any bin (over the belt's end
  or its side); it is removed from the scene.
- ``placed_in_bin``: the object came to lie inside a bin (``correct`` when the bin sorts its
  class); it is removed from the physics (it is sorted) but keeps its ground truth.
- ``pick_dropped``: a held object was released (or lost) away from every bin.
- ``unintended_contact``: a robot link touches an object the robot is not picking (neither held,
  nor overlapping the TCP volume, nor under the open gripper).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import pybullet as pb

from interfaces.events import Event, EventType
from twin.config import CellConfig
from twin.objects import read_obj_triangles
from twin.robot import Robot
from twin.stream import Placement
from twin.top_view import FloatArray, TopView, top_view
from twin.world import SpawnedBody, World

_NEAR_TCP_M = 0.25

GRIP_TOLERANCE_M = 0.0005
"""How much narrower than the measured opening the gripper must be commanded to count as
pressing (a grip starts)."""

RELEASE_GAP_M = -0.5 * GRIP_TOLERANCE_M
"""Commanded minus measured opening above which a held object is let go: the gripper no longer
presses. Between this and ``-GRIP_TOLERANCE_M`` a grip neither starts nor ends (no flicker)."""

LANDING_S = 0.5
"""An object released over a bin this recently and still above its top is landing (a 0.25 m
fall takes 0.23 s)."""

_MAX_SINKING_SPEED_MPS = 1.0
"""Bound on how fast the centre of mass of an object riding the belt can sink towards it."""

_MAX_CLOSING_SPEED_MPS = 4.0
"""Bound on how fast an object riding the belt and the TCP approach each other or a boundary.

An object on the fast path (riding, away from the TCP, untouched) is polled again only when it
could have reached a boundary (belt edge, workspace limit, the TCP's near zone) at this speed,
or its centre of mass the belt surface at :data:`_MAX_SINKING_SPEED_MPS`;
until then nothing about it can change. Objects touched by the arm are polled every step, and
poses asked for (ground truth, the target metric) are always read fresh."""


@dataclass(frozen=True)
class GroundTruth:
    """The true state of one object (world frame, SI units).

    ``orientation_xyzw`` is the object (mesh) frame's; ``length_m``, ``width_m`` and ``height_m``
    are the object's own extents (footprint and extrusion, whatever way it lies); ``top_view`` is
    what a camera above sees: the heading and extents of the face turned up.
    """

    id: int
    source_id: str
    class_name: str
    position_m: tuple[float, float, float]
    orientation_xyzw: tuple[float, float, float, float]
    linear_velocity_mps: tuple[float, float, float]
    angular_velocity_radps: tuple[float, float, float]
    top_view: TopView
    length_m: float
    width_m: float
    area_m2: float
    volume_m3: float
    height_m: float
    mass_kg: float
    on_belt: bool
    in_workspace: bool
    held: bool
    in_bin: bool


@dataclass
class _Record:
    id: int
    placement: Placement
    body: int
    mass_kg: float
    height_m: float
    inertial_inv: tuple[float, float, float, float]
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    active: bool = True
    on_belt: bool = False
    in_workspace: bool = False
    held: bool = False
    picked: bool = False
    missed: bool = False
    in_bin: bool = False
    overlap_since: float | None = None
    fingers: frozenset[int] = frozenset()
    arm_links: frozenset[int] = frozenset()
    constraint: int | None = None
    polled_step: int = -1
    next_poll_step: int = 0
    released_step: int = -1


class Monitor:
    """Watches every object of one episode; :meth:`update` returns the step's new events."""

    def __init__(self, client: int, cell: CellConfig, world: World, robot: Robot) -> None:
        self.client = client
        self.cell = cell
        self.world = world
        self.robot = robot
        self._records: list[_Record] = []
        self._vertex_cache: dict[tuple[str, float], FloatArray] = {}
        self._active: list[_Record] = []  # simulated ones, in spawn order
        self._step = 0
        self._poll_reach_m = _MAX_CLOSING_SPEED_MPS / cell.physics.physics_hz
        self._poll_vertical_ratio = _MAX_CLOSING_SPEED_MPS / _MAX_SINKING_SPEED_MPS
        self._by_body: dict[int, _Record] = {}
        self._tcp_shape = pb.createCollisionShape(
            pb.GEOM_BOX, halfExtents=list(cell.grasp.tcp_half_extents_m), physicsClientId=client
        )
        self._finger_set = {link: i for i, link in enumerate(robot.finger_links)}
        self.load_mass_kg = 0.0
        self._held: _Record | None = None
        self._pending: list[Event] = []
        self.tcp_pose = robot.tcp_pose()

    def add(self, placement: Placement, spawned: SpawnedBody, step: int, time_s: float) -> Event:
        """Register a freshly spawned object; returns its ``spawned`` event."""
        qx, qy, qz, qw = spawned.inertial_quat_xyzw
        record = _Record(
            id=len(self._records) + 1,
            placement=placement,
            body=spawned.body,
            mass_kg=spawned.mass_kg,
            height_m=spawned.height_m,
            inertial_inv=(-qx, -qy, -qz, qw),
            position=placement.position_m,
            on_belt=True,
        )
        self._records.append(record)
        self._active.append(record)
        self._by_body[spawned.body] = record
        self.load_mass_kg += record.mass_kg
        event = Event(
            time_s=time_s,
            step=step,
            type=EventType.SPAWNED,
            object_id=record.id,
            class_name=placement.spec.class_name,
            data={
                "source_id": placement.spec.object_id,
                "position_m": list(placement.position_m),
                "mass_kg": record.mass_kg,
            },
        )
        self._pending.append(event)
        return event

    def pose_of(
        self, object_id: int
    ) -> tuple[tuple[float, float, float], tuple[float, float, float, float]] | None:
        """True pose (position, mesh-frame xyzw) of a simulated object, None once it is gone."""
        if not 1 <= object_id <= len(self._records):
            return None
        record = self._records[object_id - 1]
        if not record.active:
            return None
        self._fresh(record)
        _, orientation = pb.multiplyTransforms(
            (0.0, 0.0, 0.0), record.orientation, (0.0, 0.0, 0.0), record.inertial_inv
        )
        return record.position, (orientation[0], orientation[1], orientation[2], orientation[3])

    def poses(
        self,
    ) -> dict[int, tuple[tuple[float, float, float], tuple[float, float, float, float]]]:
        """True poses of every simulated object on the belt."""
        out = {}
        for record in self._active:
            self._fresh(record)
            if record.on_belt:
                pose = self.pose_of(record.id)
                if pose is not None:
                    out[record.id] = pose
        return out

    def body_of(self, object_id: int) -> int | None:
        """PyBullet body of a twin object id, if it is still simulated."""
        if 1 <= object_id <= len(self._records):
            record = self._records[object_id - 1]
            return record.body if record.active else None
        return None

    def _fresh(self, record: _Record) -> None:
        """Read the record's pose from the physics unless it was read at this step."""
        if record.polled_step != self._step:
            record.position, record.orientation = pb.getBasePositionAndOrientation(
                record.body, physicsClientId=self.client
            )
            record.polled_step = self._step

    # -- per step ---------------------------------------------------------------------------
    def update(self, step: int, time_s: float) -> list[Event]:
        """Evaluate contacts, overlaps and fates after a physics step."""
        events, self._pending = self._pending, []
        c = self.client
        belt = self.cell.belt
        ws = self.cell.workspace
        fingers: dict[int, dict[int, tuple[float, float, float]]] = {}
        arm: dict[int, set[int]] = {}
        for cp in pb.getContactPoints(bodyA=self.robot.body, physicsClientId=c):
            record = self._by_body.get(cp[2])
            if record is None:
                continue
            finger = self._finger_set.get(cp[3])
            if finger is not None:
                fingers.setdefault(record.id, {})[finger] = cp[7]
            else:
                arm.setdefault(record.id, set()).add(cp[3])
        self.tcp_pose = self.robot.tcp_pose()
        tcp_pos, tcp_orn = self.tcp_pose
        load = 0.0

        def emit(kind: EventType, record: _Record, **data: object) -> None:
            events.append(
                Event(
                    time_s=time_s,
                    step=step,
                    type=kind,
                    object_id=record.id,
                    class_name=record.placement.spec.class_name,
                    data=dict(data),
                )
            )

        surface_z = belt.surface_z_m
        start_x, end_x = belt.start_x_m, belt.end_x_m
        centre_y, half_w = belt.centre_y_m, 0.5 * belt.width_m
        ws_lo, ws_hi = ws.min_x_m, ws.max_x_m
        tcp_x, tcp_y = tcp_pos[0], tcp_pos[1]
        near2 = _NEAR_TCP_M**2
        get_pose = pb.getBasePositionAndOrientation
        reach_m = self._poll_reach_m
        self._step = step
        for record in tuple(self._active):  # a record may be deactivated in the loop
            if record.next_poll_step > step and record.id not in fingers and record.id not in arm:
                load += record.mass_kg  # still riding the belt (see _MAX_CLOSING_SPEED_MPS)
                continue
            pos, orn = get_pose(record.body, physicsClientId=c)
            record.position, record.orientation = pos, orn
            record.polled_step = step
            record.next_poll_step = step + 1
            x, y, z = pos
            # fast path: riding the belt, away from the robot, nothing to detect but the window
            if (
                not record.held
                and z > surface_z
                and start_x <= x <= end_x
                and abs(y - centre_y) <= half_w
                and (x - tcp_x) ** 2 + (y - tcp_y) ** 2 >= near2
                and record.overlap_since is None
                and not record.fingers
                and not record.arm_links
                and record.id not in fingers
                and record.id not in arm
            ):
                record.on_belt = True
                load += record.mass_kg
                in_ws = ws_lo <= x <= ws_hi
                if in_ws != record.in_workspace:
                    if in_ws:
                        emit(EventType.ENTERED_WORKSPACE, record, x_m=x)
                    else:
                        self._left_workspace(record, x, emit)
                    record.in_workspace = in_ws
                margin_m = min(
                    (z - surface_z) * self._poll_vertical_ratio,
                    x - start_x,
                    end_x - x,
                    half_w - abs(y - centre_y),
                    abs(x - ws_lo),
                    abs(x - ws_hi),
                    math.sqrt((x - tcp_x) ** 2 + (y - tcp_y) ** 2) - _NEAR_TCP_M,
                )
                record.next_poll_step = step + max(1, int(margin_m / reach_m))
                continue
            over = self.cell.bin_at(x, y)
            # -- release of a held object
            if record.held and self._grip_gap_m() > RELEASE_GAP_M:
                self._release(record)
                if over is None:
                    emit(EventType.PICK_DROPPED, record, position_m=list(pos))
            # -- fates
            bin_hit = None
            if over is not None and over.floor_z_m - 0.05 < z < over.top_z_m:
                bin_hit = over
            if bin_hit is not None and not record.held:
                record.in_bin = True
                self._deactivate(record)
                emit(
                    EventType.PLACED_IN_BIN,
                    record,
                    bin=bin_hit.class_name,
                    correct=bin_hit.class_name == record.placement.spec.class_name,
                )
                continue
            falling_into_bin = over is not None and z > self.cell.physics.floor_z_m + 0.05
            if z < belt.surface_z_m - 0.05 and not record.held and not falling_into_bin:
                where = "belt_end" if x > belt.end_x_m else "side"
                if record.in_workspace:
                    record.in_workspace = False
                    emit(EventType.LEFT_WORKSPACE, record, direction="fell")
                self._deactivate(record)
                emit(EventType.FELL_OFF, record, where=where, position_m=list(pos))
                continue
            record.on_belt = (not record.held) and belt.on_belt_xy(x, y) and z > belt.surface_z_m
            if record.on_belt:
                load += record.mass_kg
            in_ws = record.on_belt and ws.min_x_m <= x <= ws.max_x_m
            if in_ws and not record.in_workspace:
                emit(EventType.ENTERED_WORKSPACE, record, x_m=x)
            elif record.in_workspace and not in_ws:
                self._left_workspace(record, x, emit)
            record.in_workspace = in_ws
            # -- TCP overlap
            overlap = False
            dx, dy = x - tcp_pos[0], y - tcp_pos[1]
            if dx * dx + dy * dy < _NEAR_TCP_M**2 and abs(z - tcp_pos[2]) < _NEAR_TCP_M:
                overlap = bool(
                    pb.getClosestPoints(
                        bodyA=-1,
                        bodyB=record.body,
                        distance=0.0,
                        collisionShapeA=self._tcp_shape,
                        collisionShapePositionA=tcp_pos,
                        collisionShapeOrientationA=tcp_orn,
                        physicsClientId=c,
                    )
                )
            if overlap and record.overlap_since is None:
                record.overlap_since = time_s
                emit(EventType.TCP_OVERLAP_START, record)
            elif not overlap and record.overlap_since is not None:
                record.overlap_since = None
                emit(EventType.TCP_OVERLAP_END, record)
            # -- finger and arm contacts
            touching = fingers.get(record.id, {})
            engaged = (
                record.held or overlap or (dx * dx + dy * dy < self.robot.config.max_opening_m**2)
            )
            for finger in sorted(set(touching) - record.fingers):
                emit(
                    EventType.FINGER_CONTACT, record, finger=self.robot.config.finger_links[finger]
                )
                if not engaged:
                    emit(
                        EventType.UNINTENDED_CONTACT,
                        record,
                        link=self.robot.config.finger_links[finger],
                    )
            record.fingers = frozenset(touching)
            links = frozenset(arm.get(record.id, set()))
            if not engaged:
                for link in sorted(links - record.arm_links):
                    emit(EventType.UNINTENDED_CONTACT, record, link=self._link_name(link))
            record.arm_links = links
            # -- pick success: only in the pick window (on the belt, centre of mass inside)
            if (
                self._held is None
                and in_ws
                and record.overlap_since is not None
                and time_s - record.overlap_since >= self.cell.grasp.dwell_s - 1e-9
                and self._opposite(touching)
                and self._grip_gap_m() < -GRIP_TOLERANCE_M
            ):
                self._attach(record, tcp_pos, tcp_orn)
                emit(
                    EventType.PICK_SUCCESS,
                    record,
                    dwell_s=time_s - record.overlap_since,
                    position_m=list(pos),
                )
        self.load_mass_kg = load
        return events

    def _left_workspace(self, record: _Record, x: float, emit: Callable[..., None]) -> None:
        ws = self.cell.workspace
        if record.held:
            direction = "lifted"
        elif x > ws.max_x_m:
            direction = "downstream"
        elif x < ws.min_x_m:
            direction = "upstream"
        else:
            direction = "off_belt"
        emit(EventType.LEFT_WORKSPACE, record, direction=direction, x_m=x)
        if direction == "downstream" and not record.picked and not record.missed:
            record.missed = True
            emit(EventType.MISSED, record)

    def _grip_gap_m(self) -> float:
        """Commanded minus measured gripper opening: below ``-GRIP_TOLERANCE_M`` the fingers press
        (a grip on an object wider than half the opening is a grip too), above
        ``RELEASE_GAP_M`` they let go. Read only where a grasp or release is decided."""
        return self.robot.gripper_width_target_m - self.robot.gripper_width_m()

    def _opposite(self, touching: dict[int, tuple[float, float, float]]) -> bool:
        if len(self.robot.finger_links) < 2 or len(touching) < len(self.robot.finger_links):
            return False
        normals = list(touching.values())
        dot = sum(a * b for a, b in zip(normals[0], normals[1], strict=True))
        return dot < 0.0

    def _link_name(self, link: int) -> str:
        if link < 0:
            return "base"
        info = pb.getJointInfo(self.robot.body, link, physicsClientId=self.client)
        return str(info[12].decode())

    def _attach(
        self,
        record: _Record,
        tcp_pos: tuple[float, float, float],
        tcp_orn: tuple[float, float, float, float],
    ) -> None:
        c = self.client
        inv_pos, inv_orn = pb.invertTransform(tcp_pos, tcp_orn)
        rel_pos, rel_orn = pb.multiplyTransforms(
            inv_pos, inv_orn, record.position, record.orientation
        )
        record.constraint = pb.createConstraint(
            self.robot.body,
            self.robot.tcp_link,
            record.body,
            -1,
            pb.JOINT_FIXED,
            [0.0, 0.0, 0.0],
            parentFramePosition=rel_pos,
            childFramePosition=[0.0, 0.0, 0.0],
            parentFrameOrientation=rel_orn,
            physicsClientId=c,
        )
        pb.changeConstraint(record.constraint, maxForce=500.0, physicsClientId=c)
        record.held = True
        record.picked = True
        record.on_belt = False
        self._held = record

    def _release(self, record: _Record) -> None:
        if record.constraint is not None:
            pb.removeConstraint(record.constraint, physicsClientId=self.client)
            record.constraint = None
        record.held = False
        record.released_step = self._step
        if self._held is record:
            self._held = None

    def _deactivate(self, record: _Record) -> None:
        if record.held:
            self._release(record)
        record.active = False
        self._active.remove(record)
        record.on_belt = False
        record.in_workspace = False
        record.overlap_since = None
        self._by_body.pop(record.body, None)
        self.world.remove(record.body)

    def _vertices(self, record: _Record) -> FloatArray:
        """The object's mesh vertices in its body frame, m (z scaled to its height); cached."""
        spec = record.placement.spec
        key = (str(spec.mesh_path), record.height_m)
        vertices = self._vertex_cache.get(key)
        if vertices is None:
            vertices = read_obj_triangles(spec.mesh_path).reshape(-1, 3)
            vertices[:, 2] *= record.height_m / spec.height_m
            self._vertex_cache[key] = vertices
        return vertices

    # -- ground truth -----------------------------------------------------------------------
    def landing_in_bins(self) -> list[int]:
        """Ids of objects released over a bin within the last ``LANDING_S`` that have not
        reached it yet (below its top): their fate is not decided at this instant, so an episode
        that ends now counts them neither placed nor lost. (An object left lying on a bin's rim
        for longer is not landing.)"""
        c = self.client
        recent = self._step - LANDING_S * self.cell.physics.physics_hz
        ids: list[int] = []
        for record in self._active:
            if record.held or record.in_bin or record.released_step < max(0.0, recent):
                continue
            (x, y, z), _ = pb.getBasePositionAndOrientation(record.body, physicsClientId=c)
            over = self.cell.bin_at(x, y)
            if over is not None and z >= over.top_z_m:
                ids.append(record.id)
        return ids

    def ground_truth(self) -> tuple[GroundTruth, ...]:
        """Every object that is on the belt, held, or in a bin (not those that fell off)."""
        out = []
        for record in self._records:
            if not record.active and not record.in_bin:
                continue
            if record.active:
                self._fresh(record)
                lin, ang = pb.getBaseVelocity(record.body, physicsClientId=self.client)
            else:
                lin, ang = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
            spec = record.placement.spec
            scale = record.height_m / spec.height_m
            _, orientation = pb.multiplyTransforms(
                (0.0, 0.0, 0.0), record.orientation, (0.0, 0.0, 0.0), record.inertial_inv
            )
            out.append(
                GroundTruth(
                    id=record.id,
                    source_id=spec.object_id,
                    class_name=spec.class_name,
                    position_m=record.position,
                    orientation_xyzw=tuple(orientation),
                    linear_velocity_mps=tuple(lin),
                    angular_velocity_radps=tuple(ang),
                    top_view=top_view(
                        orientation,
                        spec.yaw_rad,
                        length_m=spec.length_m,
                        width_m=spec.width_m,
                        height_m=record.height_m,
                        vertices_m=partial(self._vertices, record),
                    ),
                    length_m=spec.length_m,
                    width_m=spec.width_m,
                    area_m2=spec.area_m2,
                    volume_m3=spec.volume_m3 * scale,
                    height_m=record.height_m,
                    mass_kg=record.mass_kg,
                    on_belt=record.on_belt,
                    in_workspace=record.in_workspace,
                    held=record.held,
                    in_bin=record.in_bin,
                )
            )
        return tuple(out)
