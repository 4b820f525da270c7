"""Event detection, the grasp approximation and ground truth, evaluated after every physics step.

Grasp approximation (as the reference defines it), per station: contacts come from the contact
points on the links of the station's tool (:mod:`twin.tools`); a small box about its TCP (the
tool's ``tcp_half_extents_m``) is the overlap volume. A pick succeeds when the TCP volume
overlaps the object *and* the tool's grasp rule holds (a parallel jaw: the overlap has lasted
its dwell time, 0.6 s default, and the fingers touch from opposite sides while it presses; a
suction cup: sealed on the object's upturned face and the vacuum built up) *and* the object is
in that station's pick window at that step: on the belt with its centre of mass's x in
``StationSpec.pick_window_x_m``. Should the rule hold for several objects at one step (two
objects side by side between the fingers), the one whose centre of mass is nearest the TCP
horizontally is the one held and credited. A grasp that completes outside the window (past
it, or off the belt, e.g. an object dragged along by the fingers) is not a pick; an object that
left a station's window downstream unpicked is ``missed`` there. The object is then held by a
fixed constraint to the tool's TCP link until the tool lets it go (its carry rule: released as
commanded, slipped out of a jaw, a suction cup overloaded or its seal lost).

Fates and events (every event about a robot or a window names its ``station``):

- ``entered_workspace`` / ``left_workspace``: the object's centre of mass crosses a station's
  pick window while on the belt. Leaving it downstream without having been picked also emits
  ``missed``.
- ``fell_off``: the object dropped below the belt surface outside any bin (over the belt's end
  or its side); it is removed from the scene.
- ``placed_in_bin``: the object came to lie inside a bin (``correct`` when the bin sorts its
  class; ``station`` is the bin's); it is removed from the physics (it is sorted) but keeps its
  ground truth.
- ``pick_dropped``: a held object was let go away from every bin; ``reason`` is the tool's
  (``released``, ``slipped``, ``suction_overload``, ``seal_lost``).
- ``unintended_contact``: a robot link touches an object the robot is not picking (neither held
  by it, nor overlapping its TCP volume, nor within its tool's engaged radius).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from functools import partial

import pybullet as pb

from interfaces.bins import BinSpec
from interfaces.cell import Cell
from interfaces.events import Event, EventType
from twin.ground_truth import GroundTruth
from twin.monitor_records import (
    AtStation,
    Emitter,
    ObjectRecord,
    StationWatch,
    TcpZone,
    station_contacts,
)
from twin.object_truth import MeshCache, landing, mesh_pose, shape_key, truth_of
from twin.placement import Placement
from twin.station import Station
from twin.tools import Candidate, HeldObject, Normal, Pose
from twin.top_view import FloatArray
from twin.world import SpawnedBody, World

_NEAR_TCP_M = 0.25
_NEAR2_M2 = _NEAR_TCP_M**2

LANDING_S = 0.5
"""An object released over a bin this recently and still above its top is landing (a 0.25 m
fall takes 0.23 s)."""

_MAX_SINKING_SPEED_MPS = 1.0
"""Bound on how fast the centre of mass of an object riding the belt can sink towards it."""

_MAX_CLOSING_SPEED_MPS = 4.0
"""Bound on how fast an object riding the belt and a TCP approach each other or a boundary.

