"""The twin as a ROS 2 node: a thin shell around :class:`twin.sim.Twin`.

It converts messages to domain values and back and calls the twin; there is no simulation logic
here. Every topic's name, type and QoS comes from :mod:`interfaces.contract` (documented in
``docs/interfaces.md``): the cell topics once, the station topics once per station of the cell
under the station's namespace (``/s1/joint_states``; the bare name for the empty namespace of a
one-station cell). The loop runs in one thread: it serves callbacks (commands, pings) while
waiting for the next physics step, so a ping is echoed at once, from inside the step loop.

With a tap (:data:`Tap`), every message the node publishes is serialized once, published as
those bytes and handed to the tap; every message it subscribes to arrives as bytes, goes to the
tap and is deserialized for its callback. The tap sees the whole contract, both directions, but
the latched ``cell/bins`` (static configuration, published once at start).

``/events`` carries every event the twin logs, in the order of :attr:`twin.sim.Twin.events`:
the monitor's, rejected commands, controller timeouts and injected faults alike.

Claims: the node keeps the line's claims board (:class:`twin.claims.ClaimsBoard`: one entry per
station and track, from each station's ``line/claim``, every field checked, bounded per station
and in total) and relays it on ``/line/claims`` after every step in which it changed, a counted
topic of the tick; it allocates nothing.

The node trusts no client. Over ROS 2 every subscription takes the serialized bytes, and a
message longer than its topic's bound (:func:`max_message_bytes`) is refused before it is
decoded into Python objects (fault ``oversized``); what a message may cost afterwards is
bounded by that size. Every refusal is counted (``rejected_commands`` of the summary); the
first :data:`MAX_FAULT_EVENTS_PER_S` of each topic per second of sim time are also ``fault``
events on ``/events`` and ``/faults``, the rest counted only (``unlogged_rejections``), so a
client flooding the twin with bad messages cannot flood its event log.

Scene (``docs/interfaces.md``, :mod:`twin.scene`): ``/tf`` (every link of every station, each
TCP, every object in the simulation; at the ground-truth tick), ``/tf_static`` (each station's
root link), ``/scene/markers`` (belt, bins, robot links; once), ``/scene/objects`` (every live
object's mesh, re-sent whole when the set changes, and a DELETE for each one gone) and
``/scene/targets`` (each station's announced target and TCP path, at :data:`SCENE_TARGETS_HZ`),
sent only while a tap exists or some subscriber is matched, and not at all with
``scene=False``.

Modes: ``realtime`` paces the physics to the wall clock; ``lockstep`` steps tick k+1 only when
every station's controller has acknowledged tick k (see the LockstepTick/StepAck handshake in
the docs).
"""

from __future__ import annotations

import gc
import json
import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Protocol, TypedDict, Unpack

from cdw_interfaces.msg import (
    BeltState,
    Claim,
    ClaimArray,
    Detection,
    DetectionArray,
    LockstepTick,
    ObjectStateArray,
    PickTarget,
    Ping,
    SortingBin,
    SortingBins,
    SortingEvent,
    SortingPriorities,
    StepAck,
)
from geometry_msgs.msg import Point, PoseStamped
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import Marker, MarkerArray

from interfaces import cdr
from interfaces import contract as c
from interfaces.class_colours import class_colour
from interfaces.contract import Topic
from interfaces.detections import Detection as PerceivedDetection
from interfaces.detections import DetectionFrame
from interfaces.errors import cut
from interfaces.events import Event
from interfaces.inproc import Bus, InprocLogger, WireExact
from interfaces.ros import RosWire, message_class, msg_stamp_ns, msg_stamp_s, time_msg
from twin import scene as sc
from twin.claims import ClaimFields, ClaimsBoard
from twin.commands import (
    JointTarget,
    Rejected,
    command_age_s,
    validate_gripper,
    validate_joint_command,
    validate_priorities,
    validate_setpoint,
)
from twin.link_visuals import link_visuals
from twin.monitor import GroundTruth
from twin.sim import ArmCommand, Twin
from twin.station import Station
from twin.target_metric import PURSUIT_PHASES
from twin.telemetry import TelemetryRecorder

Tap = Callable[[str, bytes, int], None]
"""Takes every message the node sends or receives: topic, serialized CDR bytes, wall time (ns
since the Unix epoch) of the send or receipt. ``cdw-twin run`` records the episode's MCAP this
way, in the twin's process (see ``twin-node --record``)."""

TapWants = Callable[[str], bool]
"""Whether the tap takes a topic (its wire name) now. The live view alone takes only what a
client subscribed to: the node then builds the ground truth and the scene only for a client."""


class EndpointOptions(TypedDict, total=False):
    """The twin endpoint's options besides the twin and the mode (:meth:`TwinEndpoint._setup`)."""

    state_every: int
    ground_truth_every: int
    tap: Tap | None
    tap_wants: TapWants | None
    scene: bool


@dataclass
class NodeCounters:
    """What the node has seen and done; written to the episode log. ``unlogged`` counts the
    refusals beyond :data:`MAX_FAULT_EVENTS_PER_S` that were not logged as events."""

    published: Counter[str]
    received_commands: int = 0
    rejected: Counter[str] = field(default_factory=Counter)
    lockstep_timeouts: int = 0
    unlogged: int = 0


DEFAULT_MAX_MESSAGE_BYTES = 4096
"""Longest serialized message the twin takes on a subscribed topic without its own bound
(a claim, a pick target, an ack, a ping, a gripper command or a setpoint is under 300 bytes)."""

MAX_MESSAGE_BYTES: dict[str, int] = {
    c.ARM_TRAJECTORY.name: 65_536,
    c.PRIORITIES.name: 16_384,
}
"""Longest serialized message per topic (its contract name) where the default is too small:
a one-point trajectory of 7 joints is about 300 bytes, a priority list of every class of a
dataset under 1 kB."""

