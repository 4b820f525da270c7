"""A pure closed-loop episode: tracker + pick controller + an ideal (kinematic) arm.

One object moves on the belt at constant speed; a simulated camera reports it at 30 Hz with
Gaussian noise and latency; the arm reaches every joint command exactly ``command_latency_s``
after it was issued. With a :class:`GripperSpec` the station's tool is simulated and the
controller gets its measurement: a gripper's fingers move towards the commanded opening at a
finite speed and stop on the object's sides when they close around it (or close on nothing
when it is not ``grippable``); a suction cup with the vacuum on seals once its lip lies on the
object's top with the lip's disc inside it (never when not ``grippable``), and the vacuum then
builds up over the cup's ``build_up_s`` (off: it vents over ``vent_s``). Without one the tool
is not measured. The episode measures the tracking time to 4 mm (from the start of tracking
the target until the TCP-to-grasp-point distance stays below 4 mm until the gripper has closed)
by ground truth, with the rule the twin uses (:class:`interfaces.metrics.SettleTimer`). Used by
the tests and by ``python -m control.bench``.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from control.config import ControllerConfig
from control.ik import Kinematics, yaw_of
from control.pick import Command, Phase, PickController, PickStats, TcpMeasurement
from control.scheduler import grasp_z_m
from control.tracking import Detection, Tracker
from interfaces.metrics import SettleTimer
from interfaces.tools import SuctionCupSpec


@dataclass(frozen=True, kw_only=True)
class ObjectSpec:
    """The moving object: start position, footprint, class and yaw."""

    x0_m: float = -0.7
    y_m: float = 0.52
    yaw_rad: float = 0.3
    length_m: float = 0.12
    width_m: float = 0.05
    height_m: float = 0.04
    class_name: str = "brick"


@dataclass(frozen=True, kw_only=True)
class CameraSpec:
    """Detection noise, rate and latency of the simulated perception."""

    rate_hz: float = 30.0
    latency_s: float = 0.03
    position_std_m: float = 0.002
    yaw_std_rad: float = 0.02


@dataclass(frozen=True, kw_only=True)
class GripperSpec:
    """The simulated tool: a gripper's opening speed (m/s, both fingers together) and whether
    the object can be gripped at all (False: the fingers close past it, a cup never seals, as
    on a missed grasp)."""

    speed_mps: float = 0.2
    grippable: bool = True


@dataclass(frozen=True, kw_only=True)
class EpisodeResult:
    """Outcome of one episode.

    ``tracking_time_4mm_s`` is NaN when the TCP never stayed within 4 mm until the close ended;
    ``max_follow_error_m`` is the largest TCP-to-grasp-point distance during dwell and close;
    ``release_tcp_m`` is where the TCP was when the gripper first opened over a bin;
    ``openings_m`` is the measured gripper opening at every tick (NaN without a gripper).
    """

    tracking_time_4mm_s: float
    max_follow_error_m: float
    phases: tuple[tuple[float, Phase], ...]
    stats: PickStats
    max_joint_limit_violation_rad: float
    release_tcp_m: tuple[float, float, float] | None
    openings_m: tuple[float, ...] = ()


class _SimCamera:
    """Noisy detections of the object at ``camera.rate_hz``, delivered ``latency_s`` late."""

    def __init__(self, camera: CameraSpec, obj: ObjectSpec, speed_mps: float, seed: int) -> None:
        self._camera, self._obj, self._speed_mps = camera, obj, speed_mps
        self._rng = np.random.default_rng(seed)
        self._pending: deque[tuple[float, Detection]] = deque()
        self._frame = 0

    def deliver(self, t_s: float, tracker: Tracker) -> None:
        """Take the frames captured up to ``t_s`` and feed the tracker those that arrived."""
        camera, obj, rng = self._camera, self._obj, self._rng
        while self._frame / camera.rate_hz <= t_s + 1e-12:
            stamp = self._frame / camera.rate_hz
            detection = Detection(
                stamp_s=stamp,
                class_name=obj.class_name,
                confidence=0.9,
                x_m=obj.x0_m + self._speed_mps * stamp + rng.normal(0.0, camera.position_std_m),
                y_m=obj.y_m + rng.normal(0.0, camera.position_std_m),
                yaw_rad=obj.yaw_rad + rng.normal(0.0, camera.yaw_std_rad),
                length_m=obj.length_m,
                width_m=obj.width_m,
                height_m=obj.height_m,
            )
            self._pending.append((stamp + camera.latency_s, detection))
            self._frame += 1
        while self._pending and self._pending[0][0] <= t_s:
            _, detection = self._pending.popleft()
            tracker.update(detection.stamp_s, [detection], (self._speed_mps, 0.0))


class _SimGripper:
    """Fingers moving at ``gripper.speed_mps`` towards the command, stopped by the object's
    sides once they closed around it at the grasp point (unless it is not ``grippable``)."""

    def __init__(self, gripper: GripperSpec, object_width_m: float, open_m: float) -> None:
        self._gripper, self._width_m = gripper, object_width_m
        self.opening_m = open_m
        self.commanded_m = open_m
        self._holding = False

    def step(self, distance_m: float, dt_s: float, _lip: tuple[float, float, float]) -> float:
        """Move for ``dt_s`` with the TCP ``distance_m`` from the grasp point; the opening."""
        self._holding = self._gripper.grippable and (self._holding or distance_m < 0.01)
        goal = max(self.commanded_m, self._width_m) if self._holding else self.commanded_m
        step = self._gripper.speed_mps * dt_s
        self.opening_m += min(max(goal - self.opening_m, -step), step)
        self._holding = self._holding and self.opening_m <= self._width_m + 1e-9
        return self.opening_m


Lip = tuple[float, float, float]
"""Where a cup's lip is on an object: the room from the lip's centre to the top face's edges
along and across the object, and the lip's height above the top (m)."""


