"""``cdw-twin twin-node``: the twin as a ROS 2 node, for an external controller.

Example (two shells, same ``ROS_DOMAIN_ID``)::

    cdw-twin twin-node --speed 0.4 --duration 60 --mode realtime --out runs/ep0
    cdw-twin controller

The cell is the scenario's ``cell`` (default: the reference cell) unless ``--cell`` names
another (a shipped cell's name, such as ``two_pandas``, or a path), its bin slots given the
dataset's classes (:func:`twin.scenario.episode_cell`); a cell of several stations takes one
controller per station, each on its station's namespace. Every ``spawned`` event says whether
some station could take the piece (``takeable``, :mod:`twin.spawn_fit`), by the rules of the
controllers' parameter file (``--params-file``; default: the scenario's ``controller``).

The episode log goes to ``--out`` (see :mod:`twin.episode_log`): the folder and its
``status.json`` exist from the start, ``events.jsonl`` is appended as events happen (flushed at
least every 0.5 s of wall time, so even ``kill -9`` keeps every event up to the last second),
and ``summary.json`` and the node's telemetry (``telemetry.json``: round-trip latency, step
rate, belt setpoint and speed; see :mod:`twin.telemetry`) are written when the episode ends.
Ctrl-C (SIGINT) or SIGTERM ends the episode at the next step: the node writes the folder with
``"complete": false`` in ``summary.json``, closes the recording and exits with status 130.
``--record OUT.mcap`` writes every message the node publishes or receives (every topic of
``docs/interfaces.md``) as the bytes on the wire, from inside the node: no recorder process to
start, match and feed (``cdw-twin run`` records its episodes this way; ``cdw-twin record`` is
the stand-alone recorder for a cell the twin does not run).

``--foxglove [PORT]`` serves the same messages live over Foxglove's WebSocket protocol
(:mod:`twin.live_view`; port 8765 unless given, on ``--foxglove-host``, loopback by default):
open Foxglove, *Open connection*, ``ws://127.0.0.1:8765``, and watch the episode as it runs. A
port in use, or one that is no TCP port (outside 0 to 65535), is a one-line error (exit 2)
before the episode starts; so is a ``--seed`` outside ``[0, 2**64 - 1]`` and an
``--ack-timeout`` that is not a positive number of seconds (at most an hour). A file of the
episode folder that cannot be written (a full disk) ends the episode: ``status.json`` says
``failed`` with the error (rewritten in place when no new file can be created) and the node
exits with status 2 and one line naming the file. ``--gui`` opens PyBullet's
own window on the cell; without a display that can be opened (``DISPLAY``) it is a one-line
error (exit 2) before anything starts::

    cdw-twin twin-node --duration 60 --foxglove
    cdw-twin twin-node --duration 60 --gui
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import signal
import time
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any, Protocol

from interfaces.errors import CdwTwinError, cut_message
from interfaces.lifecycle import STOP_SIGNALS, die_with_parent
from twin.gui_window import check_display, window_off, window_on

if TYPE_CHECKING:
    from interfaces.cell import Cell
    from interfaces.inproc import Bus
    from twin.camera_publisher import CameraPublisher
    from twin.episode_log import EventLog
    from twin.live_view import LiveView
    from twin.ros_node import Tap, TwinEndpoint
    from twin.scenario import Scenario
    from twin.sim import Twin
    from twin.spawn_fit import PieceJudge


class EpisodeStopped(Exception):  # noqa: N818 (a request, not an error)
    """A stop signal arrived; raised between two callback passes of the step loop."""


class StoppableExecutor:
    """An executor whose ``spin_once`` raises :class:`EpisodeStopped` once ``stop`` is set.

    The signal handler only records the signal; the step loop is left at its next callback
    pass, never from inside a callback or a physics step, so the twin's state, events and
    recording stay consistent.
    """

    def __init__(self, executor: Any, stop: list[int]) -> None:
        self.executor = executor
        self._stop = stop

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Serve callbacks as the wrapped executor does, unless a stop was requested."""
        if self._stop:
            raise EpisodeStopped
        self.executor.spin_once(timeout_sec=timeout_sec)


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the node's options."""
    parser.add_argument("--scenario", type=Path, default=None, help="scenario YAML")
    parser.add_argument(
        "--cell",
        default=None,
        metavar="PATH_OR_NAME",
        help="cell file, or the name of a shipped cell (default: the scenario's)",
    )
    parser.add_argument(
        "--dataset",
        type=Path,
        default=None,
        help="meshgen output folder (default: the scenario's, or built-in)",
    )
    parser.add_argument("--speed", type=float, default=None, help="belt speed m/s (override)")
    parser.add_argument("--duration", type=float, default=None, help="episode seconds (override)")
    parser.add_argument(
        "--seed", type=seed_argument, default=None, help="seed (override; 0 to 2**64 - 1)"
    )
    parser.add_argument("--objects", type=int, default=None, help="max objects (override)")
    parser.add_argument("--prefill", type=float, default=None, help="prefill metres (override)")
    parser.add_argument("--mode", choices=("realtime", "lockstep"), default="realtime")
    parser.add_argument("--perception", choices=("default", "zero"), default="default")
    parser.add_argument(
        "--ack-timeout", type=_ack_timeout_argument, default=2.0, help="lockstep wait (s)"
    )
    parser.add_argument("--out", type=Path, default=None, help="episode log folder")
    parser.add_argument(
        "--record",
        type=Path,
        default=None,
        metavar="MCAP",
        help="record every message the node sends or receives to this MCAP file",
    )
    parser.add_argument(
        "--params-file",
        type=Path,
        default=None,
        help="the controllers' parameter file, whose rules judge whether some station could "
        "take each spawned piece (default: the scenario's controller)",
    )
    add_view_options(parser)