MAX_FAULT_EVENTS_PER_S = 20
"""Refusals of one topic logged as ``fault`` events per second of sim time (the rest are
counted only)."""

MAX_ACKS_AHEAD = 10_000
"""Farthest ahead of the current tick an acknowledgement is kept (a controller acknowledges the
tick it handled); beyond, it is refused (``bad_ack``)."""


def max_message_bytes(topic: Topic) -> int:
    """The longest serialized message the twin takes on ``topic``."""
    return MAX_MESSAGE_BYTES.get(topic.name, DEFAULT_MAX_MESSAGE_BYTES)


@dataclass
class StationLink:
    """One station's side of the node: its topics, its controller's commands and acks.

    ``pending`` counts commands received and not yet consumed by an acknowledged tick;
    ``next_tick`` is the controller's next control tick (no command comes for the ticks before
    it, so they are not waited for); ``alive``, ``acks_at_loss`` and ``lost_at_s`` follow the
    lockstep controller's losses.
    """

    station: Station
    namespace: str
    pub_joints: Any
    pub_tcp: Any
    pub_bins: Any
    telemetry: TelemetryRecorder
    joint_names: list[str] = field(default_factory=list)
    command_subs: list[Any] = field(default_factory=list)
    sub_ack: Any = None
    pending: int = 0
    acks: dict[int, int] = field(default_factory=dict)
    last_ack_tick: int = -1
    next_tick: int = 0
    alive: bool = True
    acks_at_loss: int = -1
    lost_at_s: float | None = None
    target: sc.Target | None = None
    path: sc.TcpPath = field(default_factory=sc.TcpPath)

    @property
    def name(self) -> str:
        """The station's name."""
        return self.station.name

    def wire(self, topic: Topic) -> str:
        """The station's name of a station topic."""
        return topic.resolve(self.namespace)

    def tick_ready(self, tick: int) -> bool:
        """Lockstep: the ack of ``tick`` and all the commands it announces have arrived."""
        n = self.acks.get(tick)
        return n is not None and self.pending >= n

    def consume_tick(self, tick: int) -> None:
        """Lockstep: the commands of ``tick`` are applied; forget it and older acks.

        The pending count never goes below zero: a command lost at a controller's start must
        not make every later tick wait for one more command than it announces.
        """
        self.pending = max(self.pending - self.acks.pop(tick, 0), 0)
        for old in [t for t in self.acks if t < tick]:
            del self.acks[old]


CLAIMS_REFRESH_S = 1.0
"""Longest sim time between two relays of the claims board once one was relayed."""

SCENE_TARGETS_HZ = 5.0
"""Rate of ``/scene/targets`` (each station's target and TCP path), sim time."""


class Wire(Protocol):
    """What carries a node's messages: DDS (:class:`interfaces.ros.RosWire` around the rclpy
    node) or the in-process bus (:class:`interfaces.inproc.Bus`)."""

    def create_publisher(self, msg_type: Any, name: str, qos: c.Qos) -> Any:
        """A publisher (``publish``, ``topic_name``, ``get_subscription_count``)."""
        ...

    def create_subscription(
        self, msg_type: Any, name: str, callback: Any, qos: c.Qos, *, raw: bool = False
    ) -> Any:
        """A subscription (``topic_name``, ``get_publisher_count``)."""
        ...

    def count_publishers(self, name: str) -> int:
        """Publishers of ``name``."""
        ...

    def count_subscribers(self, name: str) -> int:
        """Subscriptions of ``name``."""
        ...


def _detection_values(d: PerceivedDetection) -> cdr.DetectionValues:
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