class _SimCup:
    """A suction cup: sealed while the vacuum is on once the lip lay on the object's top with
    its disc inside the top face (unless the object is not ``grippable``); the vacuum fraction
    builds up over ``build_up_s`` while sealed and vents over ``vent_s`` otherwise."""

    def __init__(self, spec: SuctionCupSpec, gripper: GripperSpec) -> None:
        self._spec, self._gripper = spec, gripper
        self.commanded_m = 0.0
        self.vacuum = 0.0
        self._sealed = False

    def step(self, _distance_m: float, dt_s: float, lip: Lip) -> float:
        """Advance ``dt_s`` with the lip at ``lip``; the measured vacuum fraction."""
        spec = self._spec
        room_along, room_across, above = lip
        seals = (
            self._gripper.grippable
            and abs(above) <= spec.contact_tolerance_m
            and min(room_along, room_across) >= 0.5 * spec.cup_diameter_m
        )
        self._sealed = self.commanded_m >= 0.5 and (self._sealed or seals)
        if self._sealed:
            self.vacuum = min(1.0, self.vacuum + dt_s / spec.build_up_s)
        else:
            self.vacuum = max(0.0, self.vacuum - dt_s / spec.vent_s)
        return self.vacuum


def _lip(tcp_m: tuple[float, float, float], obj: ObjectSpec, x_m: float, top_z_m: float) -> Lip:
    """The lip at ``tcp_m`` on ``obj`` whose centre is at ``(x_m, obj.y_m)``."""
    dx, dy = tcp_m[0] - x_m, tcp_m[1] - obj.y_m
    c, s = math.cos(obj.yaw_rad), math.sin(obj.yaw_rad)
    along, across = dx * c + dy * s, -dx * s + dy * c
    return (
        0.5 * obj.length_m - abs(along),
        0.5 * obj.width_m - abs(across),
        tcp_m[2] - top_z_m,
    )


def _sim_tool(
    cfg: ControllerConfig, gripper: GripperSpec, obj: ObjectSpec
) -> _SimGripper | _SimCup:
    """The station's tool, simulated."""
    spec = cfg.station.tool
    if isinstance(spec, SuctionCupSpec):
        return _SimCup(spec, gripper)
    return _SimGripper(gripper, obj.width_m, cfg.tool.open_command)


