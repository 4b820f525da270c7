"""A pure closed-loop line: a stream of objects, every station's controller, ideal arms.

The objects ride the belt at constant speed (nothing pushes them); a simulated camera over the
cell's field of view reports every object lying on the belt at 30 Hz with Gaussian noise and
latency, and every controller's tracker gets the same frames (stations whose tracking tuning
is the same share one tracker: their tracks would be identical). Each station's arm reaches
every joint command exactly ``command_latency_s`` after it was issued; its tool is simulated
against the objects: a gripper's fingers move towards the commanded opening and stop on the
sides of the object they close around at its centre (it is then held, and follows the TCP); a
suction cup with the vacuum on seals on the object whose top holds the lip's disc at the lip,
the vacuum builds up over ``build_up_s`` and the object is held once it has; opening the
fingers or venting the cup lets the object go: into the bin under it, back onto the belt, or
onto the floor. The claims each controller makes are relayed to every controller in the next
control period, as the twin's board is (:mod:`control.allocation`). Objects that pass the end
of the belt are lost.

This is where the line's allocation and the cycle times are measured without physics: picks
per minute per station, recovery (objects placed in their class's bin / objects that passed
the last window), and what every controller counted. Used by the tests and to explore lines
(stations, tools, tuning) before running them in the twin.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from control.allocation import Claim
from control.config import ControllerConfig, TrackingConfig
from control.ik import Kinematics, yaw_of
from control.kinematic_sim import CameraSpec
from control.pick import Phase, PickController, PickStats, TcpMeasurement
from control.tracking import Detection, Tracker
from interfaces.cell import Cell
from interfaces.tools import ParallelJawSpec, SuctionCupSpec

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]

FINGER_SPEED_MPS = 0.2
"""Opening speed of a simulated gripper (both fingers together)."""
GRASP_RADIUS_M = 0.01
"""A gripper closing with the TCP this near an object's centre (and between its underside and
top) closes around it."""


@dataclass(frozen=True, kw_only=True)
class StreamObject:
    """An object of the stream: its footprint centroid ``(x0_m, y_m)`` on the belt at t = 0,
    long-side yaw, footprint, height and class."""

    x0_m: float
    y_m: float
    yaw_rad: float
    length_m: float
    width_m: float
    height_m: float
    class_name: str


@dataclass(frozen=True, kw_only=True)
class StreamSpec:
    """A synthetic stream: objects arrive at the infeed at ``rate_per_s`` (evenly, each
    jittered by up to half the spacing), at a uniform lateral position where they do not
    overlap an earlier one; narrow side log-uniform in ``narrow_m``, long side that times a
    uniform ``aspect``, height uniform in ``height_m``, yaw uniform, classes in turn."""

    rate_per_s: float = 2.0
    classes: tuple[str, ...] = ("concrete", "brick", "wood", "rubber")
    narrow_m: tuple[float, float] = (0.04, 0.12)
    aspect: tuple[float, float] = (1.0, 2.5)
    height_m: tuple[float, float] = (0.02, 0.08)


def random_stream(
    spec: StreamSpec, *, cell: Cell, speed_mps: float, duration_s: float, seed: int = 0
) -> tuple[StreamObject, ...]:
    """The objects of ``spec`` that reach the belt's infeed within ``duration_s``, placed at
    t = 0 where they will be (upstream of the infeed)."""
    rng = np.random.default_rng(seed)
    belt = cell.belt
    spacing_s = 1.0 / spec.rate_per_s
    placed: list[StreamObject] = []
    for i in range(int(duration_s * spec.rate_per_s)):
        arrive_s = (i + 0.5 + rng.uniform(-0.5, 0.5)) * spacing_s
        narrow = math.exp(rng.uniform(*np.log(spec.narrow_m)))
        length = narrow * rng.uniform(*spec.aspect)
        radius = 0.5 * math.hypot(narrow, length)
        x0 = belt.infeed_x_m - speed_mps * arrive_s
        for _ in range(20):
            half = 0.5 * belt.width_m - radius
            y = belt.centre_y_m + (rng.uniform(-half, half) if half > 0 else 0.0)
            clear = all(
                math.hypot(o.x0_m - x0, o.y_m - y)
                > radius + 0.5 * math.hypot(o.length_m, o.width_m)
                for o in placed[-8:]
            )
            if clear:
                placed.append(
                    StreamObject(
                        x0_m=x0,
                        y_m=y,
                        yaw_rad=rng.uniform(-0.5 * math.pi, 0.5 * math.pi),
                        length_m=length,
                        width_m=narrow,
                        height_m=rng.uniform(*spec.height_m),
                        class_name=spec.classes[i % len(spec.classes)],
                    )
                )
                break
    return tuple(placed)


@dataclass(frozen=True, kw_only=True)
class LineResult:
    """Outcome of a line episode.

    ``passed`` counts the objects that passed the end of the last station's window (by the
    belt's motion) during the episode, ``passed_by_class`` per class; ``placed_correct_by_class``
    those of them placed in a bin of their class, ``placed_wrong`` in another bin,
    ``placed_by_station`` per station the objects its tool put in a bin of their class (all of
    them, however far they were); ``dropped`` objects let go outside the bins and the belt;
    ``lost`` objects that passed the end of the belt; ``stats`` each station's controller
    counters; ``relayed_claims`` every claim relayed, in order; ``phase_s`` per station the
    time spent in each phase of the pick sequence; ``approach_strikes`` per station the objects
    its tool ran into on the way to a target (:func:`_strikes`: nothing here pushes them, in
    the twin the tool would have).
    """

    duration_s: float
    passed: int
    passed_by_class: dict[str, int]
    placed_correct_by_class: dict[str, int]
    placed_wrong: int
    placed_by_station: dict[str, int]
    dropped: int
    lost: int
    stats: dict[str, PickStats]
    relayed_claims: tuple[Claim, ...]
    phase_s: dict[str, dict[str, float]] = field(default_factory=dict)
    approach_strikes: dict[str, int] = field(default_factory=dict)

    @property
    def recovery(self) -> float:
        """Objects placed in their class's bin / objects that passed the last window."""
        placed = sum(self.placed_correct_by_class.values())
        return placed / self.passed if self.passed else 0.0

    def picks_per_min(self, station: str) -> float:
        """Objects the station placed in their class's bin, per minute."""
        return 60.0 * self.placed_by_station.get(station, 0) / self.duration_s