class TwinEndpoint:
    """The twin's side of the contract, whatever carries the messages: publishes the twin's
    state and takes commands; :func:`run_loop` drives it. :class:`TwinNode` runs it over ROS 2,
    :class:`InprocTwin` on the in-process bus."""

    _wire: Wire
    _log: Any

    def destroy_node(self) -> None:
        """Release the endpoint (a ROS node's ``destroy_node``; nothing on the bus)."""

    def _subscribed(self, subscription: Any) -> Any:
        """A subscription just created (kept by endpoints that must drop theirs)."""
        return subscription

    def _setup(
        self,
        twin: Twin,
        *,
        lockstep: bool,
        state_every: int = 4,
        ground_truth_every: int = 8,
        tap: Tap | None = None,
        tap_wants: TapWants | None = None,
        scene: bool = True,
    ) -> None:
        """Create every publisher and subscription of the cell's contract on ``self._wire``."""
        if not twin.stations:
            msg = "the twin has no episode: call reset() before building its node"
            raise RuntimeError(msg)
        self.twin = twin
        self._tap = tap
        self._tap_wants = tap_wants
        self.lockstep = lockstep
        self.state_every = state_every
        self.ground_truth_every = ground_truth_every
        self.counters = NodeCounters(published=Counter())
        self.telemetry = TelemetryRecorder()
        self.priorities: tuple[str, ...] = ()
        self._tick_counts: Counter[str] = Counter()  # by contract name (joint_states, ...)
        self._last_stamp_ns: dict[str, int] = {}
        self._events_sent = 0
        self.board = ClaimsBoard(
            [s.spec.name for s in twin.stations],
            twin.cell.belt,
            duration_s=twin.scenario.duration_s,
        )
        self._board_sent = False
        self._fault_budget: dict[str, tuple[int, int]] = {}  # topic -> (sim second, logged)
        self._claims_refresh_steps = max(1, round(CLAIMS_REFRESH_S / twin.dt_s))
        self.pub_clock = self._publisher(c.CLOCK_TOPIC)
        self.pub_belt = self._publisher(c.BELT_STATE)
        self.pub_det = self._publisher(c.DETECTIONS)
        self.pub_gt = self._publisher(c.GROUND_TRUTH_TOPIC)
        self.pub_events = self._publisher(c.EVENTS_TOPIC)
        self.pub_echo = self._publisher(c.PING_ECHO)
        self.pub_tick = self._publisher(c.LOCKSTEP_TICK)
        self.pub_faults = self._publisher(c.FAULTS)
        self.pub_claims = self._publisher(c.CLAIMS)
        self.scene = scene
        self.pub_tf = self._publisher(c.TF)
        self.pub_tf_static = self._publisher(c.TF_STATIC)
        self.pub_markers = self._publisher(c.SCENE_MARKERS)
        self.pub_objects = self._publisher(c.SCENE_OBJECTS)
        self.pub_targets = self._publisher(c.SCENE_TARGETS)
        self._scene_pubs = (
            self.pub_tf,
            self.pub_tf_static,
            self.pub_markers,
            self.pub_objects,
            self.pub_targets,
        )
        self._scene_static_sent = False
        self._targets_every = max(1, round(1.0 / (SCENE_TARGETS_HZ * twin.dt_s)))
        self._colour = class_colour(twin.cell.materials)
        self._objects = sc.ObjectMarkers(mesh=twin.object_mesh, colour=self._colour)
        self._marker_msgs: dict[tuple[str, int], tuple[sc.SceneMarker, Marker]] = {}
        self.links = [self._station_link(station) for station in twin.stations]
        self._cell_command_subs = [
            self._subscribe(c.BELT_SETPOINT, self._on_setpoint, command=True)
        ]
        self._subscribe(c.PRIORITIES, self._on_priorities, command=True)
        self._subscribe(c.PING, self._on_ping)
        for link in self.links:
            self._send(link.pub_bins, self.bins_message(link))  # latched, once

    def _station_link(self, station: Station) -> StationLink:
        ns = station.spec.namespace
        one = len(self.twin.stations) == 1
        link = StationLink(
            station=station,
            namespace=ns,
            pub_joints=self._publisher(c.JOINT_STATES, ns),
            pub_tcp=self._publisher(c.TCP_POSE, ns),
            pub_bins=self._publisher(c.BINS, ns),
            telemetry=self.telemetry if one else TelemetryRecorder(),
            joint_names=[*station.spec.robot.arm_joints, *station.tool.joint_names],
        )
        link.command_subs = [
            self._subscribe(topic, partial(handler, link), ns, link=link, command=True)
            for topic, handler in (
                (c.ARM_TRAJECTORY, self._on_trajectory),
                (c.GRIPPER_COMMAND, self._on_gripper),
                (c.PICK_TARGET, self._on_target),
                (c.CLAIM, self._on_claim),
            )
        ]
        link.sub_ack = self._subscribe(c.LOCKSTEP_ACK, partial(self._on_ack, link), ns, link=link)
        return link

    # -- the wire: every message in or out also goes to the tap (the episode's recording) ---
    def _publisher(self, topic: Topic, namespace: str = "") -> Any:
        return self._wire.create_publisher(
            message_class(topic), topic.resolve(namespace), topic.qos
        )

    _wire_takes_bytes = True
    """Whether a message already serialized for the tap is published as those bytes (DDS), or
    as the message (the in-process bus hands it over as it is)."""

    def _send(self, publisher: Any, msg: Any) -> None:
        """Publish ``msg``; with a tap, serialize it once and hand the same bytes to both."""
        if self._tap is None:
            publisher.publish(msg)
            return
        data = serialize_message(msg)
        publisher.publish(data if self._wire_takes_bytes else msg)
        self._tap(publisher.topic_name, data, time.time_ns())

    def _send_cdr(
        self, publisher: Any, encode: Callable[[], bytes], build: Callable[[], Any]
    ) -> None:
        """Publish a message written as its CDR bytes (``encode()``, :mod:`interfaces.cdr`):
        over ROS 2 the bytes as they are; on the in-process bus the message ``build()`` gives
        (the values the bytes carry, ``float32`` fields rounded: the bus hands it over as it
        is), for the subscribers there are; the tap gets the bytes. Nothing is encoded that
        nobody takes."""
        data = encode() if self._wire_takes_bytes or self._tap is not None else b""
        if self._wire_takes_bytes:
            publisher.publish(data)
        elif publisher.get_subscription_count() > 0:
            publisher.publish(WireExact(build()))
        if self._tap is not None:
            self._tap(publisher.topic_name, data, time.time_ns())

    def _taken(self, publisher: Any) -> bool:
        """Whether a message of a volatile topic reaches anyone (:meth:`_wanted`); nobody else
        would ever see it, so it need not be built."""
        return self._wanted(publisher)

    def _send_serialized(self, publisher: Any, data: bytes) -> None:
        """Publish a message already serialized (CDR); with a tap, hand it the same bytes."""
        publisher.publish(data)
        if self._tap is not None:
            self._tap(publisher.topic_name, data, time.time_ns())

    def _subscribe(
        self,
        topic: Topic,
        callback: Callable[[Any], None],
        namespace: str = "",
        *,
        link: StationLink | None = None,
        command: bool = False,
    ) -> Any:
        """Subscribe ``callback``; with a tap, record the serialized bytes too.

        Over ROS 2 the subscription takes the serialized bytes, and a message longer than
        :func:`max_message_bytes` is refused undecoded (fault ``oversized``; a ``command``
        still counts as received, as the controller counted it in its ack). On the in-process
        bus the messages are the controllers' own objects, taken as they are."""
        msg_type = message_class(topic)
        name = topic.resolve(namespace)
        qos = topic.qos
        tap = self._tap
        if not self._wire_takes_bytes:
            if tap is None:
                return self._subscribed(
                    self._wire.create_subscription(msg_type, name, callback, qos)
                )

            def on_msg(msg: Any) -> None:
                data = serialize_message(msg)  # as received: a callback may change msg
                received_ns = time.time_ns()
                callback(msg)
                tap(name, data, received_ns)

            return self._subscribed(self._wire.create_subscription(msg_type, name, on_msg, qos))
        limit = max_message_bytes(topic)

        def on_bytes(data: bytes) -> None:
            received_ns = time.time_ns()
            if len(data) > limit:
                if command:
                    self._received(link)
                detail = f"{len(data)} bytes, more than the {limit} this topic takes"
                self._reject(name, Rejected("oversized", detail), link)
                return
            callback(deserialize_message(data, msg_type))  # first: a ping's echo waits for nothing
            if tap is not None:
                tap(name, data, received_ns)

        return self._subscribed(
            self._wire.create_subscription(msg_type, name, on_bytes, qos, raw=True)
        )

    # -- commands ---------------------------------------------------------------------------
    def _received(self, link: StationLink | None) -> None:
        self.counters.received_commands += 1
        if link is not None:
            link.pending += 1

    def _reject(self, topic: str, rejected: Rejected, link: StationLink | None = None) -> None:
        """Count a refused message; log it as a fault (``/faults``, ``/events``, the node's
        log) unless its topic already logged :data:`MAX_FAULT_EVENTS_PER_S` this sim second."""
        self.counters.rejected[rejected.reason] += 1
        second = int(self.twin.time_s)
        start, logged = self._fault_budget.get(topic, (second, 0))
        if start != second:
            logged = 0
        if logged >= MAX_FAULT_EVENTS_PER_S:
            self.counters.unlogged += 1
            return
        self._fault_budget[topic] = (second, logged + 1)
        text = f"{topic}: rejected ({rejected.reason}): {cut_text(rejected.detail)}"
        self._log.error(text)
        self._send(self.pub_faults, String(data=text))
        self.twin.record_fault(rejected.reason, text, None if link is None else link.name)
        self.publish_new_events()

    def _on_trajectory(self, link: StationLink, msg: JointTrajectory) -> None:
        stamp_s, wall_s = msg_stamp_s(msg.header.stamp), time.perf_counter()
        link.telemetry.on_command(stamp_s, wall_s)
        if link.telemetry is not self.telemetry:
            self.telemetry.on_command(stamp_s, wall_s)
        self._received(link)
        if not msg.points:
            self._reject(link.wire(c.ARM_TRAJECTORY), Rejected("empty", "no points"), link)
            return
        point = msg.points[0]
        limits = link.station.robot.limits
        result = validate_joint_command(
            list(msg.joint_names),
            list(point.positions),
            list(point.velocities),
            arm_joints=link.station.spec.robot.arm_joints,
            lower=limits.lower,
            upper=limits.upper,
            velocity_limit=limits.velocity,
        )
        if isinstance(result, Rejected):
            self._reject(link.wire(c.ARM_TRAJECTORY), result, link)
            return
        assert isinstance(result, JointTarget)
        age_s = command_age_s(stamp_s, self.twin.time_s)
        command = ArmCommand(result.positions, result.velocities, age_s=age_s)
        self.twin.command(command, link.station.index)

    def _on_gripper(self, link: StationLink, msg: Float64) -> None:
        self._received(link)
        result = validate_gripper(msg.data, link.station.tool.max_command)
        if isinstance(result, Rejected):
            self._reject(link.wire(c.GRIPPER_COMMAND), result, link)
            return
        self.twin.command_gripper(result, link.station.index)

    def _on_target(self, link: StationLink, msg: PickTarget) -> None:
        self._received(link)
        p, v = msg.grasp_point, msg.velocity
        values = (p.x, p.y, p.z, v.x, v.y, v.z)
        if not all(math.isfinite(x) for x in values) or len(msg.phase) > 64:
            detail = f"grasp point and velocity {cut(values)}, phase {cut(msg.phase, 70)}"
            self._reject(link.wire(c.PICK_TARGET), Rejected("not_finite", detail), link)
            return
        self.twin.announce_target(int(msg.track_id), (p.x, p.y, p.z), msg.phase, link.station.index)
        if msg.phase in PURSUIT_PHASES:
            link.target = sc.Target((p.x, p.y, p.z), (v.x, v.y, v.z), msg_stamp_s(msg.header.stamp))
        else:
            link.target = None

    def _on_claim(self, link: StationLink, msg: Claim) -> None:
        """A station's claim goes on the board (one entry per station and track) when every
        field passes :meth:`twin.claims.ClaimsBoard.offer` (else a ``bad_claim`` or
        ``claims_full`` fault); the board is relayed on ``/line/claims`` after the next step.
        The twin only relays: it allocates nothing."""
        self._received(link)
        p, v = msg.position, msg.velocity
        fields = ClaimFields(
            station=msg.station,
            track_id=int(msg.track_id),
            class_name=msg.class_name,
            frame_id=msg.header.frame_id,
            stamp_s=msg_stamp_s(msg.header.stamp),
            position_m=(p.x, p.y, p.z),
            velocity_mps=(v.x, v.y, v.z),
            radius_m=msg.radius_m,
            state=msg.state,
        )
        msg.station = link.name
        refusal = self.board.offer(link.station.index, fields, msg)
        if refusal is None:
            return
        if refusal.reason == "claims_full":
            rejected = Rejected("claims_full", refusal.detail)
        else:
            rejected = Rejected("bad_claim", refusal.detail)
        self._reject(link.wire(c.CLAIM), rejected, link)

    def publish_claims(self, stamp: Any, step: int) -> None:
        """``/line/claims``: the whole board, ordered by station then track, when it changed
        since the last relay, and once a board was relayed at least every
        :data:`CLAIMS_REFRESH_S` (a restarted controller, which missed the earlier boards, then
        gets one to wait for); ``released`` and ``picked`` entries are relayed once and
        dropped."""
        refresh = self._board_sent and step % self._claims_refresh_steps == 0
        if not (self.board.changed or refresh):
            return
        self._board_sent = True
        msg = ClaimArray()
        msg.header.stamp = stamp
        msg.header.frame_id = "world"
        msg.claims = self.board.take()
        self._send(self.pub_claims, msg)
        self._count(c.CLAIMS, c.CLAIMS.name, msg_stamp_ns(stamp))

    def _on_ack(self, link: StationLink, msg: StepAck) -> None:
        tick = int(msg.tick)
        if tick > self.twin.step_count + MAX_ACKS_AHEAD or len(link.acks) > MAX_ACKS_AHEAD:
            detail = f"tick {tick} while the twin is at tick {self.twin.step_count}"
            self._reject(link.wire(c.LOCKSTEP_ACK), Rejected("bad_ack", detail), link)
            return
        link.acks[tick] = int(msg.n_commands)
        link.last_ack_tick = max(link.last_ack_tick, tick)
        link.next_tick = max(link.next_tick, int(msg.next_tick))

    def _on_setpoint(self, msg: Float64) -> None:
        self._received(None)
        result = validate_setpoint(msg.data)
        if isinstance(result, Rejected):
            self._reject(c.BELT_SETPOINT.name, result)
            return
        self.twin.set_belt_setpoint(result)

    def _on_priorities(self, msg: SortingPriorities) -> None:
        self._received(None)
        result = validate_priorities(list(msg.classes), self.twin.classes)
        if isinstance(result, Rejected):
            self._reject(c.PRIORITIES.name, result)
            return
        self.priorities = result

    def _on_ping(self, msg: Ping) -> None:
        msg.sim_step = self.twin.step_count
        msg.echo_ns = time.monotonic_ns()
        self._send(self.pub_echo, msg)

    # -- lockstep -----------------------------------------------------------------------------
    def tick_ready(self, tick: int) -> bool:
        """Lockstep: every station's ack of ``tick`` and all the commands it announces are in."""
        return all(link.tick_ready(tick) for link in self.links)

    @property
    def pending_commands(self) -> int:
        """Commands received and not yet consumed, over every station."""
        return sum(link.pending for link in self.links)

    def peers_matched(self) -> bool:
        """Whether every station's controller is there and has matched (:meth:`link_matched`)."""
        return all(self.link_matched(link) for link in self.links)

    def link_matched(self, link: StationLink) -> bool:
        """Whether a station's controller is there and every subscriber of a counted topic has
        matched.

        The controller is whoever publishes the station's ``lockstep/ack`` (a recorder or
        ``ros2 topic echo`` subscribes too, but acknowledges nothing). A volatile message sent
        before both its writer and its reader have matched can be lost, and the controller would
        then wait for a counted message that never comes. This checks the writer side of the
        twin's counted topics, and the reader side of its command subscriptions (every
        publisher the graph shows has matched; the controller announced them before its ack
        publisher). The controller creates its ack publisher only once its own readers of the
        tick and the counted topics have matched (see :mod:`control.node`), so seeing that
        publisher covers the reader side of the counted topics.
        """
        if link.sub_ack.get_publisher_count() == 0:
            return False
        subs = (*link.command_subs, *self._cell_command_subs)
        wire = self._wire
        if any(s.get_publisher_count() < wire.count_publishers(s.topic_name) for s in subs):
            return False
        pubs = [self.pub_tick, link.pub_joints, self.pub_belt, self.pub_det]
        if len(self.links) > 1:  # a single station's controller need not read the board
            pubs.append(self.pub_claims)
        return all(
            p.get_subscription_count() >= max(1, wire.count_subscribers(p.topic_name)) for p in pubs
        )

    # -- publishing -------------------------------------------------------------------------
    def _count(self, topic: Topic, wire: str, stamp_ns: int, *, tick: bool = True) -> None:
        """Count a message of a counted topic (every station's on its own wire name; a tick
        counts one station's, the same for all)."""
        self.counters.published[wire] += 1
        if tick:
            key = topic.name
            self._tick_counts[key] += 1
            self._last_stamp_ns[key] = max(self._last_stamp_ns.get(key, -1), stamp_ns)

    def publish_step(self) -> None:
        """Publish everything due after a physics step."""
        twin = self.twin
        step = twin.step_count
        stamp = time_msg(twin.time_s)
        stamp_ns = msg_stamp_ns(stamp)
        if self._taken(self.pub_clock):
            self._send_cdr(
                self.pub_clock,
                partial(cdr.clock_cdr, stamp.sec, stamp.nanosec),
                lambda: Clock(clock=stamp),
            )
        wall_s = time.perf_counter()
        self.telemetry.on_step(twin.time_s, wall_s)
        self.telemetry.on_state_published(twin.time_s, wall_s)
        for i, link in enumerate(self.links):
            if link.telemetry is not self.telemetry:
                link.telemetry.on_state_published(twin.time_s, wall_s)
            self._publish_station(link, stamp)
            self._count(c.JOINT_STATES, link.wire(c.JOINT_STATES), stamp_ns, tick=i == 0)
        if step % self.state_every == 0:
            self.publish_belt(stamp)
        for frame in twin.take_detections():
            self.publish_detections(frame)
        if step % self.ground_truth_every == 0:
            want_gt = self._wanted(self.pub_gt)
            want_scene = self.scene_wanted()
            if want_gt or want_scene:
                objects = twin.observe_objects()
                if want_gt:
                    self.publish_ground_truth(stamp, objects)
                if want_scene:
                    self.publish_scene(stamp, objects, targets=step % self._targets_every == 0)
        self.publish_new_events()
        self.publish_claims(stamp, step)
        if self.lockstep:
            self._publish_tick(step, stamp)
        self._tick_counts = Counter()

    def _publish_station(self, link: StationLink, stamp: Any) -> None:
        """A station's ``joint_states`` (the arm's joints, then the tool's report) and
        ``tcp_pose``."""
        station = link.station
        q, qd = station.robot.joint_state()
        tool_q, tool_qd = station.tool.joint_report()
        position = [float(v) for v in q] + tool_q
        velocity = [float(v) for v in qd] + tool_qd
        sec, nanosec = stamp.sec, stamp.nanosec

        def joint_state() -> JointState:
            joints = JointState(name=link.joint_names, position=position, velocity=velocity)
            joints.header.stamp = stamp
            return joints

        encode = partial(cdr.joint_state_cdr, sec, nanosec, link.joint_names, position, velocity)
        self._send_cdr(link.pub_joints, encode, joint_state)
        if not self._taken(link.pub_tcp):
            return
        pos, orn = self.twin.tcp_pose(station.index)
        pos3 = (float(pos[0]), float(pos[1]), float(pos[2]))
        quat = (float(orn[0]), float(orn[1]), float(orn[2]), float(orn[3]))

        def pose_stamped() -> PoseStamped:
            pose = PoseStamped()
            pose.header.stamp = stamp
            pose.header.frame_id = "world"
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = pos3
            o = pose.pose.orientation
            o.x, o.y, o.z, o.w = quat
            return pose

        encode = partial(cdr.pose_stamped_cdr, sec, nanosec, "world", pos3, quat)
        self._send_cdr(link.pub_tcp, encode, pose_stamped)

    def _publish_tick(self, step: int, stamp: Any) -> None:
        counts, last = self._tick_counts, self._last_stamp_ns
        joints, belt, detections, claims = (t.name for t in c.COUNTED)
        values = cdr.TickValues(
            tick=step,
            sec=stamp.sec,
            nanosec=stamp.nanosec,
            n_joint_states=counts[joints],
            n_belt_states=counts[belt],
            n_detections=counts[detections],
            n_claims=counts[claims],
            last_joint_state_ns=last.get(joints, -1),
            last_belt_state_ns=last.get(belt, -1),
            last_detections_ns=last.get(detections, -1),
            last_claims_ns=last.get(claims, -1),
        )

        def tick() -> LockstepTick:
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

        self._send_cdr(self.pub_tick, partial(cdr.lockstep_tick_cdr, values), tick)

    def bins_message(self, link: StationLink) -> SortingBins:
        """A station's ``cell/bins``: its bins (``StationSpec.bins``), stamped now."""
        msg = SortingBins()
        msg.header.stamp = time_msg(self.twin.time_s)
        msg.header.frame_id = "world"
        for b in link.station.spec.bins:
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

    def publish_belt(self, stamp: Any) -> None:
        """``/conveyor/state``."""
        twin = self.twin
        belt = twin.observe_belt()
        msg = BeltState(
            setpoint_mps=twin.setpoint_mps,
            speed_mps=belt.belt_speed_mps,
            position_m=belt.belt_position_m,
            motor_torque_nm=belt.motor_torque_Nm,
            motor_current_a=belt.motor_current_A,
            load_mass_kg=twin.load_mass_kg,
        )
        msg.header.stamp = stamp
        msg.header.frame_id = "world"
        self._send(self.pub_belt, msg)
        self.telemetry.on_belt(twin.time_s, twin.setpoint_mps, belt.belt_speed_mps)
        self._count(c.BELT_STATE, c.BELT_STATE.name, msg_stamp_ns(stamp))

    def publish_detections(self, frame: DetectionFrame) -> None:
        """``/objects/detections``: one released frame, stamped with its capture time."""
        stamp = time_msg(frame.capture_time_s)
        values = [_detection_values(d) for d in frame.detections]

        def detections() -> DetectionArray:
            msg = DetectionArray()
            msg.header.stamp = stamp
            msg.header.frame_id = "world"
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

        encode = partial(cdr.detection_array_cdr, stamp.sec, stamp.nanosec, "world", values)
        self._send_cdr(self.pub_det, encode, detections)
        self._count(c.DETECTIONS, c.DETECTIONS.name, msg_stamp_ns(stamp))

    def publish_ground_truth(
        self, stamp: Any, objects: tuple[GroundTruth, ...] | None = None
    ) -> None:
        """``/objects/ground_truth`` (evaluation only) of ``objects`` (default: now's)."""
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
            for gt in (self.twin.observe_objects() if objects is None else objects)
        ]
        data = cdr.object_state_array_cdr(stamp.sec, stamp.nanosec, "world", values)
        self._send_cdr(
            self.pub_gt, lambda: data, lambda: deserialize_message(data, ObjectStateArray)
        )

    # -- the scene --------------------------------------------------------------------------
    def scene_wanted(self) -> bool:
        """The scene is on and someone takes it: a tap (recording, live view) or a matched
        subscriber of a scene topic."""
        if not self.scene:
            return False
        return any(self._wanted(p) for p in self._scene_pubs)

    def _wanted(self, publisher: Any) -> bool:
        """Someone takes ``publisher``'s messages: the tap (unless it says it does not want
        that topic now) or a matched subscriber."""
        if self._tap is not None and (
            self._tap_wants is None or self._tap_wants(publisher.topic_name)
        ):
            return True
        return bool(publisher.get_subscription_count() > 0)

    def publish_scene(
        self, stamp: Any, objects: tuple[GroundTruth, ...], *, targets: bool = True
    ) -> None:
        """The scene at a ground-truth tick: the static part once, ``/tf``, the objects'
        markers when their set changed, and (``targets``) each station's target and path."""
        twin = self.twin
        if not self._scene_static_sent:
            self._scene_static_sent = True
            self.publish_scene_static(stamp)
        live = [gt for gt in objects if not gt.in_bin]
        frames: list[sc.Frame] = []
        for link in self.links:
            robot = link.station.robot
            tcp = twin.tcp_pose(link.station.index)
            frames += sc.station_frames(link.namespace, robot.link_poses(), tcp)
            link.path.add(twin.time_s, tcp[0])
        frames += sc.world_frames(
            (sc.object_frame(gt.id), (gt.position_m, gt.orientation_xyzw)) for gt in live
        )
        self._send_serialized(self.pub_tf, sc.tf_message_cdr(frames, stamp.sec, stamp.nanosec))
        update = self._objects.update(gt.id for gt in live)
        if update is not None:
            self._send(self.pub_objects, self._marker_array(update.markers, stamp))
        if targets:
            markers: list[sc.SceneMarker] = []
            for i, link in enumerate(self.links):
                markers += [sc.target_marker(i, link.target, twin.time_s), link.path.marker(i)]
            self._send(self.pub_targets, self._marker_array(markers, stamp))

    def publish_scene_static(self, stamp: Any) -> None:
        """``/tf_static`` (each station's root link in ``world``) and ``/scene/markers`` (belt,
        bins, every station's link meshes), once."""
        frames: list[sc.Frame] = []
        markers = [sc.belt_marker(self.twin.cell), *sc.bin_markers(self.twin.cell, self._colour)]
        for link in self.links:
            robot = link.station.robot
            root = sc.link_frame(link.namespace, robot.root_link)
            frames += sc.world_frames([(root, robot.root_pose())])
            markers += sc.link_markers(link.namespace, link_visuals(robot.urdf))
        self._send_serialized(
            self.pub_tf_static, sc.tf_message_cdr(frames, stamp.sec, stamp.nanosec)
        )
        self._send(self.pub_markers, self._marker_array(markers, stamp))

    def _marker_array(self, markers: Any, stamp: Any) -> MarkerArray:
        """The markers as a ``MarkerArray``, each stamped ``stamp``; a marker already converted
        (the same value) is reused, so a live object's mesh is converted once."""
        out = []
        for marker in markers:
            key = (marker.ns, marker.id)
            cached = self._marker_msgs.get(key)
            if cached is not None and cached[0] is marker:
                cached[1].header.stamp = stamp
                out.append(cached[1])
                continue
            msg = _marker_msg(marker, stamp)
            if marker.action is sc.MarkerAction.ADD and marker.frame_locked:
                self._marker_msgs[key] = (marker, msg)
            else:
                self._marker_msgs.pop(key, None)
            out.append(msg)
        return MarkerArray(markers=out)

    def publish_new_events(self) -> None:
        """``/events``: every event the twin logged since the last call, in log order."""
        events = self.twin.events
        for event in events[self._events_sent :]:
            self.publish_event(event)
        self._events_sent = len(events)

    def publish_event(self, event: Event) -> None:
        """``/events``."""
        msg = SortingEvent(
            type=str(event.type),
            object_id=event.object_id,
            class_name=event.class_name,
            detail=json.dumps(event.data),
        )
        msg.header.stamp = time_msg(event.time_s)
        self._send(self.pub_events, msg)


