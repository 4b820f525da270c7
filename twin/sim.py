"""The twin: PyBullet scene co-simulated with the belt-drive FMU, with events and ground truth.

``Twin`` follows Gymnasium's shape without depending on it::

    with Twin(scenario, dataset_dir=Path("out/meshes")) as twin:
        obs, info = twin.reset(seed=3)
        while True:
            obs, reward, terminated, truncated, info = twin.step(action)
            if terminated or truncated:
                break

The cell (:class:`interfaces.cell.Cell`: belt, camera, belt drive, physics, stations) is the
scenario's ``cell`` unless one is passed. Each station's robot is loaded at its base pose with
its tool (:attr:`Twin.stations`, in the cell's order). ``action`` is an :class:`ArmCommand`
(a station's joint targets, optional feed-forward velocities, its tool's command), a sequence
of them (one per station at most) or ``None`` to keep the last ones: the scripted-arm hook for
tests and users. The co-simulation master runs a fixed physics step (240 Hz default); every
``drive.step_s`` (default: every step) it sets the belt-drive FMU's inputs (setpoint, mass on
the belt), calls ``doStep`` and reads the belt speed that drives the kinematic belt. Time is
``step * dt``, never accumulated.

The camera model is the scenario's ``perception`` unless a :class:`PerceptionConfig` is passed:
the oracle (ground truth through its error model) or, with ``source: camera``, the cell's
rendered RGB-D cameras through a detector, scored against ground truth
(:mod:`twin.perception_source`, :meth:`Twin.perception_summary`, ``docs/camera.md``). The twin
steps its perception; the perception and its cameras read the twin back through
:class:`twin.sim_view.PerceptionSim`, which ``Twin`` satisfies, and never import this module.
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
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import replace
from pathlib import Path
from types import TracebackType

import numpy as np
import pybullet as pb

from interfaces.camera import RgbdFrame
from interfaces.cell import Cell
from interfaces.detections import DetectionFrame
from interfaces.events import Event, EventType
from interfaces.materials import dataset_table as dataset_materials
from interfaces.metrics import Counts, count_events, event_scores, exit_station
from interfaces.run_records import EventScores
from twin.belt_drive import BeltDrive, BeltState
from twin.episode_setup import collision_cache_dir, drive_parameters, entering_classes
from twin.errors import ConfigError
from twin.monitor import GroundTruth, Monitor
from twin.objects import ImageLayout, ObjectSpec, load_dataset, read_obj_triangles
from twin.observation import ArmState, Observation
from twin.perception import Perception
from twin.perception_config import PerceptionConfig
from twin.perception_source import PerceptionStepper
from twin.scenario import Scenario, episode_cell, scenario_cell, seed_tree
from twin.spawn_fit import PieceJudge, SpawnFit
from twin.station import ArmCommand, Station
from twin.stream import ImageBatch, Stream
from twin.target_metric import TrackingResult
from twin.world import World

__all__ = [
    "ArmCommand",
    "ArmState",
    "EventSink",
    "Observation",
    "Twin",
    "collision_cache_dir",
    "drive_parameters",
    "entering_classes",
]


EventSink = Callable[[Event], None]
"""Called with every event the twin logs, in the order of :attr:`Twin.events`."""


class Twin:
    """The conveyor twin. One PyBullet client and one FMU instance per ``Twin``.

    ``cell`` defaults to the scenario's (a relative path taken from the working directory;
    :func:`twin.cmd_node.build_scenario` resolves it against the scenario file), its bins
    resolved against the dataset's class table (:func:`twin.scenario.episode_cell`); a cell
    passed in is taken as it is (resolved by the caller). ``classes`` are the classes that can
    enter the belt (:func:`entering_classes`): the camera's labels.
    ``event_sink`` (also settable as the attribute of that name) receives every event as it
    is appended to :attr:`events`; it sees the events of every episode (every :meth:`reset`).
    The attribute ``spawn_judge`` (a :class:`twin.spawn_fit.PieceJudge`: the stations'
    controllers' own static rules, :func:`control.fit.line_refusal`; set it before
    :meth:`reset`) marks every ``spawned`` event with whether some station could take the piece
    (``takeable``, and its ``refusal`` when not); without one (None) the events carry no mark.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        dataset_dir: Path,
        cell: Cell | None = None,
        perception: PerceptionConfig | None = None,
        perception_enabled: bool = True,
        realtime: bool = False,
        gui: bool = False,
        event_sink: EventSink | None = None,
    ) -> None:
        self.scenario = scenario
        self.layouts: tuple[ImageLayout, ...] = load_dataset(dataset_dir)
        if cell is None:
            cell = episode_cell(scenario, scenario_cell(scenario), dataset_materials(dataset_dir))
        self.cell = cell
        self.dt_s = self.cell.physics.dt_s
        step_s = self.cell.drive.step_s
        self._fmu_every = (
            1 if step_s is None else max(1, round(step_s * self.cell.physics.physics_hz))
        )
        self.realtime = realtime
        self.perception_config = perception or scenario.perception
        self.perception_enabled = perception_enabled
        self.perception: Perception | None = None  # the oracle of the episode, if it is one
        self._perception = PerceptionStepper(self)
        self.dataset_dir = dataset_dir
        self.classes = entering_classes(self.layouts, scenario, self.cell)
        drive_parameters(self.cell.drive, scenario.system.perturbation, 0)  # refused early
        self._cache_dir, self._cache = collision_cache_dir()
        self.client = pb.connect(pb.GUI if gui else pb.DIRECT)
        self._gui = gui
        self.visual_shapes = True
        """Whether the next :meth:`reset` loads the robots with their visual meshes (a camera
        looks at them; without, a robot loads in milliseconds: :func:`twin.robot.load_flags`,
        :func:`twin.episode_setup.robot_visuals_wanted`). PyBullet's window always has them."""
        self._drive: BeltDrive | None = None
        self._world: World | None = None
        self.stations: tuple[Station, ...] = ()
        self._monitor: Monitor | None = None
        self._batches: Iterator[ImageBatch] = iter(())
        self._next_batch: ImageBatch | None = None
        self.step_count = 0
        self.setpoint_mps = scenario.system.belt_speed_mps
        self._belt_state = BeltState(0.0, 0.0, 0.0, 0.0, 0.0)
        self._events: list[Event] = []
        self._shapes: dict[int, tuple[ObjectSpec, float]] = {}  # object id -> spec, height
        self._triangles: dict[tuple[Path, float], np.ndarray] = {}
        self.event_sink = event_sink
        self.spawn_judge: PieceJudge | None = None
        self._spawn_fit: SpawnFit | None = None
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
        """Release the FMU, the cameras and the PyBullet client."""
        self._perception.close()
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
        physics = self.cell.physics
        pb.resetSimulation(physicsClientId=c)
        pb.setGravity(0.0, 0.0, -physics.gravity_mps2, physicsClientId=c)
        pb.setPhysicsEngineParameter(
            fixedTimeStep=self.dt_s,
            numSolverIterations=physics.solver_iterations,
            numSubSteps=0,
            deterministicOverlappingPairs=1,
            enableConeFriction=0,
            physicsClientId=c,
        )
        self._world = World(c, self.cell, self._cache_dir)
        self._world.prepare([spec for layout in self.layouts for spec in layout.objects])
        self.stations = tuple(
            Station.load(
                c,
                i,
                spec,
                dt_s=self.dt_s,
                gravity_mps2=physics.gravity_mps2,
                materials=self.cell.materials,
                visual_shapes=self.visual_shapes or self._gui,
            )
            for i, spec in enumerate(self.cell.stations)
        )
        self._monitor = Monitor(c, self.cell, self._world, self.stations)
        stream = Stream(self.layouts, self.scenario, self.cell.belt, seeds, self.cell.materials)
        self._batches = iter(stream)
        self._next_batch = next(self._batches, None)
        self._open_drive(seeds.fmu_seed)
        self.step_count = 0
        self.setpoint_mps = self.scenario.system.belt_speed_mps
        self._belt_state = BeltState(0.0, 0.0, 0.0, 0.0, 0.0)
        self._events = []
        self._shapes = {}
        self.perception = self._perception.reset(self.scenario.seed, seeds.perception)
        judge = self.spawn_judge
        self._spawn_fit = None if judge is None else SpawnFit(judge, self._mesh_of)
        self._spawn_due()
        self._wall_start = time.perf_counter()
        return self.observe(), {"seed": self.scenario.seed}

    def _open_drive(self, fmu_seed: int) -> None:
        if self._drive is not None:
            self._drive.__exit__(None, None, None)
            self._drive = None
        drive = self.cell.drive
        params = drive_parameters(drive, self.scenario.system.perturbation, fmu_seed)
        if drive.builtin:
            self._drive = BeltDrive(parameters=params)
        else:
            self._drive = BeltDrive(Path(drive.fmu), mapping=drive.mapping, parameters=params)
        self._drive.__enter__()

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
        self, action: ArmCommand | Sequence[ArmCommand] | None = None
    ) -> tuple[Observation, float, bool, bool, dict[str, object]]:
        """Advance one physics step; returns Gymnasium's ``(obs, reward, terminated, truncated,
        info)``, the reward being the number of objects picked in this step."""
        events = self.advance(action)
        picks = sum(1 for e in events if e.type is EventType.PICK_SUCCESS)
        obs = self.observe(events)
        truncated = self.time_s >= self.scenario.duration_s
        return obs, float(picks), False, truncated, {}

    def _started(self) -> tuple[World, Monitor, BeltDrive]:
        if self._world is None or self._monitor is None or self._drive is None:
            msg = "the twin has no episode: call reset() before step(), advance() or observe()"
            raise ConfigError(msg)
        return self._world, self._monitor, self._drive

    def _station(self, index: int) -> Station:
        if not 0 <= index < len(self.stations):
            self._started()
            msg = f"station {index}: the cell has {len(self.stations)} station(s)"
            raise ConfigError(msg)
        return self.stations[index]

    def advance(self, action: ArmCommand | Sequence[ArmCommand] | None = None) -> list[Event]:
        """Advance one physics step without building an observation; returns the new events."""
        world, monitor, drive = self._started()
        self._command_or_hold(action)
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
        for station in self.stations:
            if station.targets.active:
                self._track(station, monitor, new)
        if self.perception_enabled:
            self._perception.step(self.step_count, self.time_s)
        if self.realtime:
            target = self._wall_start + self.time_s / self._realtime_factor
            delay = target - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        return new

    def _command_or_hold(self, action: ArmCommand | Sequence[ArmCommand] | None) -> None:
        """Apply this step's commands (a station without one follows its last command), and
        hand every arm's targets to its motors through its joint limiter."""
        if action is None:
            commanded: tuple[int, ...] = ()
        elif isinstance(action, ArmCommand):
            self.command(action)
            commanded = (action.station,)
        else:
            for command in action:
                self.command(command)
            commanded = tuple(command.station for command in action)
        for station in self.stations:
            if station.index not in commanded:
                station.robot.extrapolate(self.dt_s)
            station.drive()

    def _track(self, station: Station, monitor: Monitor, new: list[Event]) -> None:
        """The station's tracking-time measurement for this step."""
        for event in new:
            if event.type is EventType.PICK_SUCCESS and event.data.get("station") == station.name:
                station.targets.finish(self.time_s)
        station.targets.update(self.time_s, monitor.tcp_pose(station.index)[0], monitor.pose_of)

    def command(self, action: ArmCommand, station: int | None = None) -> None:
        """Set a station's arm (and tool) targets (``station`` overrides ``action.station``);
        they hold until the next command."""
        index = action.station if station is None else station
        self._station(index).command(action)

    def command_gripper(self, width_m: float, station: int = 0) -> None:
        """Set a station's gripper opening target (m); it holds until the next command."""
        self._station(station).command_tool(width_m)

    def announce_target(
        self,
        track_id: int,
        grasp_point: tuple[float, float, float],
        phase: str,
        station: int = 0,
    ) -> None:
        """A station's controller says which object it pursues (for the tracking time)."""
        _, monitor, _ = self._started()
        self._station(station).targets.announce(
            self.time_s, track_id, grasp_point, phase, monitor.poses()
        )

    def take_detections(self) -> list[DetectionFrame]:
        """Detection frames released since the last call (after their latency)."""
        return self._perception.take()

    def write_camera_examples(self, folder: Path | None) -> None:
        """With the camera source, each later episode writes one frame per camera with its
        detections drawn into ``folder`` (:func:`interfaces.run_folder.camera_frame_name`;
        None: none); the oracle writes nothing."""
        self._perception.examples_folder = folder

    def camera_frames(self) -> tuple[RgbdFrame, ...]:
        """Every camera's frame of the camera source's last capture, as rendered (none with the
        oracle): what the node publishes, without a second render."""
        return self._perception.latest_frames()

    def perception_summary(self) -> dict[str, float] | None:
        """The episode's perception scored against ground truth so far (flat keys with units:
        :data:`twin.perception_score.PERCEPTION_METRICS`), or None unless the scenario's
        ``perception.source`` is ``camera``."""
        return self._perception.summary()

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
        world, monitor, _ = self._started()
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
                fit = None
                if self._spawn_fit is not None:
                    fit = self._spawn_fit(placement.spec, spawned.height_m, placement.yaw_rad)
                event = monitor.add(placement, spawned, self.step_count, self.time_s, extra=fit)
                self._shapes[event.object_id] = (placement.spec, spawned.height_m)
            self._next_batch = next(self._batches, None)

    # -- reading ----------------------------------------------------------------------------
    def observe(self, events: list[Event] | tuple[Event, ...] = ()) -> Observation:
        """Ground truth now."""
        _, monitor, _ = self._started()
        return Observation(
            time_s=self.time_s,
            step=self.step_count,
            belt=self._belt_state,
            setpoint_mps=self.setpoint_mps,
            load_mass_kg=monitor.load_mass_kg,
            objects=monitor.ground_truth(),
            arms=tuple(self._arm_state(station) for station in self.stations),
            events=tuple(events),
        )

    @staticmethod
    def _arm_state(station: Station) -> ArmState:
        q, qd = station.robot.joint_state()
        pos, orn = station.tool.tcp_pose()
        return ArmState(
            joint_positions=tuple(float(v) for v in q),
            joint_velocities=tuple(float(v) for v in qd),
            tcp_position_m=(float(pos[0]), float(pos[1]), float(pos[2])),
            tcp_orientation_xyzw=(float(orn[0]), float(orn[1]), float(orn[2]), float(orn[3])),
            gripper_width_m=station.tool.measured(),
        )

    def observe_belt(self) -> BeltState:
        """The belt drive's outputs at the last communication point."""
        return self._belt_state

    def observe_objects(self) -> tuple[GroundTruth, ...]:
        """Ground truth of every object on the belt, held or in a bin."""
        _, monitor, _ = self._started()
        return monitor.ground_truth()

    def object_mesh(self, object_id: int) -> tuple[np.ndarray, str]:
        """An object's mesh triangles ``(t, 3, 3)`` in its own frame (the frame of its ground
        truth pose; z stretched to its sampled height), m, and its class. Cached per mesh and
        height; :class:`ConfigError` for an id no object of this episode has."""
        shape = self._shapes.get(object_id)
        if shape is None:
            msg = f"object id {object_id}: no object of this episode has it"
            raise ConfigError(msg)
        spec, height_m = shape
        return self._mesh_of(spec, height_m), spec.class_name

    def _mesh_of(self, spec: ObjectSpec, height_m: float) -> np.ndarray:
        """The triangles ``(t, 3, 3)`` of ``spec``'s mesh stretched to ``height_m`` (cached)."""
        key = (spec.mesh_path, height_m)
        triangles = self._triangles.get(key)
        if triangles is None:
            triangles = read_obj_triangles(spec.mesh_path).astype(float)
            triangles[..., 2] *= height_m / spec.height_m
            self._triangles[key] = triangles
        return triangles

    def object_shape(self, object_id: int) -> tuple[ObjectSpec, float] | None:
        """The meshgen spec and sampled height of object ``object_id`` of this episode (None:
        no object has that id yet)."""
        return self._shapes.get(object_id)

    def body_of(self, object_id: int) -> int | None:
        """The PyBullet body of object ``object_id`` while it is simulated, else None."""
        return None if self._monitor is None else self._monitor.body_of(object_id)

    @property
    def world(self) -> World | None:
        """The episode's static scene (belt, floor, bins; None before the first reset)."""
        return self._world

    def landing_in_bins(self) -> list[int]:
        """Ids of released objects over a bin, still above its top (see :class:`Monitor`)."""
        _, monitor, _ = self._started()
        return monitor.landing_in_bins()

    def tcp_pose(
        self, station: int = 0
    ) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """A station's TCP position and xyzw orientation after the last step (no new FK)."""
        _, monitor, _ = self._started()
        return monitor.tcp_pose(station)

    @property
    def load_mass_kg(self) -> float:
        """Mass currently on the belt (the FMU's load input)."""
        return 0.0 if self._monitor is None else self._monitor.load_mass_kg

    @property
    def events(self) -> tuple[Event, ...]:
        """Every event of the episode so far."""
        return tuple(self._events)

    def record_fault(self, kind: str, detail: str, station: str | None = None) -> Event:
        """Log a fault (bad command, controller crash) as an event, naming the ``station`` it
        concerns if one; scores stay honest."""
        return self._record(EventType.FAULT, {"kind": kind, "detail": detail}, station=station)

    def record_controller_resumed(self, outage_s: float, station: str | None = None) -> Event:
        """Log that a station's controller acknowledges ticks again after ``outage_s`` of sim
        time without one (lockstep)."""
        return self._record(EventType.CONTROLLER_RESUMED, {"outage_s": outage_s}, station=station)

    def _record(
        self, kind: EventType, data: dict[str, object], *, station: str | None = None
    ) -> Event:
        """Log an event about no object, now (with the ``station`` it concerns, if one)."""
        if station is not None:
            data = {**data, "station": station}
        event = Event(time_s=self.time_s, step=self.step_count, type=kind, object_id=0, data=data)
        self._events.append(event)
        if self.event_sink is not None:
            self.event_sink(event)
        return event

    def counts(self, station: str | None = None) -> Counts:
        """What the events so far add up to, for the line or one station (by name).

        The line's misses are those of its most downstream station: an object an upstream
        station missed may still be picked further down.
        """
        return count_events(
            self._events,
            self.time_s,
            station=station,
            line_exit=exit_station(self.cell.stations),
        )

    def scores(self, station: str | None = None) -> EventScores:
        """The event scores (:func:`interfaces.metrics.event_scores`) of the line or a station."""
        return event_scores(self.counts(station))

    def finish_pursuits(self) -> None:
        """End every station's open pursuit now (the episode ends)."""
        for station in self.stations:
            station.targets.finish(self.time_s)

    def tracking_results(self, station: str | None = None) -> list[TrackingResult]:
        """Every finished pursuit, of every station (in station order) or of one."""
        return [
            result
            for s in self.stations
            if station is None or s.name == station
            for result in s.targets.results
        ]

    def wall_elapsed_s(self) -> float:
        """Wall-clock seconds since the last reset."""
        return time.perf_counter() - self._wall_start
