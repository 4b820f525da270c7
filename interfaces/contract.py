"""The ROS 2 contract between the cell and its clients: every topic once, with type and QoS.

The twin node, the controller, the recorder and the test of ``docs/interfaces.md`` all take
topic names, message types and QoS from here. A *cell* topic exists once per cell (clock, belt,
detections, events, ...); a *station* topic exists once per station, under the station's ROS
namespace: ``JOINT_STATES.resolve("s1")`` is ``/s1/joint_states``, and a station with the empty
namespace keeps the bare name ``/joint_states``.

Time: a stamp is sim time (``/clock``) in the twin and wall time on a real cell; it converts to
``(sec, nanosec)`` with :func:`time_parts` and to integer nanoseconds with :func:`stamp_ns`.
Nothing here imports ROS; :mod:`interfaces.ros` turns these values into rclpy objects.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

NS_PER_S = 1_000_000_000

Publisher = Literal["twin", "controller", "client"]
"""Who sends a topic: the cell (the twin), a station's controller, or any client."""


@dataclass(frozen=True, kw_only=True)
class Qos:
    """A topic's QoS: history keep-last ``depth``, reliability and durability."""

    depth: int
    reliable: bool = True
    latched: bool = False

    def describe(self) -> str:
        """The form ``docs/interfaces.md`` writes it in: ``reliable, volatile, keep last 10``."""
        reliability = "reliable" if self.reliable else "best effort"
        durability = "transient local" if self.latched else "volatile"
        return f"{reliability}, {durability}, keep last {self.depth}"


STATE = Qos(depth=10)
"""State and command streams."""
STREAM = Qos(depth=100)
"""Handshake and probe streams, whose every message counts."""
EVENTS = Qos(depth=1000, latched=True)
"""The event log: a late subscriber gets the last 1000."""
LATCHED = Qos(depth=1, latched=True)
"""Static configuration and the latest decision: a late subscriber gets it."""
CLOCK = Qos(depth=1, reliable=False)
"""``/clock``: only the newest matters."""
GROUND_TRUTH = Qos(depth=1, reliable=False)
"""Evaluation-only ground truth: only the newest matters."""
TRANSFORMS = Qos(depth=100)
"""``/tf``: what tf2's listeners expect (reliable, volatile, keep last 100)."""


@dataclass(frozen=True, kw_only=True)
class Topic:
    """One topic of the contract.

    ``name`` is absolute (``/clock``) for a cell topic and relative (``joint_states``) for a
    station topic; :meth:`resolve` gives the name on the wire. ``publisher`` says who sends it:
    the ``twin`` (the cell), a ``controller`` (the client of a station), or any ``client``.
    """

    name: str
    msgtype: str
    qos: Qos
    scope: Literal["cell", "station"] = "cell"
    publisher: Publisher = "twin"

    def resolve(self, namespace: str = "") -> str:
        """The topic's name on the wire for a station's ``namespace`` (cell topics ignore it)."""
        if self.scope == "cell":
            return self.name
        return f"/{namespace}/{self.name}" if namespace else f"/{self.name}"

    @property
    def package(self) -> str:
        """The message package (``sensor_msgs``)."""
        return self.msgtype.split("/", 1)[0]

    @property
    def type_name(self) -> str:
        """The message class name (``JointState``)."""
        return self.msgtype.rsplit("/", 1)[-1]


def _cell(name: str, msgtype: str, qos: Qos, publisher: Publisher = "twin") -> Topic:
    return Topic(name=name, msgtype=msgtype, qos=qos, scope="cell", publisher=publisher)


def _station(name: str, msgtype: str, qos: Qos, publisher: Publisher = "twin") -> Topic:
    return Topic(name=name, msgtype=msgtype, qos=qos, scope="station", publisher=publisher)


# -- published by the cell --------------------------------------------------------------------
CLOCK_TOPIC = _cell("/clock", "rosgraph_msgs/msg/Clock", CLOCK)
JOINT_STATES = _station("joint_states", "sensor_msgs/msg/JointState", STATE)
TCP_POSE = _station("tcp_pose", "geometry_msgs/msg/PoseStamped", STATE)
BINS = _station("cell/bins", "cdw_interfaces/msg/SortingBins", LATCHED)
BELT_STATE = _cell("/conveyor/state", "cdw_interfaces/msg/BeltState", STATE)
DETECTIONS = _cell("/objects/detections", "cdw_interfaces/msg/DetectionArray", STATE)
EVENTS_TOPIC = _cell("/events", "cdw_interfaces/msg/SortingEvent", EVENTS)
GROUND_TRUTH_TOPIC = _cell(
    "/objects/ground_truth", "cdw_interfaces/msg/ObjectStateArray", GROUND_TRUTH
)
PING_ECHO = _cell("/ping/echo", "cdw_interfaces/msg/Ping", STREAM)
LOCKSTEP_TICK = _cell("/lockstep/tick", "cdw_interfaces/msg/LockstepTick", STREAM)
FAULTS = _cell("/twin/faults", "std_msgs/msg/String", STREAM)
CLAIMS = _cell("/line/claims", "cdw_interfaces/msg/ClaimArray", STATE)