class TwinNode(Node, TwinEndpoint):
    """The twin's side of the contract as a ROS 2 node (``cdw_twin``)."""

    def __init__(self, twin: Twin, *, lockstep: bool, **options: Unpack[EndpointOptions]) -> None:
        Node.__init__(self, "cdw_twin")
        self._wire = RosWire(self)
        self._log = self.get_logger()
        self._setup(twin, lockstep=lockstep, **options)


class InprocTwin(TwinEndpoint):
    """The twin's side of the contract on the in-process bus (``--transport inproc``): the same
    topics, messages and lockstep handshake as :class:`TwinNode`, without DDS."""

    def __init__(self, twin: Twin, bus: Bus, **options: Unpack[EndpointOptions]) -> None:
        self._wire = bus
        self._log = InprocLogger("cdw_twin")
        self._subscriptions: list[Any] = []
        self._setup(twin, lockstep=True, **options)

    _wire_takes_bytes = False

    def _subscribed(self, subscription: Any) -> Any:
        self._subscriptions.append(subscription)
        return subscription

    def detach(self) -> None:
        """Take nothing more from the bus (the episode ended: over ROS 2 the twin node stops
        reading here), so the controllers can be handed the last tick on their own."""
        for subscription in self._subscriptions:
            subscription.destroy()
        self._subscriptions.clear()


