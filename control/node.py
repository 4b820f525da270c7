"""The controller as a ROS 2 node: a thin shell around the pure tracker and pick controller.

It converts messages to the controller's dataclasses and back; the logic lives in
:mod:`control.tracking`, :mod:`control.scheduler`, :mod:`control.allocation` and
:mod:`control.pick`; the conversions are :mod:`control.messages`, the wire
:class:`interfaces.wire.Wire`. Topic names, types and QoS come from :mod:`interfaces.contract`.
The node drives one station of the cell: it lives in the station's namespace, and the
station's topics (``joint_states``, the commands, ``line/claim``, ``lockstep/ack``) are under
it (``/s1/joint_states``; the bare names for the empty namespace); the cell's topics (belt,
detections, priorities, the claims board ``/line/claims``, the lockstep tick) are shared by
every station. The station's claims go out on its ``line/claim`` with the commands of their
tick (counted in the ack); the boards the cell relays on ``/line/claims`` are applied in order.

When the control update runs:

- realtime: on every ``steps_per_update``-th ``joint_states`` message (every 2nd at 120 Hz
  control and 240 Hz state), at the sim time of that message. The update runs as soon as a
  fresh state is there, so no timer phase adds latency, and no wall clock is involved.
- lockstep: on ``/lockstep/tick`` k (one per cell), once the messages the tick covers have all
  arrived; every ``steps_per_update``-th tick at the tick's sim time. The tick names, per
  counted topic, the newest stamp published up to it; messages are attributed to ticks by
  their stamps, so a restarted controller, or one whose reader dropped messages, finds its
  place in the stream.
  Every tick is acknowledged with the number of command messages published for that tick.
  Discovery is checked from both sides before the first tick, because a volatile message
  sent before both its writer and its reader have matched can be lost, and the other side
  would then wait for a message that never comes:

  - the ack publisher is created only once this node's subscriptions to the tick and the
    counted topics have each matched a publisher (reader side). The twin does not
    publish tick 0 before it sees that publisher, so the twin's first tick and its messages
    reach readers that already know their writer;
  - no tick is handled before every command publisher and the ack publisher has matched a
    subscriber (writer side).

  Ticks that arrive earlier wait in the queue; a steady-clock timer re-checks every 5 ms.

Incoming messages are queued with their stamps and applied in a fixed order (belt, detections,
claims boards, joint states) up to the stamps the tick names, so the same inputs give the same
outputs regardless of the DDS delivery order across topics.
"""

from __future__ import annotations

import math
import time
from collections import Counter, deque
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from trajectory_msgs.msg import JointTrajectoryPoint

from control.allocation import Claim
from control.config import ControllerConfig
from control.errors import ControlError, RobotModelError
from control.ik import Kinematics, yaw_of
from control.inbox import StampedInbox
from control.messages import (
    JointSample,
    claim_msg,
    claims_of,
    detections_of,
    joint_sample,
    priorities_of,
)
from control.pick import PURSUIT_PHASES, Command, PickController, TcpMeasurement
from control.predicted_tracks import PredictedTracks
from control.scheduler import nearest_grasp_yaw
from control.tracking import Track, Tracker
from interfaces.contract import (
    ARM_TRAJECTORY,
    BELT_STATE,
    CLAIM,
    CLAIMS,
    COMMANDS,
    COUNTED,
    DETECTIONS,
    GRIPPER_COMMAND,
    JOINT_STATES,
    LOCKSTEP_ACK,
    LOCKSTEP_TICK,
    PICK_TARGET,
    PRIORITIES,
    Topic,
)
from interfaces.inproc import Bus, InprocLogger
from interfaces.ros import RosWire, message_class, msg_stamp_ns, msg_stamp_s, time_msg
from interfaces.run_records import ControllerStats, TimingUs
from interfaces.wire import Wire

FloatArray = NDArray[np.float64]


ERRORS_CHECK_EVERY = 12
"""Control updates between two checks for new rejections, errors and aborts to log (0.1 s at
120 Hz)."""