# -- the scene (visualisation: RViz, Foxglove, the episode's recording) ------------------------
TF = _cell("/tf", "tf2_msgs/msg/TFMessage", TRANSFORMS)
TF_STATIC = _cell("/tf_static", "tf2_msgs/msg/TFMessage", LATCHED)
SCENE_MARKERS = _cell("/scene/markers", "visualization_msgs/msg/MarkerArray", LATCHED)
SCENE_OBJECTS = _cell("/scene/objects", "visualization_msgs/msg/MarkerArray", LATCHED)
SCENE_TARGETS = _cell("/scene/targets", "visualization_msgs/msg/MarkerArray", STATE)
SCENE: tuple[Topic, ...] = (TF, TF_STATIC, SCENE_MARKERS, SCENE_OBJECTS, SCENE_TARGETS)
"""The scene's topics: sent only while recorded, served live or subscribed."""

CLAIM_STATES: tuple[str, ...] = ("claimed", "released", "picked")
"""The values of a ``Claim``'s ``state``: the station pursues the object, gave it up, holds it."""

# -- subscribed by the cell -------------------------------------------------------------------
ARM_TRAJECTORY = _station(
    "arm_controller/joint_trajectory", "trajectory_msgs/msg/JointTrajectory", STATE, "controller"
)
GRIPPER_COMMAND = _station("gripper/command", "std_msgs/msg/Float64", STATE, "controller")
PICK_TARGET = _station("controller/target", "cdw_interfaces/msg/PickTarget", STATE, "controller")
LOCKSTEP_ACK = _station("lockstep/ack", "cdw_interfaces/msg/StepAck", STREAM, "controller")
CLAIM = _station("line/claim", "cdw_interfaces/msg/Claim", STATE, "controller")
BELT_SETPOINT = _cell("/conveyor/speed_setpoint", "std_msgs/msg/Float64", STATE, "client")
PRIORITIES = _cell("/sorting/priorities", "cdw_interfaces/msg/SortingPriorities", LATCHED, "client")
PING = _cell("/ping", "cdw_interfaces/msg/Ping", STREAM, "client")

PUBLISHED: tuple[Topic, ...] = (
    CLOCK_TOPIC,
    JOINT_STATES,
    TCP_POSE,
    BINS,
    BELT_STATE,
    DETECTIONS,
    EVENTS_TOPIC,
    GROUND_TRUTH_TOPIC,
    PING_ECHO,
    LOCKSTEP_TICK,
    FAULTS,
    CLAIMS,
    *SCENE,
)
"""Every topic the cell publishes."""

SUBSCRIBED: tuple[Topic, ...] = (
    ARM_TRAJECTORY,
    GRIPPER_COMMAND,
    PICK_TARGET,
    LOCKSTEP_ACK,
    CLAIM,
    BELT_SETPOINT,
    PRIORITIES,
    PING,
)
"""Every topic the cell subscribes to."""

TOPICS: tuple[Topic, ...] = PUBLISHED + SUBSCRIBED
"""The whole contract."""

COUNTED: tuple[Topic, ...] = (JOINT_STATES, BELT_STATE, DETECTIONS, CLAIMS)
"""Lockstep: the topics a ``LockstepTick`` counts, in the order of its ``last_*_ns`` fields."""

COMMANDS: tuple[Topic, ...] = (ARM_TRAJECTORY, GRIPPER_COMMAND, PICK_TARGET, CLAIM)
"""Lockstep: the station topics whose messages a ``StepAck`` counts in ``n_commands``."""


def station_topics(namespace: str) -> dict[Topic, str]:
    """Every station topic with its name on the wire for ``namespace``."""
    return {t: t.resolve(namespace) for t in TOPICS if t.scope == "station"}


def resolved_topics(namespaces: tuple[str, ...]) -> list[tuple[str, Topic]]:
    """Every topic of a cell with the given station namespaces, as ``(wire name, topic)``;
    cell topics once, station topics once per station."""
    out: list[tuple[str, Topic]] = []
    for topic in TOPICS:
        if topic.scope == "cell":
            out.append((topic.name, topic))
        else:
            out.extend((topic.resolve(ns), topic) for ns in namespaces)
    return out


# -- time ---------------------------------------------------------------------------------------
def time_parts(t_s: float) -> tuple[int, int]:
    """``(sec, nanosec)`` of ``t_s >= 0`` seconds; a fraction that rounds up to 1 s carries."""
    sec = int(t_s)
    nanosec = round((t_s - sec) * 1e9)
    if nanosec >= NS_PER_S:
        sec, nanosec = sec + 1, nanosec - NS_PER_S
    return sec, nanosec


def stamp_ns(sec: int, nanosec: int) -> int:
    """Integer nanoseconds of a ``(sec, nanosec)`` stamp."""
    return int(sec) * NS_PER_S + int(nanosec)


def stamp_s(sec: int, nanosec: int) -> float:
    """Seconds of a ``(sec, nanosec)`` stamp."""
    return float(sec) + 1e-9 * float(nanosec)