@dataclass(kw_only=True, eq=False)
class _Body:
    """An object's state: on the belt, held by a station, or done (binned, dropped, lost)."""

    spec: StreamObject
    index: int
    x0_m: float
    y_m: float
    state: str = "belt"
    holder: str = ""
    base_z_m: float = 0.0

    def position_at(self, t_s: float, speed_mps: float) -> tuple[float, float]:
        """Where it lies on the belt at ``t_s``."""
        return (self.x0_m + speed_mps * t_s, self.y_m)

    def holds_point(self, x: float, y: float, t_s: float, speed_mps: float) -> float:
        """The least room from ``(x, y)`` to the edges of its footprint (negative: outside)."""
        cx, cy = self.position_at(t_s, speed_mps)
        c, s = math.cos(self.spec.yaw_rad), math.sin(self.spec.yaw_rad)
        dx, dy = x - cx, y - cy
        along, across = dx * c + dy * s, -dx * s + dy * c
        return min(0.5 * self.spec.length_m - abs(along), 0.5 * self.spec.width_m - abs(across))


class _Camera:
    """Frames of every object on the belt inside the field of view, delivered late."""

    def __init__(self, camera: CameraSpec, cell: Cell, speed_mps: float, seed: int) -> None:
        self._camera, self._cell, self._speed_mps = camera, cell, speed_mps
        self._rng = np.random.default_rng(seed)
        self._pending: deque[tuple[float, float, list[Detection]]] = deque()
        self._frame = 0

    def capture(self, t_s: float, bodies: Sequence[_Body]) -> None:
        """Take the frames captured up to ``t_s``."""
        camera, rng, fov = self._camera, self._rng, self._cell.camera
        while self._frame / camera.rate_hz <= t_s + 1e-12:
            stamp = self._frame / camera.rate_hz
            found = []
            for body in bodies:
                x, y = body.position_at(stamp, self._speed_mps)
                if body.state != "belt" or not fov.fov_min_x_m <= x <= fov.fov_max_x_m:
                    continue
                o = body.spec
                found.append(
                    Detection(
                        stamp_s=stamp,
                        class_name=o.class_name,
                        confidence=0.9,
                        x_m=x + rng.normal(0.0, camera.position_std_m),
                        y_m=y + rng.normal(0.0, camera.position_std_m),
                        yaw_rad=o.yaw_rad + rng.normal(0.0, camera.yaw_std_rad),
                        length_m=o.length_m,
                        width_m=o.width_m,
                        height_m=o.height_m,
                        base_z_m=body.base_z_m,
                    )
                )
            self._pending.append((stamp + camera.latency_s, stamp, found))
            self._frame += 1

    def deliver(self, t_s: float, trackers: Sequence[Tracker]) -> None:
        """Feed every tracker the frames that arrived by ``t_s``."""
        while self._pending and self._pending[0][0] <= t_s:
            _, stamp, found = self._pending.popleft()
            for tracker in trackers:
                tracker.update(stamp, found, (self._speed_mps, 0.0))