MAX_SEED = 2**64 - 1
"""Largest seed the command line takes (:data:`twin.scenario.MAX_SEED`)."""

MAX_ACK_TIMEOUT_S = 3600.0
"""Longest lockstep wait ``--ack-timeout`` takes."""


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        msg = f"invalid int value: {text[:40]!r}"
        raise argparse.ArgumentTypeError(msg) from None


def seed_argument(text: str) -> int:
    """``--seed``: an integer in ``[0, 2**64 - 1]`` (argparse's one-line error otherwise)."""
    value = _integer(text)
    if not 0 <= value <= MAX_SEED:
        msg = f"must be in [0, 2**64 - 1], not {text[:40]}"
        raise argparse.ArgumentTypeError(msg)
    return value


def port_argument(text: str) -> int:
    """``--foxglove PORT``: a TCP port, ``[0, 65535]`` (0: any free port)."""
    value = _integer(text)
    if not 0 <= value <= 65535:
        msg = f"a TCP port is in [0, 65535] (0: any free one), not {text[:40]}"
        raise argparse.ArgumentTypeError(msg)
    return value


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        msg = f"invalid float value: {text[:40]!r}"
        raise argparse.ArgumentTypeError(msg) from None


def _ack_timeout_argument(text: str) -> float:
    value = _float(text)
    if not 0.0 < value <= MAX_ACK_TIMEOUT_S:
        msg = f"must be in (0, {MAX_ACK_TIMEOUT_S:g}] s, not {text[:40]}"
        raise argparse.ArgumentTypeError(msg)
    return value


MAX_RECORD_IMAGES_HZ = 120.0
"""Highest ``--record-images`` rate (a camera's own rate bounds it: one frame per frame)."""


def _record_hz_argument(text: str) -> float:
    value = _float(text)
    if not 0.0 <= value <= MAX_RECORD_IMAGES_HZ:
        msg = f"must be in [0, {MAX_RECORD_IMAGES_HZ:g}] Hz (0: no images), not {text[:40]}"
        raise argparse.ArgumentTypeError(msg)
    return value


def add_view_options(parser: argparse.ArgumentParser) -> None:
    """``--foxglove [PORT]``, ``--foxglove-host``, ``--gui`` and ``--record-images HZ``
    (twin-node and run)."""
    from twin.live_view import DEFAULT_HOST, DEFAULT_PORT

    parser.add_argument(
        "--foxglove",
        type=port_argument,
        nargs="?",
        const=DEFAULT_PORT,
        default=None,
        metavar="PORT",
        help=f"serve every topic live to Foxglove over WebSocket (port {DEFAULT_PORT})",
    )
    parser.add_argument(
        "--foxglove-host",
        default=DEFAULT_HOST,
        metavar="HOST",
        help=f"address the live view listens on ({DEFAULT_HOST}: this machine only)",
    )
    parser.add_argument("--gui", action="store_true", help="open PyBullet's window on the cell")
    parser.add_argument(
        "--record-images",
        type=_record_hz_argument,
        default=None,
        metavar="HZ",
        help="rate (sim time) at which the recording and the live view take the cameras' "
        "images (default: 1 with perception.source camera, 0 with the oracle; a subscriber "
        "on a camera topic gets every frame)",
    )


