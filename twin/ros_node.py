"""The twin as a ROS 2 node: a thin shell around :class:`twin.sim.Twin`.

It converts messages to domain values and back and calls the twin; there is no simulation logic
here, and each other job has its own module: the wire with its tap and message bounds
(:mod:`twin.tapped_wire`), the messages in both their forms (:mod:`twin.encoders`), the scene
topics (:mod:`twin.scene_publisher`), the claims board (:mod:`twin.claims`), the lockstep
bookkeeping (:mod:`twin.lockstep`) and the step loop (:mod:`twin.step_loop`). Every topic's
name, type and QoS comes from :mod:`interfaces.contract` (documented in ``docs/interfaces.md``):
the cell topics once, the station topics once per station of the cell under the station's
namespace (``/s1/joint_states``; the bare name for the empty namespace of a one-station cell).
The loop runs in one thread: it serves callbacks (commands, pings) while waiting for the next
physics step, so a ping is echoed at once, from inside the step loop.

With a tap (:data:`twin.tapped_wire.Tap`) the node's every message, both directions, goes to the
tap but the latched ``cell/bins`` (static configuration, published once at start).

``/events`` carries every event the twin logs, in the order of :attr:`twin.sim.Twin.events`:
the monitor's, rejected commands, controller timeouts and injected faults alike.

Claims: the node keeps the line's claims board (:class:`twin.claims.ClaimsBoard`: one entry per
station and track, from each station's ``line/claim``, every field checked, bounded per station
and in total) and relays it on ``/line/claims`` after every step in which it changed, a counted
topic of the tick; it allocates nothing.

The node trusts no client. A message longer than its topic's bound is refused before it is
decoded (fault ``oversized``, :func:`twin.tapped_wire.max_message_bytes`). Every refusal is
counted (``rejected_commands`` of the summary); the first :data:`MAX_FAULT_EVENTS_PER_S` of each
topic per second of sim time are also ``fault`` events on ``/events`` and ``/faults``, the rest
counted only (``unlogged_rejections``), so a client flooding the twin with bad messages cannot
flood its event log.

Extra per-step publishers (``step_publishers``, :class:`twin.scene_publisher.StepPublisher`: a
camera's images, say) are attached to the node's wire at its start and handed every step's
stamp after the twin's own messages.

Modes: ``realtime`` paces the physics to the wall clock; ``lockstep`` steps tick k+1 only when
every station's controller has acknowledged tick k (see the LockstepTick/StepAck handshake in
the docs).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any, TypedDict, Unpack

from builtin_interfaces.msg import Time
from cdw_interfaces.msg import (
    Claim,
    PickTarget,
    Ping,
    SortingBins,
    SortingPriorities,
    StepAck,
)
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.node import Node
from std_msgs.msg import Float64, String
from trajectory_msgs.msg import JointTrajectory

from interfaces import contract as c
from interfaces.contract import Topic
from interfaces.detections import DetectionFrame
from interfaces.events import Event
from interfaces.inproc import Bus, InprocLogger
from interfaces.phases import TRACKED_PHASES
from interfaces.ros import RosWire, msg_stamp_ns, msg_stamp_s, time_msg
from interfaces.wire import Wire
from twin import encoders as enc
from twin import scene as sc
from twin.claims import ClaimsBoard
from twin.claims_relay import CLAIMS_REFRESH_S, ClaimsRelay
from twin.commands import (
    MAX_FAULT_EVENTS_PER_S,
    FaultBudget,
    JointTarget,
    Rejected,
    command_age_s,
    cut_text,
    validate_gripper,
    validate_joint_command,
    validate_priorities,
    validate_setpoint,
    validate_target,
)
from twin.ground_truth import GroundTruth
from twin.lockstep import MAX_ACKS_AHEAD, RESYNC_WAIT_S, AckBook, TickCounter
from twin.scene_publisher import SCENE_TARGETS_HZ, ScenePublisher, StepPublisher
from twin.sim import ArmCommand, Twin
from twin.station import Station
from twin.step_loop import Lockstep, run_loop
from twin.tapped_wire import (
    DEFAULT_MAX_MESSAGE_BYTES,
    MAX_MESSAGE_BYTES,
    Tap,
    TappedWire,
    TapWants,
    max_message_bytes,
)
from twin.telemetry import TelemetryRecorder


class EndpointOptions(TypedDict, total=False):
    """The twin endpoint's options besides the twin and the mode (:meth:`TwinEndpoint._setup`)."""

    state_every: int
    ground_truth_every: int
    tap: Tap | None
    tap_wants: TapWants | None
    scene: bool
    step_publishers: Sequence[StepPublisher]