@dataclass(kw_only=True, eq=False)
class _Tool:
    """A station's simulated tool: the measured value and the object it holds."""

    spec: ParallelJawSpec | SuctionCupSpec
    value: float
    command: float
    held: _Body | None = None
    sealed: _Body | None = None


class _Station:
    """One station: its controller, ideal arm (latency) and simulated tool."""

    def __init__(self, config: ControllerConfig) -> None:
        self.config = config
        self.name = config.station.name
        self.controller = PickController(config)
        self.kin: Kinematics = self.controller.kinematics
        dt_s = config.motion.control_period_s
        delay = max(round(config.motion.command_latency_s / dt_s), 1)
        self.in_flight: deque[FloatArray] = deque([self.controller.q_ready.copy()] * delay)
        open_value = config.tool.open_command
        self.tool = _Tool(spec=config.station.tool, value=open_value, command=open_value)
        self.placed = 0
        self.phase_s: dict[str, float] = {}
        self.struck: set[int] = set()

    def tcp(self) -> tuple[Vec3, float]:
        """The TCP now (the command of ``command_latency_s`` ago) and its yaw."""
        oMtool = self.kin.fk(self.in_flight.popleft())  # noqa: N806
        p = oMtool.translation
        return (float(p[0]), float(p[1]), float(p[2])), yaw_of(oMtool)


@dataclass(kw_only=True)
class _World:
    """The objects and the belt."""

    cell: Cell
    speed_mps: float
    bodies: list[_Body]
    lost: int = 0
    dropped: int = 0
    placed: dict[int, str] = field(default_factory=dict)

    def top_z(self, body: _Body) -> float:
        return self.cell.belt.surface_z_m + body.base_z_m + body.spec.height_m

    def under(self, tcp: Vec3, t_s: float) -> tuple[_Body, float] | None:
        """The object on the belt whose footprint holds ``tcp``'s point with the most room."""
        best: tuple[_Body, float] | None = None
        for body in self.bodies:
            if body.state != "belt":
                continue
            room = body.holds_point(tcp[0], tcp[1], t_s, self.speed_mps)
            if room >= 0.0 and (best is None or room > best[1]):
                best = (body, room)
        return best

    def let_go(self, body: _Body, tcp: Vec3, t_s: float) -> str:
        """``body`` falls from ``tcp``: into a bin (its class name), onto the belt or the
        floor."""
        target = self.cell.bin_at(tcp[0], tcp[1])
        if target is not None:
            body.state = "binned"
            self.placed[body.index] = target.class_name
            return target.class_name
        if self.cell.belt.on_belt_xy(tcp[0], tcp[1]):
            body.state, body.holder = "belt", ""
            body.x0_m, body.y_m = tcp[0] - self.speed_mps * t_s, tcp[1]
            return ""
        body.state = "dropped"
        self.dropped += 1
        return ""

    def lose_past_end(self, t_s: float) -> None:
        for body in self.bodies:
            if body.state == "belt" and body.position_at(t_s, self.speed_mps)[0] > (
                self.cell.belt.end_x_m
            ):
                body.state = "lost"
                self.lost += 1