def build_scenario(args: argparse.Namespace) -> tuple[Scenario, Path, Cell]:
    """The scenario with command-line overrides, the dataset folder and the cell, checked
    together (:func:`twin.scenario_check.check_scenario`); the cell's bins resolved for the
    dataset (:func:`twin.scenario.episode_cell`).

    The scenario's ``cell`` and ``dataset`` are relative to its file; ``args.cell`` (when set)
    names the cell instead, relative to the working directory.
    """
    from interfaces.cell import load_cell
    from twin.scenario import Scenario, scenario_cell, scenario_dataset
    from twin.scenario_check import check_scenario

    scenario = Scenario.load(args.scenario) if args.scenario else Scenario()
    system = scenario.system
    objects = scenario.objects
    if args.speed is not None:
        system = dataclasses.replace(system, belt_speed_mps=args.speed)
    if args.prefill is not None:
        system = dataclasses.replace(system, prefill_m=args.prefill)
    if args.objects is not None:
        objects = dataclasses.replace(objects, max_objects=args.objects)
    scenario = dataclasses.replace(
        scenario,
        system=system,
        objects=objects,
        duration_s=scenario.duration_s if args.duration is None else args.duration,
        seed=scenario.seed if args.seed is None else args.seed,
    )
    base = args.scenario.parent if args.scenario is not None else None
    dataset = args.dataset if args.dataset is not None else scenario_dataset(scenario, base)
    where = str(args.scenario or "default scenario")
    cell_arg = getattr(args, "cell", None)
    cell = load_cell(cell_arg) if cell_arg is not None else scenario_cell(scenario, base, where)
    selection = check_scenario(scenario, dataset, where=where, cell=cell)
    return scenario, dataset, selection.cell or cell


def spawn_judge(args: argparse.Namespace, scenario: Scenario, cell: Cell) -> PieceJudge:
    """Whether some station of ``cell`` could take a piece, by its controllers' own rules
    (:func:`control.fit.line_refusal`), each station's configuration loaded once from the
    controllers' parameter file: ``--params-file``, else the file the scenario's
    ``controller`` names (relative to the scenario file; :func:`control.config.params_path`).
    The twin marks every spawned piece with it (:mod:`twin.spawn_fit`)."""
    from control.config import params_path, station_configs
    from control.fit import Piece, line_refusal

    path: Path | None = getattr(args, "params_file", None)
    if path is None:
        base = args.scenario.parent if args.scenario is not None else None
        try:
            path = params_path(scenario.controller, base)
        except CdwTwinError as exc:
            where = args.scenario or "default scenario"
            msg = f"{where}: controller = {scenario.controller!r}: {exc}"
            raise CdwTwinError(msg) from None
    configs = station_configs(path, cell)

    def judge(
        *,
        class_name: str,
        length_m: float,
        width_m: float,
        height_m: float,
        face_radius_m: float,
        face_tilt_rad: float,
    ) -> str | None:
        piece = Piece(
            class_name=class_name,
            length_m=length_m,
            width_m=width_m,
            height_m=height_m,
            face_radius_m=face_radius_m,
            face_tilt_rad=face_tilt_rad,
        )
        return line_refusal(piece, configs)

    return judge


def _open_live_view(args: argparse.Namespace, cell: Cell) -> LiveView | None:
    """The live view of every topic of the cell on ``--foxglove``'s port, if asked for."""
    port: int | None = getattr(args, "foxglove", None)
    if port is None:
        return None
    from interfaces.cell_topics import cell_topics
    from twin.live_view import LiveView

    view = LiveView(cell_topics(cell), host=args.foxglove_host, port=port)
    print(f"cdw-twin twin-node: live view on {view.url} (Foxglove: Open connection)", flush=True)
    return view


def camera_publisher(args: argparse.Namespace, twin: Twin) -> CameraPublisher | None:
    """The publisher of the cell's cameras (None for a cell without any), taking the tap's
    frames at ``--record-images`` (:func:`twin.camera_publisher.record_hz_for`)."""
    if not twin.cell.cameras:
        return None
    from twin.camera_publisher import CameraPublisher, record_hz_for

    hz = record_hz_for(twin.perception_config.source, getattr(args, "record_images", None))
    return CameraPublisher(record_hz=hz)