def _violation_rad(kin: Kinematics, q: np.ndarray) -> float:
    """How far ``q`` lies outside the joint limits (0 inside)."""
    return float(np.max(np.maximum(kin.lower_rad - q, 0.0) + np.maximum(q - kin.upper_rad, 0.0)))


def run_episode(
    speed_mps: float,
    *,
    seed: int = 0,
    duration_s: float = 3.5,
    config: ControllerConfig | None = None,
    obj: ObjectSpec | None = None,
    camera: CameraSpec | None = None,
    gripper: GripperSpec | None = None,
) -> EpisodeResult:
    """Run one closed-loop episode at belt speed ``speed_mps`` and measure it."""
    cfg = config if config is not None else ControllerConfig()
    obj = obj if obj is not None else ObjectSpec()
    sim_camera = _SimCamera(camera or CameraSpec(), obj, speed_mps, seed)
    controller = PickController(cfg)
    kin = controller.kinematics
    tracker = Tracker(cfg.tracking, classes=cfg.classes)
    dt_s = cfg.motion.control_period_s
    delay_ticks = max(round(cfg.motion.command_latency_s / dt_s), 1)
    in_flight: deque[np.ndarray] = deque([controller.q_ready.copy()] * delay_ticks)
    grasp_z = grasp_z_m(obj.height_m, cfg)
    history: list[tuple[float, Phase, float]] = []
    phases: list[tuple[float, Phase]] = []
    worst_violation = 0.0
    release_tcp_m: tuple[float, float, float] | None = None
    fingers = None if gripper is None else _sim_tool(cfg, gripper, obj)
    openings: list[float] = []
    for tick in range(round(duration_s / dt_s)):
        t_s = tick * dt_s
        sim_camera.deliver(t_s, tracker)
        oMtool = kin.fk(in_flight.popleft())  # noqa: N806
        p = oMtool.translation
        tcp_m = (float(p[0]), float(p[1]), float(p[2]))
        distance = math.dist(tcp_m, (obj.x0_m + speed_mps * t_s, obj.y_m, grasp_z))
        lip = _lip(tcp_m, obj, obj.x0_m + speed_mps * t_s, cfg.belt.surface_z_m + obj.height_m)
        openings.append(math.nan if fingers is None else fingers.step(distance, dt_s, lip))
        measured = TcpMeasurement(
            position_m=tcp_m, yaw_rad=yaw_of(oMtool), tool_measured=openings[-1]
        )
        command: Command = controller.update(
            t_s, measured, tracker.predict_to(t_s), (speed_mps, 0.0)
        )
        if fingers is not None:
            fingers.commanded_m = command.tool_command
        q_cmd = np.asarray(command.joint_positions_rad)
        worst_violation = max(worst_violation, _violation_rad(kin, q_cmd))
        in_flight.append(q_cmd)
        if not phases or phases[-1][1] != command.phase:
            phases.append((t_s, command.phase))
        history.append((t_s, command.phase, distance))
        if command.phase == Phase.RELEASE and release_tcp_m is None:
            release_tcp_m = measured.position_m
    return EpisodeResult(
        tracking_time_4mm_s=_tracking_time(history),
        max_follow_error_m=max(
            (d for _, p, d in history if p in (Phase.DWELL, Phase.CLOSE)), default=math.nan
        ),
        phases=tuple(phases),
        stats=controller.stats(),
        max_joint_limit_violation_rad=worst_violation,
        release_tcp_m=release_tcp_m,
        openings_m=tuple(openings),
    )


def _tracking_time(history: list[tuple[float, Phase, float]]) -> float:
    """Time from the first approach until the distance stays < 4 mm to the end of the close
    (NaN when there was no close, or the distance was not below 4 mm at its end)."""
    start = next((t for t, p, _ in history if p == Phase.APPROACH), None)
    close_end = max((t for t, p, _ in history if p == Phase.CLOSE), default=None)
    if start is None or close_end is None:
        return math.nan
    timer = SettleTimer(start)
    for t_s, _, distance_m in history:
        if start <= t_s <= close_end:
            timer.update(t_s, distance_m)
    settled_s = timer.settled_after_s
    return math.nan if settled_s is None else settled_s