def cut_text(text: str, limit: int = 300) -> str:
    """``text``, at most ``limit`` characters (a refusal's detail may quote a client's
    string)."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _marker_msg(marker: sc.SceneMarker, stamp: Any) -> Marker:
    """A ``visualization_msgs/Marker`` of a scene marker."""
    msg = Marker()
    msg.header.stamp = stamp
    msg.header.frame_id = marker.frame_id
    msg.ns = marker.ns
    msg.id = marker.id
    msg.type = int(marker.kind)
    msg.action = int(marker.action)
    if marker.action is sc.MarkerAction.DELETE:
        return msg
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z = marker.position_m
    o.x, o.y, o.z, o.w = marker.orientation_xyzw
    msg.scale.x, msg.scale.y, msg.scale.z = marker.scale
    col = msg.color
    col.r, col.g, col.b, col.a = marker.rgba
    msg.frame_locked = marker.frame_locked
    if marker.points_m is not None:
        msg.points = [Point(x=x, y=y, z=z) for x, y, z in marker.points_m.tolist()]
    return msg


def run_loop(
    node: TwinEndpoint,
    executor: Any,
    *,
    realtime_factor: float = 1.0,
    ack_timeout_s: float = 2.0,
    start_timeout_s: float = 60.0,
    on_first_step: Callable[[], None] | None = None,
) -> None:
    """Step the twin until its scenario's duration, serving callbacks between steps;
    ``on_first_step`` is called as the first step's messages go out (in lockstep, once the
    controllers have matched)."""
    twin = node.twin
    spin_once = executor.spin_once
    duration = twin.scenario.duration_s
    gc.collect()
    gc.freeze()  # everything built so far is long-lived: keep the collector off it
    if node.lockstep:
        Lockstep(node, spin_once, ack_timeout_s, start_timeout_s).run(duration, on_first_step)
        return
    if on_first_step is not None:
        on_first_step()
    node.publish_step()
    period = twin.dt_s / realtime_factor
    next_wall = time.perf_counter()
    while twin.time_s < duration - 1e-9:
        spin_once(timeout_sec=0.0)
        _serve_until(spin_once, next_wall)
        twin.advance()
        spin_once(timeout_sec=0.0)
        node.publish_step()
        next_wall += period
        if next_wall < time.perf_counter() - 0.25:
            next_wall = time.perf_counter()


def _serve_until(spin_once: Callable[..., None], wall_s: float) -> None:
    """Serve callbacks until the ``time.perf_counter()`` time ``wall_s``."""
    while (remaining := wall_s - time.perf_counter()) > 0:
        spin_once(timeout_sec=remaining)


RESYNC_WAIT_S = 10.0


class Lockstep:
    """Step tick k+1 once every station's controller has acknowledged tick k with all its
    commands; a tick before the next control tick a controller's last ack announced
    (``StepAck.next_tick``) is not waited for: no command of it can come.

    A station's controller that does not answer within ``ack_timeout_s`` is lost: a
    ``controller_timeout`` fault naming the station is logged, and the cell goes on in lockstep
    with the other stations' controllers, or at the wall-clock pace when none is left, as a
    real cell would while a controller restarts, so an outage costs about the sim time it
    lasts. When that station's acks come again (a restarted controller), the twin waits up to
    ``RESYNC_WAIT_S`` for it to catch up, logs ``controller_resumed`` and waits for it again.
    """

    def __init__(
        self,
        node: TwinEndpoint,
        spin_once: Callable[..., None],
        ack_timeout_s: float,
        start_timeout_s: float,
    ) -> None:
        self.node = node
        self.twin = node.twin
        self.spin_once = spin_once
        self.ack_timeout_s = ack_timeout_s
        self.start_timeout_s = start_timeout_s
        self.next_wall = 0.0

    def run(self, duration: float, on_first_step: Callable[[], None] | None = None) -> None:
        """Match the controllers, then step until ``duration`` (``on_first_step``: see
        :func:`run_loop`)."""
        node, twin = self.node, self.twin
        deadline = time.monotonic() + self.start_timeout_s
        while not node.peers_matched() and time.monotonic() < deadline:
            self.spin_once(timeout_sec=0.05)
        for link in node.links:
            link.alive = node.link_matched(link)
            if not link.alive:
                link.lost_at_s = 0.0
                self._fault(link, "no controller subscribed before the start")
        if on_first_step is not None:
            on_first_step()
        node.publish_step()
        self.next_wall = time.perf_counter()
        while twin.time_s < duration - 1e-9:
            tick = twin.step_count
            waits = self._waits(tick)
            if waits:
                self._wait_for(tick, waits)
                for link, wait_s in waits:
                    self._settle(link, tick, wait_s)
            elif any(link.alive for link in node.links):
                self.spin_once(timeout_sec=0.0)  # no controller sends commands for this tick
                self.next_wall = time.perf_counter()
            else:
                self.next_wall += twin.dt_s
                _serve_until(self.spin_once, self.next_wall)
                self.spin_once(timeout_sec=0.0)
            twin.advance()
            node.publish_step()

    def _waits(self, tick: int) -> list[tuple[StationLink, float]]:
        """The stations whose acks tick ``tick`` waits for, each with its patience (s): a live
        controller, or a lost one acknowledging again (resync)."""
        waits = []
        for link in self.node.links:
            resync = not link.alive and link.last_ack_tick > link.acks_at_loss
            if link.alive and tick < link.next_tick:
                continue  # announced: no command of this controller before its next tick
            if link.alive or resync:
                wait_s = self.ack_timeout_s
                if tick == 0 or resync:
                    wait_s = self.start_timeout_s if tick == 0 else RESYNC_WAIT_S
                waits.append((link, wait_s))
        return waits

    def _wait_for(self, tick: int, waits: list[tuple[StationLink, float]]) -> None:
        """Serve callbacks until every waited-for station is ready or past its patience."""
        now = time.monotonic()
        until = [(link, now + wait_s) for link, wait_s in waits]
        while True:
            remaining = max(
                (t - time.monotonic() for link, t in until if not link.tick_ready(tick)),
                default=0.0,
            )
            if remaining <= 0:
                return
            self.spin_once(timeout_sec=min(remaining, 0.05))

    def _settle(self, link: StationLink, tick: int, wait_s: float) -> None:
        """After the wait: a station's controller resumed, lost, or still in step."""
        twin, node = self.twin, self.node
        ok = link.tick_ready(tick)
        if ok and link.lost_at_s is not None:
            twin.record_controller_resumed(twin.time_s - link.lost_at_s, link.name)
            node.publish_new_events()
            link.lost_at_s = None
        if not ok and link.alive:
            node.counters.lockstep_timeouts += 1
            self._fault(link, f"no acknowledgement of tick {tick} within {wait_s} s")
            link.lost_at_s = twin.time_s
        if not ok:
            # every command received so far has been applied; a restarted controller's
            # acks count only its own commands
            link.acks_at_loss = link.last_ack_tick
            link.pending = 0
            self.next_wall = time.perf_counter()
        link.alive = ok
        link.consume_tick(tick)

    def _fault(self, link: StationLink, detail: str) -> None:
        self.twin.record_fault("controller_timeout", detail, link.name)
        self.node.publish_new_events()


def make_executor() -> Any:
    """The EventsExecutor: it serves a callback with less latency than the default executor
    (``docs/benchmarks.md``), and the step loop serves callbacks between physics steps."""
    return EventsExecutor()


__all__ = [
    "InprocTwin",
    "Lockstep",
    "StationLink",
    "TwinEndpoint",
    "TwinNode",
    "Wire",
    "make_executor",
    "run_loop",
]