def fan_out(writers: Sequence[Tap]) -> Tap | None:
    """One tap handing each message to every writer in turn (None without writers)."""
    if not writers:
        return None
    if len(writers) == 1:
        return writers[0]

    def tap(topic: str, data: bytes, log_time_ns: int) -> None:
        for write in writers:
            write(topic, data, log_time_ns)

    return tap


class InprocPeers(Protocol):
    """The controllers of an in-process episode (``--transport inproc``), built by the caller
    that knows them (:mod:`experiments.inproc`: the twin's package does not import the
    controller's)."""

    def start(self, bus: Bus, cell: Cell) -> None:
        """Create every station's controller on ``bus`` and match it to the twin's endpoint."""
        ...

    def finish(self) -> None:
        """The episode ended (or stopped): write each controller's stats."""
        ...


def run(args: argparse.Namespace, peers: InprocPeers | None = None) -> int:
    """Run one episode as a ROS 2 node (with ``peers``: on the in-process bus, the controllers
    in this process, lockstep); 130 when SIGINT or SIGTERM ended it early."""
    stop: list[int] = []

    def on_signal(signum: int, frame: FrameType | None) -> None:
        del frame
        stop.append(signum)

    previous = {s: signal.signal(s, on_signal) for s in STOP_SIGNALS}
    try:
        die_with_parent()
        interrupted = _run_episode(args, stop, peers)
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    return 130 if interrupted else 0


def _run_episode(
    args: argparse.Namespace, stop: list[int], peers: InprocPeers | None = None
) -> bool:
    """The episode; True when a stop signal ended it before its duration."""
    from twin.episode_log import EpisodeWriteError, start_episode_folder, write_status
    from twin.episode_setup import robot_visuals_wanted
    from twin.perception_config import PerceptionConfig
    from twin.ros_isolation import clean_stale_fastdds_shm, local_ros_defaults
    from twin.sim import Twin

    gui = getattr(args, "gui", False)
    if gui:
        check_display()
    scenario, dataset, cell = build_scenario(args)
    judge = spawn_judge(args, scenario, cell)
    perception = PerceptionConfig.zero_noise() if args.perception == "zero" else None
    view = _open_live_view(args, cell)
    local_ros_defaults()
    clean_stale_fastdds_shm()
    out: Path | None = args.out
    log = None
    if out is not None:
        log = start_episode_folder(out, scenario=scenario.name, seed=scenario.seed)
    try:
        with ExitStack() as stack:
            if view is not None:
                stack.callback(view.close)
            if log is not None:
                stack.enter_context(log)
            twin = stack.enter_context(
                Twin(
                    scenario,
                    dataset_dir=dataset,
                    cell=cell,
                    perception=perception,
                    gui=gui,
                    event_sink=None if log is None else log.append,
                )
            )
            twin.spawn_judge = judge
            twin.visual_shapes = robot_visuals_wanted(
                cell,
                twin.perception_config.source,
                over_ros=peers is None,
                recorded=args.record is not None,
                viewed=view is not None,
            )
            return _serve(args, twin, stop, log, view, peers)
    except BaseException as exc:
        if out is not None:
            error = cut_message(f"{type(exc).__name__}: {exc}", 1000)
            with contextlib.suppress(CdwTwinError):
                write_status(out, "failed", error=error)
        if isinstance(exc, OSError):
            where = f"{exc.filename}: " if exc.filename else ""
            msg = f"{where}cannot write the episode: {exc.strerror or exc}"
            raise EpisodeWriteError(msg) from None
        raise