An object on the fast path (riding, away from every TCP, untouched) is polled again only when
it could have reached a boundary (belt edge, a pick window's limit, a TCP's near zone) at this
speed, or its centre of mass the belt surface at :data:`_MAX_SINKING_SPEED_MPS`; until then
nothing about it can change. Objects touched by an arm are polled every step, and poses asked
for (ground truth, the target metric) are always read fresh."""


class Monitor:
    """Watches every object of one episode; :meth:`update` returns the step's new events."""

    def __init__(
        self, client: int, cell: Cell, world: World, stations: tuple[Station, ...]
    ) -> None:
        self.client = client
        self.cell = cell
        self.world = world
        self.stations = stations
        self._records: list[ObjectRecord] = []
        self._meshes = MeshCache()
        self._active: list[ObjectRecord] = []  # simulated ones, in spawn order
        self._step = 0
        self._poll_reach_m = _MAX_CLOSING_SPEED_MPS / cell.physics.physics_hz
        self._poll_vertical_ratio = _MAX_CLOSING_SPEED_MPS / _MAX_SINKING_SPEED_MPS
        self._by_body: dict[int, ObjectRecord] = {}
        self._bins: list[tuple[BinSpec, str]] = [(b, s.name) for s in cell.stations for b in s.bins]
        self._watches = tuple(StationWatch.of(station, client) for station in stations)
        self.load_mass_kg = 0.0
        self._pending: list[Event] = []
        self._truth_cache: tuple[GroundTruth, ...] | None = None  # of this step

    def tcp_pose(self, station: int = 0) -> Pose:
        """A station's TCP pose after the last step (no new forward kinematics)."""
        return self._watches[station].tcp_pose

    def add(
        self,
        placement: Placement,
        spawned: SpawnedBody,
        step: int,
        time_s: float,
        *,
        extra: Mapping[str, object] | None = None,
    ) -> Event:
        """Register a freshly spawned object; returns its ``spawned`` event (``extra`` added
        to its data: :class:`twin.spawn_fit.SpawnFit`'s judgement)."""
        qx, qy, qz, qw = spawned.inertial_quat_xyzw
        record = ObjectRecord(
            id=len(self._records) + 1,
            placement=placement,
            body=spawned.body,
            mass_kg=spawned.mass_kg,
            height_m=spawned.height_m,
            inertial_inv=(-qx, -qy, -qz, qw),
            at=[AtStation() for _ in self._watches],
            position=placement.position_m,
            on_belt=True,
        )
        self._records.append(record)
        self._active.append(record)
        self._by_body[spawned.body] = record
        self._truth_cache = None
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
                **(extra or {}),
            },
        )
        self._pending.append(event)
        return event

    def pose_of(self, object_id: int) -> Pose | None:
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

    def poses(self) -> dict[int, Pose]:
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

    def _fresh(self, record: ObjectRecord) -> None:
        """Read the record's pose from the physics unless it was read at this step."""
        if record.polled_step != self._step:
            record.position, record.orientation = pb.getBasePositionAndOrientation(
                record.body, physicsClientId=self.client
            )
            record.polled_step = self._step

    # -- per step ---------------------------------------------------------------------------
    def update(self, step: int, time_s: float) -> list[Event]:
        """Evaluate contacts, overlaps and fates after a physics step.

        Objects riding the belt away from every TCP, untouched, take the fast path here (only
        their pick-window crossings can happen; they are polled again when they could have
        reached a boundary, see :data:`_MAX_CLOSING_SPEED_MPS`); every other object goes
        through every rule (:meth:`_evaluate`). A one-station cell's fast path is written out
        here (it runs for most objects at every step); a line's is :meth:`_ride`.
        """
        events, self._pending = self._pending, []
        emit = Emitter(events, step, time_s)
        for watch in self._watches:
            watch.station.tool.tick(time_s)
        touched, stations = self._read_contacts()
        one = len(stations) == 1
        tcp_x, tcp_y, lo, hi, _ = stations[0]
        belt = self.cell.belt
        surface_z, start_x, end_x = belt.surface_z_m, belt.start_x_m, belt.end_x_m
        centre_y, half_w = belt.centre_y_m, 0.5 * belt.width_m
        get_pose, c = pb.getBasePositionAndOrientation, self.client
        reach_m, vertical = self._poll_reach_m, self._poll_vertical_ratio
        load = 0.0
        self._step = step
        self._truth_cache = None
        for record in tuple(self._active):  # a record may be deactivated in the loop
            if record.next_poll_step > step and record.id not in touched:
                load += record.mass_kg  # still riding the belt
                continue
            pos, orn = get_pose(record.body, physicsClientId=c)
            record.position, record.orientation = pos, orn
            record.polled_step = step
            record.next_poll_step = step + 1
            x, y, z = pos
            margin_m = None
            if (
                record.held_by is None
                and not record.busy
                and record.id not in touched
                and z > surface_z
                and start_x <= x <= end_x
                and abs(y - centre_y) <= half_w
            ):
                if not one:
                    belt_m = min(
                        (z - surface_z) * vertical,
                        x - start_x,
                        end_x - x,
                        half_w - abs(y - centre_y),
                    )
                    margin_m = self._ride(record, emit, belt_m, stations)
                elif (d2 := (x - tcp_x) ** 2 + (y - tcp_y) ** 2) >= _NEAR2_M2:
                    margin_m = min(
                        (z - surface_z) * vertical,
                        x - start_x,
                        end_x - x,
                        half_w - abs(y - centre_y),
                        abs(x - lo),
                        abs(x - hi),
                        math.sqrt(d2) - _NEAR_TCP_M,
                    )
                    if (lo <= x <= hi) != record.at[0].in_window:
                        self._cross(record, 0, x, emit)
            if margin_m is not None:  # riding, away from every TCP: the fast path
                record.on_belt = True
                load += record.mass_kg
                record.next_poll_step = step + max(1, int(margin_m / reach_m))
            elif self._evaluate(record, emit, time_s):
                load += record.mass_kg
        self.load_mass_kg = load
        for watch in self._watches:
            if watch.grasped:
                self._credit(watch, emit, time_s)
        return events

    def _ride(
        self, record: ObjectRecord, emit: Emitter, belt_m: float, stations: tuple[TcpZone, ...]
    ) -> float | None:
        """The fast path of an object riding the belt ``belt_m`` from its edges: None when it
        is near a TCP (the full evaluation follows, and finds the same window crossings in the
        same order), else its pick-window crossings and how far it is from every boundary."""
        x, y, _ = record.position
        margin_m = belt_m
        for tcp_x, tcp_y, lo, hi, s in stations:
            d2 = (x - tcp_x) ** 2 + (y - tcp_y) ** 2
            if d2 < _NEAR2_M2:
                return None
            margin_m = min(margin_m, abs(x - lo), abs(x - hi), math.sqrt(d2) - _NEAR_TCP_M)
            if (lo <= x <= hi) != record.at[s].in_window:
                self._cross(record, s, x, emit)
        return margin_m

    def _cross(self, record: ObjectRecord, s: int, x: float, emit: Emitter) -> None:
        """An object riding the belt crossed station ``s``'s pick window limit."""
        watch, at = self._watches[s], record.at[s]
        if not at.in_window:
            emit(EventType.ENTERED_WORKSPACE, record, x_m=x, station=watch.name)
        else:
            self._left_window(record, watch, at, x, emit)
        at.in_window = not at.in_window

    def _read_contacts(self) -> tuple[set[int], tuple[TcpZone, ...]]:
        """Every tool and arm contact of every station's robot with an object, and the TCPs.

        Returns the ids of the objects a robot touches, and per station its TCP's x and y, its
        pick window's limits and its index (what the fast path needs)."""
        touched: set[int] = set()
        tcps = []
        by_body = self._by_body
        for i, watch in enumerate(self._watches):
            fingers: dict[int, dict[int, Normal]] = {}
            arm: dict[int, set[int]] = {}
            tool_links = watch.station.tool.contact_links
            body = watch.station.robot.body
            for cp in pb.getContactPoints(bodyA=body, physicsClientId=self.client):
                record = by_body.get(cp[2])
                if record is None:
                    continue
                touched.add(record.id)
                finger = tool_links.get(cp[3])
                if finger is not None:
                    fingers.setdefault(record.id, {})[finger] = cp[7]
                else:
                    arm.setdefault(record.id, set()).add(cp[3])
            watch.fingers, watch.arm = fingers, arm
            watch.tcp_pose = tcp = watch.station.tool.tcp_pose()
            tcps.append((tcp[0][0], tcp[0][1], watch.lo_x_m, watch.hi_x_m, i))
        return touched, tuple(tcps)

    def _evaluate(self, record: ObjectRecord, emit: Emitter, time_s: float) -> bool:
        """Every rule for an object off the fast path; whether it lay on the belt at this step
        (before a grasp in it lifts it: its mass is on the belt drive's load this step)."""
        x, y, z = record.position
        over = self._bin_at(x, y)
        if record.held_by is not None:
            self._carry(record, over, emit, time_s)
        if self._fate(record, over, emit):
            return False
        belt = self.cell.belt
        on_belt = (not record.held) and belt.on_belt_xy(x, y) and z > belt.surface_z_m
        record.on_belt = on_belt
        for watch, at in zip(self._watches, record.at, strict=True):
            in_ws = record.on_belt and watch.lo_x_m <= x <= watch.hi_x_m
            if in_ws and not at.in_window:
                emit(EventType.ENTERED_WORKSPACE, record, x_m=x, station=watch.name)
            elif at.in_window and not in_ws:
                self._left_window(record, watch, at, x, emit)
            at.in_window = in_ws
        busy = False
        for watch, at in zip(self._watches, record.at, strict=True):
            busy = self._station_rules(watch, at, record, emit, time_s) or busy
        record.busy = busy
        return on_belt

    def _bin_at(self, x_m: float, y_m: float) -> tuple[BinSpec, str] | None:
        """The first bin (and its station's name) whose inner area holds the point."""
        for entry in self._bins:
            if entry[0].contains_xy(x_m, y_m):
                return entry
        return None

    def _carry(
        self, record: ObjectRecord, over: tuple[BinSpec, str] | None, emit: Emitter, time_s: float
    ) -> None:
        """Let go of a held object once its station's tool does (released, slipped, ...)."""
        assert record.held_by is not None
        watch = self._watches[record.held_by]
        reason = watch.station.tool.carry(time_s)
        if reason is not None:
            self._release(record)
            if over is None:
                emit(
                    EventType.PICK_DROPPED,
                    record,
                    position_m=list(record.position),
                    station=watch.name,
                    reason=reason,
                )

    def _fate(self, record: ObjectRecord, over: tuple[BinSpec, str] | None, emit: Emitter) -> bool:
        """Placed in a bin or fallen off: the object leaves the physics (returns True)."""
        x, _, z = record.position
        if over is not None and not record.held:
            bin_spec, station = over
            if bin_spec.floor_z_m - 0.05 < z < bin_spec.top_z_m:
                record.in_bin = True
                self._deactivate(record)
                emit(
                    EventType.PLACED_IN_BIN,
                    record,
                    bin=bin_spec.class_name,
                    correct=bin_spec.class_name == record.class_name,
                    station=station,
                )
                return True
        belt = self.cell.belt
        falling_into_bin = over is not None and z > self.cell.physics.floor_z_m + 0.05
        if z < belt.surface_z_m - 0.05 and not record.held and not falling_into_bin:
            where = "belt_end" if x > belt.end_x_m else "side"
            for watch, at in zip(self._watches, record.at, strict=True):
                if at.in_window:
                    at.in_window = False
                    emit(EventType.LEFT_WORKSPACE, record, direction="fell", station=watch.name)
            self._deactivate(record)
            emit(EventType.FELL_OFF, record, where=where, position_m=list(record.position))
            return True
        return False

    def _left_window(
        self, record: ObjectRecord, watch: StationWatch, at: AtStation, x: float, emit: Emitter
    ) -> None:
        if record.held:
            direction = "lifted"
        elif x > watch.hi_x_m:
            direction = "downstream"
        elif x < watch.lo_x_m:
            direction = "upstream"
        else:
            direction = "off_belt"
        emit(EventType.LEFT_WORKSPACE, record, direction=direction, x_m=x, station=watch.name)
        if direction == "downstream" and not record.picked and not at.missed:
            at.missed = True
            emit(EventType.MISSED, record, station=watch.name)

    def _station_rules(
        self, watch: StationWatch, at: AtStation, record: ObjectRecord, emit: Emitter, time_s: float
    ) -> bool:
        """TCP overlap, contacts and the grasp of one station; whether it is busy with the
        object (overlapping or touching it). A station whose TCP is not near the object, that
        neither touches it now nor did at the last step, has nothing to say about it (a line's
        other stations, for every object near one TCP): returns at once."""
        x, y, z = record.position
        tcp_pos, tcp_orn = watch.tcp_pose
        overlap = False
        dx, dy = x - tcp_pos[0], y - tcp_pos[1]
        near = dx * dx + dy * dy < _NEAR_TCP_M**2 and abs(z - tcp_pos[2]) < _NEAR_TCP_M
        if not (
            near
            or at.overlap_since is not None
            or at.fingers
            or at.arm_links
            or record.id in watch.fingers
            or record.id in watch.arm
        ):
            return False
        if near:
            overlap = bool(
                pb.getClosestPoints(
                    bodyA=-1,
                    bodyB=record.body,
                    distance=0.0,
                    collisionShapeA=watch.tcp_shape,
                    collisionShapePositionA=tcp_pos,
                    collisionShapeOrientationA=tcp_orn,
                    physicsClientId=self.client,
                )
            )
        if overlap and at.overlap_since is None:
            at.overlap_since = time_s
            emit(EventType.TCP_OVERLAP_START, record, station=watch.name)
        elif not overlap and at.overlap_since is not None:
            at.overlap_since = None
            emit(EventType.TCP_OVERLAP_END, record, station=watch.name)
        tool = watch.station.tool
        engaged = (
            record.held_by == watch.station.index
            or overlap
            or (dx * dx + dy * dy < tool.engaged_radius_m**2)
        )
        touching = station_contacts(watch, at, record, engaged, emit)
        if watch.held is None and record.held_by is None and at.overlap_since is not None:
            candidate = Candidate(
                object_id=record.id,
                time_s=time_s,
                overlap_s=time_s - at.overlap_since,
                touching=touching,
                tcp_pose=watch.tcp_pose,
                shape_key=shape_key(record),
                mesh_pose=partial(mesh_pose, record),
                triangles=partial(self._meshes.triangles, record),
            )
            if tool.grasps(candidate) and at.in_window:
                watch.grasped.append((dx * dx + dy * dy, record, candidate.overlap_s))
        return at.overlap_since is not None or bool(at.fingers) or bool(at.arm_links)

    def _credit(self, watch: StationWatch, emit: Emitter, time_s: float) -> None:
        """The station's tool holds the object it grasps nearest its TCP: attach it, credit
        the pick."""
        _, record, overlap_s = min(watch.grasped, key=lambda g: (g[0], g[1].id))
        watch.grasped.clear()
        if record.held_by is not None:  # another station took it at this step
            return
        self._attach(record, watch, time_s)
        emit(
            EventType.PICK_SUCCESS,
            record,
            dwell_s=overlap_s,
            position_m=list(record.position),
            station=watch.name,
        )

    def _attach(self, record: ObjectRecord, watch: StationWatch, time_s: float) -> None:
        c = self.client
        station = watch.station
        link_pos, link_orn = station.tool.link_pose()
        inv_pos, inv_orn = pb.invertTransform(link_pos, link_orn)
        rel_pos, rel_orn = pb.multiplyTransforms(
            inv_pos, inv_orn, record.position, record.orientation
        )
        record.constraint = pb.createConstraint(
            station.robot.body,
            station.tool.tcp_link,
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
        record.held_by = station.index
        record.picked = True
        record.on_belt = False
        watch.held = record
        station.tool.hold(
            HeldObject(
                object_id=record.id,
                body=record.body,
                class_name=record.class_name,
                mass_kg=record.mass_kg,
                friction=record.placement.friction,
            ),
            time_s,
        )

    def _release(self, record: ObjectRecord) -> None:
        if record.constraint is not None:
            pb.removeConstraint(record.constraint, physicsClientId=self.client)
            record.constraint = None
        if record.held_by is not None:
            watch = self._watches[record.held_by]
            if watch.held is record:
                watch.held = None
                watch.station.tool.release()
        record.held_by = None
        record.released_step = self._step

    def _deactivate(self, record: ObjectRecord) -> None:
        if record.held:
            self._release(record)
        record.active = False
        self._active.remove(record)
        record.on_belt = False
        record.busy = False
        for at in record.at:
            at.in_window = False
            at.overlap_since = None
        self._by_body.pop(record.body, None)
        self.world.remove(record.body)

    def _vertices(self, record: ObjectRecord) -> FloatArray:
        """The object's mesh vertices in its body frame (:class:`twin.object_truth.MeshCache`)."""
        return self._meshes.vertices(record)

    # -- ground truth -----------------------------------------------------------------------
    def landing_in_bins(self) -> list[int]:
        """Ids of objects released over a bin within the last ``LANDING_S`` that have not
        reached it yet (:func:`twin.object_truth.landing`)."""
        since = max(0.0, self._step - LANDING_S * self.cell.physics.physics_hz)
        return landing(self._active, self._bin_at, since_step=since, client=self.client)

    def ground_truth(self) -> tuple[GroundTruth, ...]:
        """Every object that is on the belt, held, or in a bin (not those that fell off).

        Computed once per step (the camera and the ground-truth topic both take it at the
        30 Hz steps): nothing changes an object between two :meth:`update` calls but a spawn.
        """
        if self._truth_cache is None:
            self._truth_cache = tuple(
                self._truth(record) for record in self._records if record.active or record.in_bin
            )
        return self._truth_cache

    def _truth(self, record: ObjectRecord) -> GroundTruth:
        if record.final_truth is not None:
            return record.final_truth
        if not record.active:
            record.final_truth = self._truth_now(record)
            return record.final_truth
        return self._truth_now(record)

    def _truth_now(self, record: ObjectRecord) -> GroundTruth:
        if record.active:
            self._fresh(record)
        vertices: Callable[[], FloatArray] = partial(self._vertices, record)
        return truth_of(record, client=self.client, vertices=vertices)


__all__ = ["LANDING_S", "GroundTruth", "Monitor"]
"""``GroundTruth`` is :mod:`twin.ground_truth`'s, re-exported for the importers of its old home."""