def _closes_on(tool: _Tool, world: _World, tcp: Vec3, t_s: float, step_m: float) -> _Body | None:
    """The object the closing fingers reach in this step: around it (the TCP near its centre,
    between its underside and top), opened wider than it, and closing to it."""
    found = world.under(tcp, t_s)
    if found is None:
        return None
    body = found[0]
    cx, cy = body.position_at(t_s, world.speed_mps)
    low = world.cell.belt.surface_z_m + body.base_z_m
    around = math.hypot(tcp[0] - cx, tcp[1] - cy) <= GRASP_RADIUS_M
    width = body.spec.width_m
    reached = tool.value >= width >= tool.value - step_m
    return body if around and low <= tcp[2] <= world.top_z(body) and reached else None


def _step_jaw(tool: _Tool, world: _World, tcp: Vec3, t_s: float, dt_s: float) -> None:
    """Fingers move towards the command; closing at an object's centre they stop on it."""
    step = FINGER_SPEED_MPS * dt_s
    if tool.held is None and tool.command < tool.value:
        body = _closes_on(tool, world, tcp, t_s, step)
        if body is not None:
            tool.held, body.state = body, "held"
    goal = tool.command
    if tool.held is not None:
        goal = max(goal, tool.held.spec.width_m)
    tool.value += min(max(goal - tool.value, -step), step)


def _step_cup(
    tool: _Tool, spec: SuctionCupSpec, world: _World, tcp: Vec3, t_s: float, dt_s: float
) -> None:
    """The vacuum seals on the object under the lip, builds up, and holds it; off, it vents."""
    on = tool.command >= 0.5
    if on and tool.sealed is None and tool.held is None:
        found = world.under(tcp, t_s)
        if found is not None:
            body, room = found
            touching = abs(tcp[2] - world.top_z(body)) <= spec.contact_tolerance_m
            if touching and room >= 0.5 * spec.cup_diameter_m:
                tool.sealed = body
    if tool.sealed is not None and tool.held is None:
        lifted = tcp[2] - world.top_z(tool.sealed) > spec.contact_tolerance_m
        if not on or lifted:
            tool.sealed = None  # lifted off before the vacuum held it
    if on and (tool.sealed is not None or tool.held is not None):
        tool.value = min(1.0, tool.value + dt_s / spec.build_up_s)
    else:
        tool.value = max(0.0, tool.value - dt_s / spec.vent_s)
    if tool.sealed is not None and tool.value >= 1.0:
        tool.held, tool.sealed = tool.sealed, None
        tool.held.state = "held"


def _released(tool: _Tool) -> bool:
    """Whether the tool no longer holds its object: fingers opened past it, vacuum vented."""
    if tool.held is None:
        return False
    if isinstance(tool.spec, SuctionCupSpec):
        return tool.command < 0.5 and tool.value < 0.5
    return tool.value > tool.held.spec.width_m + 0.005


def _step_tool(station: _Station, world: _World, tcp: Vec3, t_s: float, dt_s: float) -> None:
    tool = station.tool
    if isinstance(tool.spec, SuctionCupSpec):
        _step_cup(tool, tool.spec, world, tcp, t_s, dt_s)
    else:
        _step_jaw(tool, world, tcp, t_s, dt_s)
    if tool.held is not None:
        tool.held.holder = station.name
    if _released(tool):
        assert tool.held is not None
        if world.let_go(tool.held, tcp, t_s) == tool.held.spec.class_name:
            station.placed += 1
        tool.held = None


@dataclass(kw_only=True)
class _Board:
    """The claims board, relayed as the twin relays it."""

    entries: dict[tuple[str, int], Claim] = field(default_factory=dict)
    relayed: list[Claim] = field(default_factory=list)

    def relay(self, claims: Sequence[Claim]) -> tuple[Claim, ...] | None:
        """Take a period's claims; the board to relay, or None when it did not change."""
        if not claims:
            return None
        for claim in claims:
            self.entries[(claim.station, claim.track_id)] = claim
        board = tuple(self.entries[key] for key in sorted(self.entries))
        self.relayed.extend(claims)
        for key in [k for k, c in self.entries.items() if c.state != "claimed"]:
            del self.entries[key]
        return board