def _serve(
    args: argparse.Namespace,
    twin: Twin,
    stop: list[int],
    log: EventLog | None,
    view: LiveView | None = None,
    peers: InprocPeers | None = None,
) -> bool:
    """Run the twin node until the episode ends or a stop signal; write the episode folder.

    The node's tap feeds the recording and the live view, when there are. With ``peers`` the
    twin's endpoint and the controllers share the in-process bus instead of ROS 2.

    ``wall_seconds`` (and the real-time factor) count from the first step: the wait for the
    controllers to start and match is ``match_wall_seconds``."""
    from rclpy.utilities import try_shutdown

    from interfaces.run_folder import TELEMETRY_FILE
    from twin.episode_log import EpisodeWriteError, write_episode_file, write_status, write_summary
    from twin.episode_summary import episode_summary
    from twin.recording import open_cell_recording

    scenario = twin.scenario
    gui = getattr(args, "gui", False)
    if gui:
        window_off(twin)
    twin.write_camera_examples(args.out)  # with the camera source: one frame per camera
    twin.reset()
    if gui:
        window_on(twin)
    recording = open_cell_recording(args.record, twin.cell)
    writers = [sink.write for sink in (recording, view) if sink is not None]
    # a recording takes everything; the live view alone only what a client subscribed to
    wants = view.wants if recording is None and view is not None else None
    cameras = camera_publisher(args, twin)
    node, executor, detach = _endpoint(args, twin, fan_out(writers), peers, wants, cameras)
    wall0 = time.perf_counter()
    try:
        interrupted, first, end = _step(
            args, node, StoppableExecutor(executor, stop), peers, detach
        )
    finally:
        if cameras is not None:
            cameras.close()
    wall = end - first
    if recording is not None:
        try:
            recording.close()
        except OSError as exc:
            msg = f"{args.record}: cannot write the recording: {exc.strerror or exc}"
            raise EpisodeWriteError(msg) from None
    if log is not None:
        log.close()
    twin.finish_pursuits()
    summary = episode_summary(
        twin,
        node,
        mode=args.mode,
        transport="ros" if peers is None else "inproc",
        wall_s=wall,
        match_wall_s=first - wall0,
        stopped_by=signal.Signals(stop[0]).name if interrupted else None,
    )
    out: Path | None = args.out
    if out is not None:
        write_episode_file(out, TELEMETRY_FILE, node.telemetry.to_json())
        write_summary(out, summary)
        write_status(
            out,
            "interrupted" if interrupted else "finished",
            scenario=scenario.name,
            seed=scenario.seed,
            sim_seconds=twin.time_s,
        )
    node.destroy_node()
    if peers is None:
        try_shutdown()
    return interrupted


def _step(
    args: argparse.Namespace,
    node: TwinEndpoint,
    executor: StoppableExecutor,
    peers: InprocPeers | None,
    detach: Callable[[], None],
) -> tuple[bool, float, float]:
    """Run the step loop; whether a stop signal ended it, and the ``perf_counter`` times of
    the first step and of the end. In process, the controllers are then handed the last tick
    (as over ROS 2) and write their stats, also when the loop failed."""
    from twin.ros_node import run_loop

    stepping: list[float] = []
    interrupted = False
    try:
        run_loop(
            node,
            executor,
            ack_timeout_s=args.ack_timeout,
            on_first_step=lambda: stepping.append(time.perf_counter()),
        )
    except EpisodeStopped:
        interrupted = True
    except BaseException:
        if peers is not None:
            peers.finish()  # what the controllers counted until the failure
        raise
    if peers is not None:
        detach()
        executor.executor.spin_once(timeout_sec=0.0)  # the last tick, as over ROS 2
        peers.finish()
    end = time.perf_counter()
    return interrupted, stepping[0] if stepping else end, end


def _endpoint(
    args: argparse.Namespace,
    twin: Twin,
    tap: Tap | None,
    peers: InprocPeers | None,
    tap_wants: Callable[[str], bool] | None = None,
    cameras: CameraPublisher | None = None,
) -> tuple[TwinEndpoint, Any, Callable[[], None]]:
    """The twin's endpoint, what serves its callbacks, and what stops its reading at the end:
    a ROS 2 node and its executor, or (``peers``) the in-process bus, with the controllers
    created on it; ``cameras`` publishes the cell's cameras beside the twin's messages."""
    extras = () if cameras is None else (cameras,)
    if peers is None:
        import rclpy
        from rclpy.signals import SignalHandlerOptions

        from twin.ros_node import TwinNode, make_executor

        # rclpy's own SIGINT handler would shut the context down under the step loop
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        node = TwinNode(
            twin,
            lockstep=args.mode == "lockstep",
            tap=tap,
            tap_wants=tap_wants,
            step_publishers=extras,
        )
        executor = make_executor()
        executor.add_node(node)
        return node, executor, lambda: None
    from interfaces.inproc import Bus
    from twin.ros_node import InprocTwin

    bus = Bus()
    inproc = InprocTwin(twin, bus, tap=tap, tap_wants=tap_wants, step_publishers=extras)
    peers.start(bus, twin.cell)
    return inproc, bus, inproc.detach
