"""The twin: PyBullet scene co-simulated with the belt-drive FMU, with events and ground truth.

``Twin`` follows Gymnasium's shape without depending on it::

    with Twin(scenario, dataset_dir=Path("out/meshes")) as twin:
        obs, info = twin.reset(seed=3)
        while True:
            obs, reward, terminated, truncated, info = twin.step(action)
            if terminated or truncated:
                break

``action`` is an :class:`ArmCommand` (joint targets, optional feed-forward velocities, gripper
opening) or ``None`` to keep the last one: the scripted-arm hook for tests and users. The
co-simulation master runs a fixed physics step (240 Hz default); every ``fmu_every_n_steps`` it
sets the FMU's inputs (setpoint, mass on the belt), calls ``doStep`` and reads the belt speed that
drives the kinematic belt. Time is ``step * dt``, never accumulated.

The camera model is the scenario's ``perception`` unless a :class:`PerceptionConfig` is passed.
Injected faults (the scenario's ``faults``): inside a ``belt_stall`` window the FMU receives a
setpoint of 0 whatever was commanded (``setpoint_mps`` keeps the commanded value); inside a
``detection_dropout`` window no detection frame is released. Each window's start and end is
logged as a ``fault`` event with ``kind`` ``injected_belt_stall`` / ``injected_detection_dropout``.

Every event the twin logs is also handed, as it is logged, to its ``event_sink`` when one is set
(e.g. :meth:`twin.episode_log.EventLog.append`): a caller streams the episode's events to disk
as they happen, so a killed process still leaves them behind.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import TracebackType

import numpy as np
import pybullet as pb

from interfaces.events import Event, EventType
from twin.belt_drive import BeltDrive, BeltState
from twin.builtin import cache_root
from twin.config import ROBOTS, CellConfig
from twin.errors import ConfigError
from twin.monitor import GroundTruth, Monitor
from twin.objects import ImageLayout, load_dataset
from twin.perception import DetectionFrame, Perception, PerceptionConfig
from twin.robot import Robot
from twin.scenario import Scenario, seed_tree
from twin.scores import Scores, compute_scores
from twin.stream import ImageBatch, Stream
from twin.target_metric import TargetTracker
from twin.world import World

# Names of the belt-drive FMU's perturbation parameters (see fmus/belt_drive/readme.md).
PERTURBATION_PARAMETERS = (
    "perturbation_std_N",
    "perturbation_correlation_time_s",
    "perturbation_seed",
)


def collision_cache_dir() -> tuple[Path, tempfile.TemporaryDirectory[str] | None]:
    """Where merged collision shapes go: ``<cache root>/collision``, shared by every episode.

    The files are keyed by content (:func:`twin.collision.merged_collision_file`), so one merge
    per mesh per machine serves every later episode. Where the cache root cannot be created
    (a read-only home), a temporary folder of this twin's own, removed on close.
    """
    folder = cache_root() / "collision"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        usable = os.access(folder, os.W_OK | os.X_OK)
    except OSError:
        usable = False
    if not usable:
        temporary = tempfile.TemporaryDirectory(prefix="cdw-twin-shapes-")
        return Path(temporary.name), temporary
    return folder, None


@dataclass(frozen=True)
class ArmCommand:
    """A command for the arm: joint targets ``(n,)``, optional velocities ``(n,)``, gripper."""

    joint_positions: tuple[float, ...]
    joint_velocities: tuple[float, ...] | None = None
    gripper_width_m: float | None = None


@dataclass(frozen=True)
class Observation:
    """What the twin knows at one instant (ground truth)."""

    time_s: float
    step: int
    belt: BeltState
    setpoint_mps: float
    load_mass_kg: float
    objects: tuple[GroundTruth, ...]
    joint_positions: tuple[float, ...]
    joint_velocities: tuple[float, ...]
    tcp_position_m: tuple[float, float, float]
    tcp_orientation_xyzw: tuple[float, float, float, float]
    gripper_width_m: float
    events: tuple[Event, ...] = field(default=())


EventSink = Callable[[Event], None]
"""Called with every event the twin logs, in the order of :attr:`Twin.events`."""


class Twin:
    """The conveyor twin. One PyBullet client and one FMU instance per ``Twin``.

    ``event_sink`` (also settable as the attribute of that name) receives every event as it
    is appended to :attr:`events`; it sees the events of every episode (every :meth:`reset`).
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        dataset_dir: Path,
        cell: CellConfig | None = None,
        fmu_path: Path | None = None,
        fmu_parameters: dict[str, float] | None = None,
        perception: PerceptionConfig | None = None,
        perception_enabled: bool = True,
        realtime: bool = False,
        gui: bool = False,
        event_sink: EventSink | None = None,
    ) -> None:
        if cell is None:
            if scenario.robot not in ROBOTS:
                msg = f"robot = {scenario.robot!r}: unknown robot (known: {sorted(ROBOTS)})"
                raise ConfigError(msg)
            cell = CellConfig(robot=ROBOTS[scenario.robot])
        self.scenario = scenario
        self.cell = cell
        self.dt_s = cell.physics.dt_s
        self._fmu_every = cell.physics.fmu_every_n_steps
        self._fmu_path = fmu_path
        self._fmu_parameters = dict(fmu_parameters or {})
        self.realtime = realtime
        self.perception_config = perception or scenario.perception
        self.perception_enabled = perception_enabled
        self.perception: Perception | None = None
        self.targets = TargetTracker()
        self._released: list[DetectionFrame] = []
        self.layouts: tuple[ImageLayout, ...] = load_dataset(dataset_dir)
        self._cache_dir, self._cache = collision_cache_dir()
        self.client = pb.connect(pb.GUI if gui else pb.DIRECT)
        self._drive: BeltDrive | None = None
        self._world: World | None = None
        self.robot: Robot | None = None
        self._monitor: Monitor | None = None
        self._batches: Iterator[ImageBatch] = iter(())
        self._next_batch: ImageBatch | None = None
        self.step_count = 0
        self.setpoint_mps = scenario.system.belt_speed_mps
        self._belt_state = BeltState(0.0, 0.0, 0.0, 0.0, 0.0)
        self._events: list[Event] = []
        self.event_sink = event_sink
        self._wall_start = 0.0
        self._realtime_factor = 1.0

    # -- life cycle -------------------------------------------------------------------------
    def __enter__(self) -> Twin:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Release the FMU and the PyBullet client."""
        if self._drive is not None:
            self._drive.__exit__(None, None, None)
            self._drive = None
        if self.client >= 0:
            pb.disconnect(physicsClientId=self.client)
            self.client = -1
        if self._cache is not None:
            self._cache.cleanup()

    def reset(self, seed: int | None = None) -> tuple[Observation, dict[str, object]]:
        """Start a new episode; ``seed`` overrides the scenario's seed."""
        if seed is not None:
            self.scenario = replace(self.scenario, seed=seed)
        seeds = seed_tree(self.scenario.seed)
        c = self.client
        pb.resetSimulation(physicsClientId=c)
        pb.setGravity(0.0, 0.0, -self.cell.physics.gravity_mps2, physicsClientId=c)
        pb.setPhysicsEngineParameter(
            fixedTimeStep=self.dt_s,
            numSolverIterations=self.cell.physics.solver_iterations,
            numSubSteps=0,
            deterministicOverlappingPairs=1,
            enableConeFriction=0,
            physicsClientId=c,
        )
        self._world = World(c, self.cell, self._cache_dir)
        self._world.prepare([spec for layout in self.layouts for spec in layout.objects])
        self.robot = Robot(c, self.cell.robot)
        self._monitor = Monitor(c, self.cell, self._world, self.robot)
        stream = Stream(self.layouts, self.scenario, self.cell.belt, seeds)
        self._batches = iter(stream)
        self._next_batch = next(self._batches, None)
        if self._drive is not None:
            self._drive.__exit__(None, None, None)
        params = dict(self._fmu_parameters)
        perturbation = self.scenario.system.perturbation
        if self._fmu_path is None:
            amplitude, tau_s, fmu_seed = PERTURBATION_PARAMETERS
            params.setdefault(amplitude, perturbation.force_std_N if perturbation.enabled else 0.0)
            params.setdefault(tau_s, perturbation.correlation_time_s)
            params.setdefault(fmu_seed, seeds.fmu_seed % 2**31)
        self._drive = BeltDrive(self._fmu_path, parameters=params)
        self._drive.__enter__()
        self.step_count = 0
        self.setpoint_mps = self.scenario.system.belt_speed_mps
        self._belt_state = BeltState(0.0, 0.0, 0.0, 0.0, 0.0)
        self._events = []
        self.perception = Perception(
            self.perception_config,
            self.scenario.objects.classes,
            self.cell.belt.surface_z_m,
            self.dt_s,
            seeds.perception,
            dropout_windows_s=self.scenario.faults.detection_dropout,
        )
        self.targets = TargetTracker()
        self._released = []
        self._spawn_due()
        self._wall_start = time.perf_counter()
        return self.observe(), {"seed": self.scenario.seed}

    # -- stepping ---------------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        """Simulated time: ``step_count * dt``."""
        return self.step_count * self.dt_s

    def set_belt_setpoint(self, speed_mps: float) -> None:
        """The belt speed setpoint handed to the FMU from the next communication step on."""
        if not (math.isfinite(speed_mps) and 0.0 <= speed_mps <= 2.0):
            msg = f"belt setpoint {speed_mps!r} m/s is outside [0, 2]"
            raise ConfigError(msg)
        self.setpoint_mps = speed_mps

    def pace(self, realtime_factor: float = 1.0) -> None:
        """Pace :meth:`step` to the wall clock (``realtime_factor`` x real time) from now on."""
        self.realtime = True
        self._realtime_factor = realtime_factor
        self._wall_start = time.perf_counter() - self.time_s / realtime_factor

    def step(
        self, action: ArmCommand | None = None
    ) -> tuple[Observation, float, bool, bool, dict[str, object]]:
        """Advance one physics step; returns Gymnasium's ``(obs, reward, terminated, truncated,
        info)``, the reward being the number of objects picked in this step."""
        events = self.advance(action)
        picks = sum(1 for e in events if e.type is EventType.PICK_SUCCESS)
        obs = self.observe(events)
        truncated = self.time_s >= self.scenario.duration_s
        return obs, float(picks), False, truncated, {}

    def _started(self) -> tuple[World, Robot, Monitor, BeltDrive]:
        if (
            self._world is None
            or self.robot is None
            or self._monitor is None
            or self._drive is None
        ):
            msg = "the twin has no episode: call reset() before step(), advance() or observe()"
            raise ConfigError(msg)
        return self._world, self.robot, self._monitor, self._drive

    def advance(self, action: ArmCommand | None = None) -> list[Event]:
        """Advance one physics step without building an observation; returns the new events."""
        world, robot, monitor, drive = self._started()
        if action is not None:
            self.command(action)
        else:
            robot.extrapolate(self.dt_s)
        self._apply_schedule()
        if self.step_count % self._fmu_every == 0:
            self._belt_state = drive.step(
                self.dt_s * self._fmu_every, self.drive_setpoint_mps, monitor.load_mass_kg
            )
        world.set_belt_speed(self._belt_state.belt_speed_mps, self.dt_s)
        self._spawn_due()
        pb.stepSimulation(physicsClientId=self.client)
        self.step_count += 1
        new = monitor.update(self.step_count, self.time_s)
        if new:
            self._events.extend(new)
            if self.event_sink is not None:
                for event in new:
                    self.event_sink(event)
        if self.targets.active:
            for event in new:
                if event.type is EventType.PICK_SUCCESS:
                    self.targets.finish(self.time_s)
            self.targets.update(self.time_s, monitor.tcp_pose[0], monitor.pose_of)
        if self.perception is not None and self.perception_enabled:
            if self.perception.capture_due(self.step_count):
                self.perception.capture(self.time_s, monitor.ground_truth())
            self._released.extend(self.perception.released(self.time_s))
        if self.realtime:
            target = self._wall_start + self.time_s / self._realtime_factor
            delay = target - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        return new

    def command(self, action: ArmCommand) -> None:
        """Set the arm (and gripper) targets; they hold until the next command."""
        _, robot, _, _ = self._started()
        n = len(robot.arm_joints)
        if len(action.joint_positions) != n:
            msg = f"arm command has {len(action.joint_positions)} joint positions, robot has {n}"
            raise ConfigError(msg)
        qd = None if action.joint_velocities is None else np.asarray(action.joint_velocities)
        robot.command(np.asarray(action.joint_positions, dtype=float), qd)
        if action.gripper_width_m is not None:
            robot.command_gripper(action.gripper_width_m)
        robot.apply_commands()

    def command_gripper(self, width_m: float) -> None:
        """Set the gripper opening target (m); it holds until the next command."""
        _, robot, _, _ = self._started()
        robot.command_gripper(width_m)
        robot.apply_commands()

    def announce_target(
        self, track_id: int, grasp_point: tuple[float, float, float], phase: str
    ) -> None:
        """The controller says which object it pursues (for the tracking-time metric)."""
        _, _, monitor, _ = self._started()
        self.targets.announce(self.time_s, track_id, grasp_point, phase, monitor.poses())

    def take_detections(self) -> list[DetectionFrame]:
        """Detection frames released since the last call (after their latency)."""
        frames, self._released = self._released, []
        return frames

    @property
    def drive_setpoint_mps(self) -> float:
        """The setpoint the belt drive receives now: 0 in a belt-stall window."""
        return 0.0 if self.scenario.faults.stalled(self.time_s) else self.setpoint_mps

    def _apply_schedule(self) -> None:
        for t_s, speed in self.scenario.system.speed_schedule:
            if abs(self.time_s - t_s) < 0.5 * self.dt_s:
                self.setpoint_mps = speed
        faults = self.scenario.faults
        for kind, windows in (
            ("injected_belt_stall", faults.belt_stall),
            ("injected_detection_dropout", faults.detection_dropout),
        ):
            for start_s, end_s in windows:
                for edge, t_s in (("start", start_s), ("end", end_s)):
                    if abs(self.time_s - t_s) < 0.5 * self.dt_s:
                        self.record_fault(kind, f"{edge} of window [{start_s}, {end_s}] s")

    def _spawn_due(self) -> None:
        world, _, monitor, _ = self._started()
        while (
            self._next_batch is not None
            and self._belt_state.belt_position_m >= self._next_batch.trigger_m
        ):
            for placement in self._next_batch.placements:
                quat = pb.getQuaternionFromEuler([0.0, 0.0, placement.yaw_rad])
                spawned = world.spawn(
                    placement.spec,
                    placement.position_m,
                    quat,
                    height_m=placement.height_m,
                    friction=placement.friction,
                    restitution=placement.restitution,
                )
                monitor.add(placement, spawned, self.step_count, self.time_s)
            self._next_batch = next(self._batches, None)

    # -- reading ----------------------------------------------------------------------------
    def observe(self, events: list[Event] | tuple[Event, ...] = ()) -> Observation:
        """Ground truth now."""
        _, robot, monitor, _ = self._started()
        q, qd = robot.joint_state()
        pos, orn = robot.tcp_pose()
        return Observation(
            time_s=self.time_s,
            step=self.step_count,
            belt=self._belt_state,
            setpoint_mps=self.setpoint_mps,
            load_mass_kg=monitor.load_mass_kg,
            objects=monitor.ground_truth(),
            joint_positions=tuple(float(v) for v in q),
            joint_velocities=tuple(float(v) for v in qd),
            tcp_position_m=(float(pos[0]), float(pos[1]), float(pos[2])),
            tcp_orientation_xyzw=(float(orn[0]), float(orn[1]), float(orn[2]), float(orn[3])),
            gripper_width_m=robot.gripper_width_m(),
            events=tuple(events),
        )

    def observe_belt(self) -> BeltState:
        """The belt drive's outputs at the last communication point."""
        return self._belt_state

    def observe_objects(self) -> tuple[GroundTruth, ...]:
        """Ground truth of every object on the belt, held or in a bin."""
        _, _, monitor, _ = self._started()
        return monitor.ground_truth()

    def landing_in_bins(self) -> list[int]:
        """Ids of released objects over a bin, still above its top (see :class:`Monitor`)."""
        _, _, monitor, _ = self._started()
        return monitor.landing_in_bins()

    @property
    def tcp_pose(self) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """TCP position and xyzw orientation after the last step (no new FK)."""
        _, _, monitor, _ = self._started()
        return monitor.tcp_pose

    @property
    def load_mass_kg(self) -> float:
        """Mass currently on the belt (the FMU's load input)."""
        return 0.0 if self._monitor is None else self._monitor.load_mass_kg

    @property
    def events(self) -> tuple[Event, ...]:
        """Every event of the episode so far."""
        return tuple(self._events)

    def record_fault(self, kind: str, detail: str) -> Event:
        """Log a fault (bad command, controller crash) as an event; scores stay honest."""
        return self._record(EventType.FAULT, {"kind": kind, "detail": detail})

    def record_controller_resumed(self, outage_s: float) -> Event:
        """Log that a controller acknowledges ticks again after ``outage_s`` of sim time without
        one (lockstep)."""
        return self._record(EventType.CONTROLLER_RESUMED, {"outage_s": outage_s})

    def _record(self, kind: EventType, data: dict[str, object]) -> Event:
        """Log an event about no object, now."""
        event = Event(time_s=self.time_s, step=self.step_count, type=kind, object_id=0, data=data)
        self._events.append(event)
        if self.event_sink is not None:
            self.event_sink(event)
        return event

    def scores(self) -> Scores:
        """Scores from the events so far."""
        return compute_scores(self._events, self.time_s)

    def wall_elapsed_s(self) -> float:
        """Wall-clock seconds since the last reset."""
        return time.perf_counter() - self._wall_start