def run_line(
    configs: Sequence[ControllerConfig],
    objects: Sequence[StreamObject],
    *,
    speed_mps: float,
    duration_s: float,
    seed: int = 0,
    camera: CameraSpec | None = None,
) -> LineResult:
    """Run the stations of ``configs`` (one per station of one cell) on ``objects`` at belt
    speed ``speed_mps`` for ``duration_s``."""
    cell = configs[0].cell
    dt_s = configs[0].motion.control_period_s
    world = _World(
        cell=cell,
        speed_mps=speed_mps,
        bodies=[_Body(spec=o, index=i, x0_m=o.x0_m, y_m=o.y_m) for i, o in enumerate(objects)],
    )
    stations = [_Station(config) for config in configs]
    trackers: dict[TrackingConfig, Tracker] = {}
    for config in configs:
        trackers.setdefault(config.tracking, Tracker(config.tracking, classes=config.classes))
    tracker_of = [trackers[config.tracking] for config in configs]
    sim_camera = _Camera(camera or CameraSpec(), cell, speed_mps, seed)
    board = _Board()
    outbox: list[Claim] = []
    for tick in range(round(duration_s / dt_s)):
        t_s = tick * dt_s
        relayed = board.relay(outbox)
        outbox = []
        sim_camera.capture(t_s, world.bodies)
        sim_camera.deliver(t_s, list(trackers.values()))
        for station, tracker in zip(stations, tracker_of, strict=True):
            if relayed is not None:
                station.controller.apply_claims(relayed)
            outbox.extend(_step_station(station, world, tracker, t_s, dt_s))
        world.lose_past_end(t_s)
    return _result(world, stations, board, duration_s)


def _step_station(
    station: _Station, world: _World, tracker: Tracker, t_s: float, dt_s: float
) -> tuple[Claim, ...]:
    """One control period of a station; the claims it made."""
    tcp, yaw = station.tcp()
    if station.controller.phase is Phase.APPROACH:  # the phase the TCP is moving in
        station.struck.update(_strikes(station, world, tcp, t_s))
    _step_tool(station, world, tcp, t_s, dt_s)
    measured = TcpMeasurement(position_m=tcp, yaw_rad=yaw, tool_measured=station.tool.value)
    command = station.controller.update(
        t_s, measured, tracker.predict_to(t_s), (world.speed_mps, 0.0)
    )
    station.tool.command = command.tool_command
    phase = str(command.phase)
    station.phase_s[phase] = station.phase_s.get(phase, 0.0) + dt_s
    station.in_flight.append(np.asarray(command.joint_positions_rad))
    return command.claims


def _strikes(station: _Station, world: _World, tcp: Vec3, t_s: float) -> list[int]:
    """The objects on the belt the tool is in now: the TCP below an object's top with the
    tool's body over its footprint (a suction cup's stem disc, ``body_radius_m``; a gripper's
    TCP point). Asked during the approach, where the tool should pass above everything."""
    spec = station.tool.spec
    radius_m = spec.body_radius_m if isinstance(spec, SuctionCupSpec) else 0.0
    return [
        body.index
        for body in world.bodies
        if body.state == "belt"
        and tcp[2] < world.top_z(body)
        and body.holds_point(tcp[0], tcp[1], t_s, world.speed_mps) >= -radius_m
    ]


def _result(
    world: _World, stations: Sequence[_Station], board: _Board, duration_s: float
) -> LineResult:
    end_x = world.cell.last_window_max_x_m
    passed_by_class: dict[str, int] = {}
    correct_by_class: dict[str, int] = {}
    wrong = 0
    for body in world.bodies:
        if body.spec.x0_m + world.speed_mps * duration_s <= end_x:
            continue  # still upstream of the last window: not judged
        name = body.spec.class_name
        passed_by_class[name] = passed_by_class.get(name, 0) + 1
        binned = world.placed.get(body.index)
        if binned == name:
            correct_by_class[name] = correct_by_class.get(name, 0) + 1
        elif binned is not None:
            wrong += 1
    return LineResult(
        duration_s=duration_s,
        passed=sum(passed_by_class.values()),
        passed_by_class=passed_by_class,
        placed_correct_by_class=correct_by_class,
        placed_wrong=wrong,
        placed_by_station={s.name: s.placed for s in stations},
        dropped=world.dropped,
        lost=world.lost,
        stats={s.name: s.controller.stats() for s in stations},
        relayed_claims=tuple(board.relayed),
        phase_s={s.name: dict(s.phase_s) for s in stations},
        approach_strikes={s.name: len(s.struck) for s in stations},
    )