@dataclass
class NodeCounters:
    """What the node has seen and done; written to the episode log. ``unlogged`` counts the
    refusals beyond :data:`MAX_FAULT_EVENTS_PER_S` that were not logged as events."""

    published: Counter[str]
    received_commands: int = 0
    rejected: Counter[str] = field(default_factory=Counter)
    lockstep_timeouts: int = 0
    unlogged: int = 0


@dataclass
class StationLink:
    """One station's side of the node: its topics, its controller's commands and acks
    (``book``: the lockstep bookkeeping, :class:`twin.lockstep.AckBook`)."""

    station: Station
    namespace: str
    pub_joints: Any
    pub_tcp: Any
    pub_bins: Any
    telemetry: TelemetryRecorder
    joint_names: list[str] = field(default_factory=list)
    command_subs: list[Any] = field(default_factory=list)
    sub_ack: Any = None
    book: AckBook = field(default_factory=AckBook)

    @property
    def name(self) -> str:
        """The station's name."""
        return self.station.name

    def wire(self, topic: Topic) -> str:
        """The station's name of a station topic."""
        return topic.resolve(self.namespace)


class TwinEndpoint:
    """The twin's side of the contract, whatever carries the messages: publishes the twin's
    state and takes commands; :func:`twin.step_loop.run_loop` drives it. :class:`TwinNode` runs
    it over ROS 2, :class:`InprocTwin` on the in-process bus."""

    _wire: Wire
    _log: Any
    _wire_takes_bytes = True
    """Whether a message already serialized for the tap is published as those bytes (DDS), or
    as the message (the in-process bus hands it over as it is)."""

    def destroy_node(self) -> None:
        """Release the endpoint (a ROS node's ``destroy_node``; nothing on the bus)."""

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
        step_publishers: Sequence[StepPublisher] = (),
    ) -> None:
        """Create every publisher and subscription of the cell's contract on ``self._wire``."""
        if not twin.stations:
            msg = "the twin has no episode: call reset() before building its node"
            raise RuntimeError(msg)
        self.twin = twin
        self.io = TappedWire(
            self._wire, takes_bytes=self._wire_takes_bytes, tap=tap, tap_wants=tap_wants
        )
        self.lockstep = lockstep
        self.state_every = state_every
        self.ground_truth_every = ground_truth_every
        self.counters = NodeCounters(published=Counter())
        self.telemetry = TelemetryRecorder()
        self.priorities: tuple[str, ...] = ()
        self._ticks = TickCounter()
        self._events_sent = 0
        self._fault_budget = FaultBudget()
        publisher = self.io.publisher
        self.pub_clock = publisher(c.CLOCK_TOPIC)
        self.pub_belt = publisher(c.BELT_STATE)
        self.pub_det = publisher(c.DETECTIONS)
        self.pub_gt = publisher(c.GROUND_TRUTH_TOPIC)
        self.pub_events = publisher(c.EVENTS_TOPIC)
        self.pub_echo = publisher(c.PING_ECHO)
        self.pub_tick = publisher(c.LOCKSTEP_TICK)
        self.pub_faults = publisher(c.FAULTS)
        self.pub_claims = publisher(c.CLAIMS)
        self.board = ClaimsBoard(
            [s.spec.name for s in twin.stations],
            twin.cell.belt,
            duration_s=twin.scenario.duration_s,
        )
        self.claims = ClaimsRelay(self.io, self.pub_claims, self.board, dt_s=twin.dt_s)
        self.scene = ScenePublisher(self.io, twin, enabled=scene)
        self.step_publishers = tuple(step_publishers)
        for extra in self.step_publishers:
            extra.attach(self.io, twin)
        self.links = [self._station_link(station) for station in twin.stations]
        self._cell_command_subs = [
            self._subscribe(c.BELT_SETPOINT, self._on_setpoint, command=True)
        ]
        self._subscribe(c.PRIORITIES, self._on_priorities, command=True)
        self._subscribe(c.PING, self._on_ping)
        for link in self.links:
            self.io.send(link.pub_bins, self.bins_message(link))  # latched, once

    def _station_link(self, station: Station) -> StationLink:
        ns = station.spec.namespace
        one = len(self.twin.stations) == 1
        publisher = self.io.publisher
        link = StationLink(
            station=station,
            namespace=ns,
            pub_joints=publisher(c.JOINT_STATES, ns),
            pub_tcp=publisher(c.TCP_POSE, ns),
            pub_bins=publisher(c.BINS, ns),
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

    def _subscribe(
        self,
        topic: Topic,
        callback: Any,
        namespace: str = "",
        *,
        link: StationLink | None = None,
        command: bool = False,
    ) -> Any:
        """Subscribe ``callback`` (:meth:`twin.tapped_wire.TappedWire.subscribe`); a message
        over its bound is refused (fault ``oversized``; a ``command`` still counts as received,
        as the controller counted it in its ack)."""

        def oversized(name: str, detail: str) -> None:
            if command:
                self._received(link)
            self._reject(name, Rejected("oversized", detail), link)

        return self.io.subscribe(topic, callback, namespace, on_oversized=oversized)

    # -- commands ---------------------------------------------------------------------------
    def _received(self, link: StationLink | None) -> None:
        self.counters.received_commands += 1
        if link is not None:
            link.book.command_received()

    def _reject(self, topic: str, rejected: Rejected, link: StationLink | None = None) -> None:
        """Count a refused message; log it as a fault (``/faults``, ``/events``, the node's
        log) unless its topic already logged :data:`MAX_FAULT_EVENTS_PER_S` this sim second."""
        self.counters.rejected[rejected.reason] += 1
        if not self._fault_budget.admit(topic, self.twin.time_s):
            self.counters.unlogged += 1
            return
        text = f"{topic}: rejected ({rejected.reason}): {cut_text(rejected.detail)}"
        self._log.error(text)
        self.io.send(self.pub_faults, String(data=text))
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
        refused = validate_target((p.x, p.y, p.z, v.x, v.y, v.z), msg.phase)
        if refused is not None:
            self._reject(link.wire(c.PICK_TARGET), refused, link)
            return
        self.twin.announce_target(int(msg.track_id), (p.x, p.y, p.z), msg.phase, link.station.index)
        target = None
        if msg.phase in TRACKED_PHASES:
            target = sc.Target((p.x, p.y, p.z), (v.x, v.y, v.z), msg_stamp_s(msg.header.stamp))
        self.scene.set_target(link.station.index, target)

    def _on_claim(self, link: StationLink, msg: Claim) -> None:
        """A station's claim goes on the board (:meth:`twin.claims_relay.ClaimsRelay.offer`,
        else a ``bad_claim`` or ``claims_full`` fault); relayed after the next step."""
        self._received(link)
        rejected = self.claims.offer(link.station.index, link.name, msg)
        if rejected is not None:
            self._reject(link.wire(c.CLAIM), rejected, link)

    def publish_claims(self, stamp: Time, step: int) -> None:
        """``/line/claims`` when due (:meth:`twin.claims_relay.ClaimsRelay.publish`)."""
        if self.claims.publish(stamp, step):
            self._count(c.CLAIMS, c.CLAIMS.name, msg_stamp_ns(stamp))

    def _on_ack(self, link: StationLink, msg: StepAck) -> None:
        detail = link.book.take_ack(
            int(msg.tick),
            int(msg.n_commands),
            int(msg.next_tick),
            current_tick=self.twin.step_count,
        )
        if detail:
            self._reject(link.wire(c.LOCKSTEP_ACK), Rejected("bad_ack", detail), link)

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
        self.io.send(self.pub_echo, msg)

    # -- lockstep -----------------------------------------------------------------------------
    def count_lockstep_timeout(self) -> None:
        """Count a station's controller that missed its tick (``lockstep_timeouts``)."""
        self.counters.lockstep_timeouts += 1

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
            self._ticks.count(topic.name, stamp_ns)

    def publish_step(self) -> None:
        """Publish everything due after a physics step, then the extra step publishers'."""
        twin = self.twin
        step = twin.step_count
        stamp = time_msg(twin.time_s)
        stamp_ns = msg_stamp_ns(stamp)
        if self.io.wanted(self.pub_clock):
            self.io.send_outgoing(self.pub_clock, enc.clock(stamp))
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
            want_gt = self.io.wanted(self.pub_gt)
            want_scene = self.scene.wanted()
            if want_gt or want_scene:
                objects = twin.observe_objects()
                if want_gt:
                    self.publish_ground_truth(stamp, objects)
                if want_scene:
                    targets = step % self.scene.targets_every == 0
                    self.scene.publish(stamp, objects, targets=targets)
        for extra in self.step_publishers:
            extra.publish_step(stamp, step)
        self.publish_new_events()
        self.publish_claims(stamp, step)
        if self.lockstep:
            self._publish_tick(step, stamp)
        else:
            self._ticks.take(step, stamp.sec, stamp.nanosec)  # counted per tick all the same

    def _publish_station(self, link: StationLink, stamp: Time) -> None:
        """A station's ``joint_states`` (the arm's joints, then the tool's report) and
        ``tcp_pose``."""
        station = link.station
        q, qd = station.robot.joint_state()
        tool_q, tool_qd = station.tool.joint_report()
        position = [float(v) for v in q] + tool_q
        velocity = [float(v) for v in qd] + tool_qd
        self.io.send_outgoing(
            link.pub_joints, enc.joint_state(stamp, link.joint_names, position, velocity)
        )
        if not self.io.wanted(link.pub_tcp):
            return
        pos, orn = self.twin.tcp_pose(station.index)
        pos3 = (float(pos[0]), float(pos[1]), float(pos[2]))
        quat = (float(orn[0]), float(orn[1]), float(orn[2]), float(orn[3]))
        self.io.send_outgoing(link.pub_tcp, enc.pose_stamped(stamp, pos3, quat))

    def _publish_tick(self, step: int, stamp: Time) -> None:
        values = self._ticks.take(step, stamp.sec, stamp.nanosec)
        self.io.send_outgoing(self.pub_tick, enc.lockstep_tick(stamp, values))

    def bins_message(self, link: StationLink) -> SortingBins:
        """A station's ``cell/bins``: its bins (``StationSpec.bins``), stamped now."""
        return enc.bins(link.station, time_msg(self.twin.time_s))

    def publish_belt(self, stamp: Time) -> None:
        """``/conveyor/state``."""
        twin = self.twin
        belt = twin.observe_belt()
        values = enc.BeltValues(
            setpoint_mps=twin.setpoint_mps,
            speed_mps=belt.belt_speed_mps,
            position_m=belt.belt_position_m,
            motor_torque_nm=belt.motor_torque_Nm,
            motor_current_a=belt.motor_current_A,
            load_mass_kg=twin.load_mass_kg,
        )
        self.io.send(self.pub_belt, enc.belt_state(stamp, values))
        self.telemetry.on_belt(twin.time_s, twin.setpoint_mps, belt.belt_speed_mps)
        self._count(c.BELT_STATE, c.BELT_STATE.name, msg_stamp_ns(stamp))

    def publish_detections(self, frame: DetectionFrame) -> None:
        """``/objects/detections``: one released frame, stamped with its capture time."""
        stamp = time_msg(frame.capture_time_s)
        self.io.send_outgoing(self.pub_det, enc.detections(stamp, frame.detections))
        self._count(c.DETECTIONS, c.DETECTIONS.name, msg_stamp_ns(stamp))

    def publish_ground_truth(
        self, stamp: Time, objects: tuple[GroundTruth, ...] | None = None
    ) -> None:
        """``/objects/ground_truth`` (evaluation only) of ``objects`` (default: now's)."""
        now = self.twin.observe_objects() if objects is None else objects
        self.io.send_outgoing(self.pub_gt, enc.ground_truth(stamp, now))

    def publish_new_events(self) -> None:
        """``/events``: every event the twin logged since the last call, in log order."""
        events = self.twin.events
        for event in events[self._events_sent :]:
            self.publish_event(event)
        self._events_sent = len(events)

    def publish_event(self, event: Event) -> None:
        """``/events``."""
        self.io.send(self.pub_events, enc.sorting_event(event))


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

    _wire_takes_bytes = False

    def __init__(self, twin: Twin, bus: Bus, **options: Unpack[EndpointOptions]) -> None:
        self._wire = bus
        self._log = InprocLogger("cdw_twin")
        self._setup(twin, lockstep=True, **options)

    def detach(self) -> None:
        """Take nothing more from the bus (the episode ended: over ROS 2 the twin node stops
        reading here), so the controllers can be handed the last tick on their own."""
        for subscription in self.io.subscriptions:
            subscription.destroy()
        self.io.subscriptions.clear()


def make_executor() -> Any:
    """The EventsExecutor: it serves a callback with less latency than the default executor
    (``docs/benchmarks.md``), and the step loop serves callbacks between physics steps."""
    return EventsExecutor()


__all__ = [
    "CLAIMS_REFRESH_S",
    "DEFAULT_MAX_MESSAGE_BYTES",
    "MAX_ACKS_AHEAD",
    "MAX_FAULT_EVENTS_PER_S",
    "MAX_MESSAGE_BYTES",
    "RESYNC_WAIT_S",
    "SCENE_TARGETS_HZ",
    "EndpointOptions",
    "InprocTwin",
    "Lockstep",
    "NodeCounters",
    "StationLink",
    "Tap",
    "TapWants",
    "TwinEndpoint",
    "TwinNode",
    "Wire",
    "cut_text",
    "make_executor",
    "max_message_bytes",
    "run_loop",
]