def _timing(values_s: Sequence[float]) -> TimingUs:
    """Mean, median, 95th and 99th percentiles and maximum in microseconds (None without
    samples): the tick's p99 is what must fit the control period on a real cell."""
    if not values_s:
        return TimingUs()
    us = 1e6 * np.asarray(values_s, dtype=np.float64)
    p50, p95, p99 = (float(v) for v in np.percentile(us, [50.0, 95.0, 99.0]))
    return TimingUs(mean=float(np.mean(us)), p50=p50, p95=p95, p99=p99, max=float(np.max(us)))


class ControllerEndpoint:
    """Tracks detections, picks objects and streams arm, tool and target commands for one
    station, its topics under the station's namespace, whatever carries the messages:
    :class:`ControllerNode` over ROS 2, :class:`InprocController` on the in-process bus."""

    _wire: Wire
    _log: Any

    def _setup(self, config: ControllerConfig, *, lockstep: bool) -> None:
        """Create publishers and subscriptions on ``self._wire``.

        Raises ``ControlError`` (``RobotModelError``, ``ControlConfigError``) when the robot
        model cannot be built.
        """
        namespace = config.station.namespace
        self.config = config
        self.lockstep = lockstep
        self._kin = Kinematics.of_station(config.station, config.ik)
        self._tool = config.tool
        missing = [n for n in self._tool.urdf_joint_names if not self._kin.has_joint(n)]
        if missing:
            msg = f"{self._kin.urdf_path}: tool.joints: no joint {missing[0]!r} in the URDF"
            raise RobotModelError(msg)
        self._tracker = Tracker(config.tracking, classes=config.classes)
        self._controller: PickController | None = None
        self._arm_names = tuple(config.robot.arm_joints)
        self._steps_per_update = config.steps_per_update
        self._period_s = config.motion.control_period_s
        self._priorities: dict[str, float] | None = None
        self._boards: list[list[Claim]] = []
        self._belt_velocity_mps: tuple[float, float] = (0.0, 0.0)
        self._joint: JointSample | None = None
        self.topics: dict[Topic, str] = {
            t: t.resolve(namespace) for t in (*COUNTED, *COMMANDS, LOCKSTEP_ACK)
        }
        """Every counted and command topic with its name on the wire."""
        self._counted = tuple(self.topics[t] for t in COUNTED)
        self._commands = tuple(self.topics[t] for t in COMMANDS)
        self._received: Counter[str] = Counter()
        self._inbox: StampedInbox[Any] = StampedInbox(self._counted)
        self._ticks: deque[tuple[Any, float]] = deque()
        self._acked_commands = 0
        self._last_control_tick = -1
        self._last_update_s = -math.inf
        self.tick_time_s = 0.0
        """Lockstep: the sim time of the last tick handled."""
        self._last_q_cmd: FloatArray | None = None
        self._last_tool_command: float | None = None
        self._last_target_key: tuple[int, str] | None = None
        self._updates = 0
        self.published: Counter[str] = Counter()
        self.skipped: Counter[str] = Counter()
        self.ticks_acked = 0
        self.update_wall_s: deque[float] = deque(maxlen=200_000)
        self.tick_to_ack_wall_s: deque[float] = deque(maxlen=200_000)
        self._logged: dict[str, float] = {}
        self._error_snapshot: dict[str, int] = {}

        self.pub_traj = self._publisher(ARM_TRAJECTORY)
        self.pub_gripper = self._publisher(GRIPPER_COMMAND)
        self.pub_target = self._publisher(PICK_TARGET)
        self.pub_claim = self._publisher(CLAIM)
        self.pub_ack: Any = None
        self._outputs_matched = False
        self._counted_subs = self._subscribe_inputs()

    def _subscribe_inputs(self) -> list[Any]:
        """Subscribe to the inputs; the counted ones (and the tick in lockstep) returned."""
        counted = [
            self._subscribe(JOINT_STATES, self._on_joint_state),
            self._subscribe(BELT_STATE, self._on_belt),
            self._subscribe(DETECTIONS, self._on_detections),
            self._subscribe(CLAIMS, self._on_claims),
        ]
        self._subscribe(PRIORITIES, self._on_priorities)
        if self.lockstep:
            counted.append(self._subscribe(LOCKSTEP_TICK, self._on_tick))
        return counted

    def _publisher(self, topic: Topic) -> Any:
        return self._wire.create_publisher(
            message_class(topic), topic.resolve(self.config.station.namespace), topic.qos
        )

    def _subscribe(self, topic: Topic, callback: Any) -> Any:
        return self._wire.create_subscription(
            message_class(topic), topic.resolve(self.config.station.namespace), callback, topic.qos
        )

    def try_match(self) -> bool:
        """Lockstep: create the ack publisher once every counted subscription has matched a
        publisher, and handle the ticks that waited for it; True once the outputs have matched
        too (:meth:`outputs_matched`)."""
        if self.pub_ack is None and all(s.get_publisher_count() > 0 for s in self._counted_subs):
            self.pub_ack = self._publisher(LOCKSTEP_ACK)
        if self._ticks:
            self._drain_ticks()
        return self._outputs_matched

    def outputs_matched(self) -> bool:
        """Whether the ack publisher exists and it and every command topic has a matched
        subscriber (sticky)."""
        if not self._outputs_matched and self.pub_ack is not None:
            pubs = (self.pub_traj, self.pub_gripper, self.pub_target, self.pub_claim, self.pub_ack)
            self._outputs_matched = all(p.get_subscription_count() > 0 for p in pubs)
        return self._outputs_matched

    # -- inputs -----------------------------------------------------------------------------
    def _arrived(self, topic: str, msg: Any) -> None:
        """Count and queue a message of a counted topic (by its name on the wire)."""
        self._received[topic] += 1
        self._inbox.add(topic, msg_stamp_ns(msg.header.stamp), msg)

    def _on_joint_state(self, msg: Any) -> None:
        topic = self._counted[0]
        self._arrived(topic, msg)
        if self.lockstep:
            self._drain_ticks()
        elif self._received[topic] % self._steps_per_update == 0:
            self._consume(None)
            if self._joint is not None:
                self._control(self._joint.stamp_s)

    def _on_belt(self, msg: Any) -> None:
        self._arrived(self._counted[1], msg)
        if self.lockstep:
            self._drain_ticks()

    def _on_detections(self, msg: Any) -> None:
        self._arrived(self._counted[2], msg)
        if self.lockstep:
            self._drain_ticks()

    def _on_claims(self, msg: Any) -> None:
        self._arrived(self._counted[3], msg)
        if self.lockstep:
            self._drain_ticks()

    def _on_priorities(self, msg: Any) -> None:
        priorities, unknown = priorities_of(list(msg.classes), self.config.classes)
        if unknown:
            self.skipped["unknown_priority_class"] += len(unknown)
            self._warn("priorities", f"{PRIORITIES.name}: unknown classes {unknown} ignored")
        self._priorities = priorities
        if self._controller is not None:
            self._controller.set_class_priorities(priorities)

    def _on_tick(self, msg: Any) -> None:
        self._ticks.append((msg, time.perf_counter()))
        self._drain_ticks()

    def _consume(self, limits_ns: Sequence[int] | None) -> None:
        """Apply queued messages stamped at or before ``limits_ns`` (per counted topic; None:
        all), belt first, then detections, then claims boards, then joint states."""
        joints, belt, detections, boards = self._counted
        limit = {} if limits_ns is None else dict(zip(self._counted, limits_ns, strict=True))
        for state in self._inbox.take(belt, limit.get(belt)):
            if math.isfinite(state.speed_mps):
                self._belt_velocity_mps = (float(state.speed_mps), 0.0)
            else:
                self.skipped["bad_belt_state"] += 1
        for frame in self._inbox.take(detections, limit.get(detections)):
            stamp_s, found = detections_of(frame)
            self._tracker.update(stamp_s, found, self._belt_velocity_mps)
        for board in self._inbox.take(boards, limit.get(boards)):
            claims, bad = claims_of(board)
            if bad:
                self.skipped["bad_claim"] += bad
                self._warn("claims", f"{boards}: {bad} malformed claims ignored")
            self._apply_board(claims)
        for message in self._inbox.take(joints, limit.get(joints)):
            sample = joint_sample(message, self._arm_names, self._tool)
            if sample is None:
                self.skipped["bad_joint_state"] += 1
                self._warn("joints", f"{joints}: arm joints missing or not finite, ignored")
            else:
                self._joint = sample

    def _drain_ticks(self) -> None:
        """Handle every queued tick whose messages have all arrived, in order.

        The tick's ``last_joint_state_ns`` is the newest stamp on this station's joint states
        (every station publishes one per step, with the same stamp).
        """
        pub_ack = self.pub_ack
        if pub_ack is None or not self.outputs_matched():
            return
        while self._ticks:
            tick, arrived_wall_s = self._ticks[0]
            limits_ns = (
                int(tick.last_joint_state_ns),
                int(tick.last_belt_state_ns),
                int(tick.last_detections_ns),
                int(tick.last_claims_ns),
            )
            if not self._inbox.complete(limits_ns):
                return
            self._ticks.popleft()
            self._consume(limits_ns)
            self.tick_time_s = msg_stamp_s(tick.stamp)
            k = int(tick.tick)
            if k > self._last_control_tick and k % self._steps_per_update == 0:
                self._last_control_tick = k
                self._control(msg_stamp_s(tick.stamp))
            sent = self.n_commands - self._acked_commands
            self._acked_commands = self.n_commands
            next_tick = (k // self._steps_per_update + 1) * self._steps_per_update
            pub_ack.publish(
                message_class(LOCKSTEP_ACK)(tick=k, n_commands=sent, next_tick=next_tick)
            )
            self.ticks_acked += 1
            self.tick_to_ack_wall_s.append(time.perf_counter() - arrived_wall_s)

    # -- control ----------------------------------------------------------------------------
    @property
    def n_commands(self) -> int:
        """Cumulative command messages published (acks carry the per-tick difference)."""
        return sum(self.published[topic] for topic in self._commands)

    def _apply_board(self, claims: list[Claim]) -> None:
        """A relayed claims board: to the controller, or kept until it exists."""
        if self._controller is None:
            self._boards.append(claims)
        else:
            self._controller.apply_claims(claims)

    def _ensure_controller(self, q: FloatArray) -> PickController:
        if self._controller is None:
            self._controller = PickController(self.config, kinematics=self._kin, q_init=q)
            if self._priorities is not None:
                self._controller.set_class_priorities(self._priorities)
            for board in self._boards:
                self._controller.apply_claims(board)
            self._boards.clear()
        return self._controller

    def _control(self, t_s: float) -> None:
        """One control update at sim time ``t_s`` with the latest measured state."""
        joint = self._joint
        if joint is None:
            self.skipped["no_joint_state"] += 1
            return
        if not t_s > self._last_update_s:
            self.skipped["stale_time"] += 1
            return
        self._last_update_s = t_s
        start = time.perf_counter()
        try:
            controller = self._ensure_controller(joint.positions_rad)
            oMtool = self._kin.fk(joint.positions_rad)  # noqa: N806
            p = oMtool.translation
            measured = TcpMeasurement(
                position_m=(float(p[0]), float(p[1]), float(p[2])),
                yaw_rad=yaw_of(oMtool),
                tool_measured=joint.tool_measured,
            )
            tracks = PredictedTracks(self._tracker, t_s)
            command = controller.update(t_s, measured, tracks, self._belt_velocity_mps)
        except (ControlError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            self.skipped["controller_error"] += 1
            self._warn("controller", f"control update at t={t_s:.4f} s failed: {exc}")
            return
        self._publish(command, tracks)
        self._updates += 1
        if self._updates % ERRORS_CHECK_EVERY == 0:
            self._log_new_errors()
        self.update_wall_s.append(time.perf_counter() - start)

    def _publish(self, command: Command, tracks: Sequence[Track]) -> None:
        stamp = time_msg(command.t_s)
        self._publish_joints(command, stamp)
        value = self._tool.clip_command(command.tool_command)
        refresh = self._updates % self.config.node.gripper_refresh_every == 0
        if math.isfinite(value) and (value != self._last_tool_command or refresh):
            self.pub_gripper.publish(message_class(GRIPPER_COMMAND)(data=value))
            self.published[self._commands[1]] += 1
            self._last_tool_command = value
        key = (command.target_id or 0, str(command.phase))
        refresh = self._updates % self.config.node.target_refresh_every == 0
        if key != self._last_target_key or refresh:
            self.pub_target.publish(self._target_msg(command, tracks, stamp))
            self.published[self._commands[2]] += 1
            self._last_target_key = key
        for claim in command.claims:
            self.pub_claim.publish(claim_msg(claim))
            self.published[self._commands[3]] += 1

    def _publish_joints(self, command: Command, stamp: Any) -> None:
        q = np.asarray(command.joint_positions_rad, dtype=np.float64)
        if not self._kin.within_limits(q):
            self.skipped["unsafe_command"] += 1
            self._warn("unsafe", f"joint command {q.tolist()} outside the limits, not sent")
            return
        limit = self._kin.velocity_limit_rps
        if self._last_q_cmd is None:
            dq = np.zeros_like(q)
        else:
            dq = np.clip((q - self._last_q_cmd) / self._period_s, -limit, limit)
        self._last_q_cmd = q
        msg = message_class(ARM_TRAJECTORY)()
        msg.header.stamp = stamp
        msg.joint_names = list(self._arm_names)
        msg.points = [
            JointTrajectoryPoint(positions=[float(v) for v in q], velocities=[float(v) for v in dq])
        ]
        self.pub_traj.publish(msg)
        self.published[self._commands[0]] += 1

    def _target_msg(self, command: Command, tracks: Sequence[Track], stamp: Any) -> Any:
        msg = message_class(PICK_TARGET)(track_id=command.target_id or 0, phase=str(command.phase))
        msg.header.stamp = stamp
        msg.header.frame_id = "world"
        track = next((t for t in tracks if t.track_id == command.target_id), None)
        velocity = track.velocity_mps if track is not None else self._belt_velocity_mps
        if command.target_id is not None:
            msg.class_name = track.class_name if track is not None else ""
            msg.velocity.x, msg.velocity.y = float(velocity[0]), float(velocity[1])
        yaw = command.setpoint.position[3]
        if track is not None:
            yaw = nearest_grasp_yaw(track.yaw_rad, yaw, self._tool.grasp_yaw_period_rad)
        msg.yaw_rad = math.atan2(math.sin(yaw), math.cos(yaw))
        point = command.grasp_point_m
        if point is not None:
            lead_s = (
                self.config.motion.command_latency_s if command.phase in PURSUIT_PHASES else 0.0
            )
            msg.grasp_point.x = float(point[0] - velocity[0] * lead_s)
            msg.grasp_point.y = float(point[1] - velocity[1] * lead_s)
            msg.grasp_point.z = float(point[2])
        return msg

    # -- bookkeeping ------------------------------------------------------------------------
    def _error_counts(self) -> dict[str, int]:
        counts = {f"rejected.{k}": v for k, v in self._tracker.rejected.items()}
        if self._controller is not None:
            stats = self._controller.stats()
            counts.update({f"error.{k}": v for k, v in stats.errors.items()})
            counts.update({f"aborted.{k}": v for k, v in stats.aborted.items()})
        return counts

    def _log_new_errors(self) -> None:
        """Warn of every count of rejections, errors and aborts that grew since the last
        check (every :data:`ERRORS_CHECK_EVERY` updates: the counters are not free to read)."""
        after = self._error_counts()
        before, self._error_snapshot = self._error_snapshot, after
        for key in sorted(after):
            if after[key] > before.get(key, 0):
                if key.startswith("rejected."):
                    detail = self._tracker.last_rejection
                else:
                    detail = self._controller.last_error if self._controller is not None else ""
                self._warn(key, f"{key}: {after[key]} so far; latest: {detail}")

    def _warn(self, kind: str, text: str) -> None:
        """Rate-limited warning, one rate limit per kind of problem."""
        now_s = time.monotonic()
        if now_s - self._logged.get(kind, -math.inf) >= self.config.node.log_throttle_s:
            self._logged[kind] = now_s
            self._log.warning(text)

    def summary(self) -> ControllerStats:
        """Counters and timing (the stats file written on shutdown)."""
        return ControllerStats(
            mode="lockstep" if self.lockstep else "realtime",
            station=self.config.station.name,
            pick=self._controller.stats() if self._controller is not None else None,
            rejected_detections=dict(self._tracker.rejected),
            skipped=dict(sorted(self.skipped.items())),
            received=dict(sorted(self._received.items())),
            published={topic: self.published[topic] for topic in self._commands},
            n_commands=self.n_commands,
            control_updates=self._updates,
            ticks_acked=self.ticks_acked,
            control_update_us=_timing(list(self.update_wall_s)),
            tick_to_ack_us=_timing(list(self.tick_to_ack_wall_s)),
        )


class ControllerNode(Node, ControllerEndpoint):
    """A station's controller as a ROS 2 node, in the station's namespace."""

    def __init__(
        self, config: ControllerConfig, *, lockstep: bool, node_name: str = "controller"
    ) -> None:
        """Create publishers and subscriptions. Realtime: ``use_sim_time`` (the node's clock
        follows ``/clock``). Lockstep: time is the ticks' (no ``/clock`` subscription, one
        message a step fewer to carry), and a steady-clock timer re-checks the matching every
        5 ms until it holds (:meth:`~ControllerEndpoint.try_match`)."""
        namespace = config.station.namespace
        Node.__init__(
            self,
            node_name,
            namespace=f"/{namespace}" if namespace else "",
            parameter_overrides=[Parameter("use_sim_time", Parameter.Type.BOOL, not lockstep)],
        )
        self._wire = RosWire(self)
        self._log = self.get_logger()
        self._setup(config, lockstep=lockstep)
        if lockstep:
            self._match_timer = self.create_timer(
                0.005, self._on_match_timer, clock=Clock(clock_type=ClockType.STEADY_TIME)
            )

    def _on_match_timer(self) -> None:
        if self.try_match():
            self._match_timer.cancel()

    def sim_time_s(self) -> float:
        """Sim time, seconds: the last tick handled in lockstep, the node's clock (``/clock``
        with ``use_sim_time``) in realtime."""
        if self.lockstep:
            return self.tick_time_s
        return float(self.get_clock().now().nanoseconds) * 1e-9


class InprocController(ControllerEndpoint):
    """A station's controller on the in-process bus (``--transport inproc``), always in
    lockstep: the same topics, messages and handshake as :class:`ControllerNode`, without DDS.
    Call :meth:`~ControllerEndpoint.try_match` once the twin's endpoint exists."""

    def __init__(self, config: ControllerConfig, bus: Bus) -> None:
        """Create publishers and subscriptions on ``bus``."""
        self._wire = bus
        namespace = config.station.namespace
        self._log = InprocLogger(f"{namespace}.controller" if namespace else "controller")
        self._setup(config, lockstep=True)


__all__ = [
    "ControllerEndpoint",
    "ControllerNode",
    "InprocController",
    "JointSample",
    "Wire",
    "claim_msg",
    "claims_of",
    "detections_of",
    "joint_sample",
    "priorities_of",
]
