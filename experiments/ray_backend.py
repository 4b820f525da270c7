"""Sweeps on Ray: ``cdw-twin sweep GRID --backend ray [--address ADDR]``.

Every episode of the grid is one Ray task that runs
:func:`experiments.episode_processes.run_episode` on the worker's machine exactly as the
local backend does on this one: its own ROS domain (claimed from the worker machine's lock
folder), its own twin and controller processes, its own run
folder (a temporary copy of the grid cell's). Nothing relies on a shared file system: the grid
cell's small files (``scenario.yaml``, ``cell.yaml``, ``controller.yaml``) travel in the task's
arguments, the dataset travels once per sweep through Ray's object store as a tar archive
(unpacked once per worker machine, keyed by its SHA-256), and the finished episode folder comes
back as a tar archive with the metrics (:mod:`experiments.sweep_shipping`). The driver unpacks
it where the local backend would have written it, so ``sweep.json``, ``sweep.csv``, the cells'
tables and intervals are written by the same code (:class:`experiments.sweep.Sweep`) for both
backends.

Resources: each task declares :data:`EPISODE_CPUS` CPUs (``--cpus-per-episode``), the measured
load of one lockstep episode (twin and controllers alternate, one core busy; see
``docs/benchmarks.md``), so Ray runs as many episodes at once on a node as it has cores.
Without ``--address`` a Ray instance is started for the sweep with ``--workers`` CPUs.

Connecting is bounded: an ``--address`` is first probed over TCP (a refused or unreachable
port is a one-line error naming the address at once), then ``ray.init`` runs in a thread the
driver waits for at most ``--connect-timeout`` seconds (:data:`CONNECT_TIMEOUT_S`); Ray's own
client retries for ever and ignores SIGTERM meanwhile. A local instance that cannot start (an
unusable ``RAY_TMPDIR``) is a one-line error too. The driver connects before it writes
anything, so a sweep that cannot reach Ray leaves no folder, and ``sweep.json`` says ``ray``
only when the episodes ran there.

Failures: an episode whose twin or controller fails is a failed row, as locally. A task whose
worker process or node dies (killed, out of memory, node lost) is retried once
(:data:`RETRIES`) and listed in ``sweep.json``'s ``retried``; if the retry dies too the episode
is a failed row naming the Ray error. No episode is ever silently missing.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import shutil
import signal
import socket
import sys
import tempfile
import threading
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Generic, Protocol, TypeVar

from experiments.sweep_shipping import (
    EpisodeResult,
    ShippedEpisode,
    dataset_key,
    pack,
    run_files,
    run_shipped_episode,
    unpack,
)
from experiments.sweep_summary import BackendNote
from interfaces.errors import CdwTwinError
from interfaces.run_records import EpisodeMetrics

if TYPE_CHECKING:
    from experiments.run_types import EpisodeSpec, RunOptions


class _Named(Protocol):
    @property
    def name(self) -> str: ...


class GridRun(Protocol):
    """A grid cell being run, as the backend ships its episodes
    (:class:`experiments.sweep.CellRun`): its run folder, options and grid cell's name."""

    @property
    def folder(self) -> Path: ...

    @property
    def options(self) -> RunOptions: ...

    @property
    def cell(self) -> _Named: ...


RunT = TypeVar("RunT", bound=GridRun)


class EpisodeBoard(Protocol[RunT]):
    """What runs a sweep's episodes and records them (:class:`experiments.sweep.Sweep`): the
    jobs, the stop signal, the notes and :meth:`finished`, which writes every table."""

    jobs: list[tuple[RunT, EpisodeSpec]]
    cancel: threading.Event
    stopped: list[str]
    retried: list[str]
    backend: BackendNote

    def finished(
        self, run: RunT, episode: EpisodeSpec, metrics: EpisodeMetrics | None, reason: str
    ) -> None: ...


EPISODE_CPUS = 1.0
"""CPUs one lockstep episode keeps busy (twin and controllers take turns)."""

RETRIES = 1
"""How often an episode whose Ray worker died is run again."""

CONNECT_TIMEOUT_S = 120.0
"""Longest the driver waits for ``ray.init`` (connecting to a cluster, or starting Ray here)."""

PROBE_TIMEOUT_S = 10.0
"""Longest the TCP probe of an ``--address`` waits for the port to answer."""

RayInitOption = bool | int | str
"""The value of a ``ray.init`` keyword the sweep passes."""

RAY_INIT_OPTIONS: dict[str, RayInitOption] = {
    "include_dashboard": False,
    "log_to_driver": False,
    "configure_logging": False,
}
"""Options of every ``ray.init`` the sweep makes: no dashboard, no worker logs on the terminal."""


class RayBackendError(CdwTwinError):
    """Ray cannot be used (not installed, no cluster at the address)."""


def import_ray() -> Any:
    """The ``ray`` module, or a one-line error saying how to get it."""
    try:
        import ray
    except ImportError as exc:
        msg = f"--backend ray: the ray package is not installed ({exc}); pip install ray"
        raise RayBackendError(msg) from exc
    return ray


def _host_port(address: str) -> tuple[str, int]:
    """``HOST:PORT`` (optionally ``ray://HOST:PORT``, ``[IPv6]:PORT``) split; a one-line
    :class:`RayBackendError` naming the address otherwise."""
    text = address.removeprefix("ray://")
    host, sep, port_text = text.rpartition(":")
    host = host.removeprefix("[").removesuffix("]")
    if not sep or not host or not port_text.isdigit() or not 0 < int(port_text) < 65536:
        msg = f"--address {address[:200]!r}: expected HOST:PORT (the Ray head's address)"
        raise RayBackendError(msg)
    return host, int(port_text)


def probe(address: str, timeout_s: float = PROBE_TIMEOUT_S) -> None:
    """Check that the head's port at ``address`` accepts a TCP connection within
    ``timeout_s``; :class:`RayBackendError` naming the address and why not."""
    host, port = _host_port(address)
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as exc:
        why = "no answer" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc))
        msg = f"--backend ray: cannot connect to the cluster at {address}: {why}"
        raise RayBackendError(msg) from None


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0][:300] if text else type(exc).__name__


class _DropSigtermNotice(logging.Filter):
    """Drops Ray's notice that a ``ray.init`` outside the main thread sets no SIGTERM
    handler."""

    def filter(self, record: logging.LogRecord) -> bool:
        """False for that notice."""
        return not str(record.msg).startswith("SIGTERM handler is not set")


def init_bounded(
    ray: Any, options: Mapping[str, RayInitOption], doing: str, timeout_s: float
) -> None:
    """``ray.init(**options)`` in a thread, waited for at most ``timeout_s``: a
    :class:`RayBackendError` ``cannot <doing>: <why>`` when it fails or does not return in
    time (the thread is left behind; the process is about to end). Ctrl-C and SIGTERM act
    meanwhile."""
    failure: list[BaseException] = []
    done = threading.Event()

    def connect() -> None:
        try:
            ray.init(**options)
        except BaseException as exc:  # handed to the waiting thread
            failure.append(exc)
        finally:
            done.set()

    # ray.init outside the main thread says it sets no SIGTERM handler: that is the point
    worker_log = logging.getLogger("ray._private.worker")
    quiet = _DropSigtermNotice()
    worker_log.addFilter(quiet)
    threading.Thread(target=connect, name="ray.init", daemon=True).start()
    finished = done.wait(timeout_s)
    worker_log.removeFilter(quiet)
    if not finished:
        msg = f"--backend ray: cannot {doing}: no answer within {timeout_s:g} s (--connect-timeout)"
        raise RayBackendError(msg)
    if failure:
        with contextlib.suppress(Exception):
            ray.shutdown()
        tmpdir = os.environ.get("RAY_TMPDIR")
        hint = f" (RAY_TMPDIR={tmpdir})" if tmpdir and "address" not in options else ""
        msg = f"--backend ray: cannot {doing}: {_first_line(failure[0])}{hint}"
        raise RayBackendError(msg) from None


def start(address: str | None, cpus: int, *, timeout_s: float = CONNECT_TIMEOUT_S) -> Any:
    """Connect to the Ray cluster at ``address`` (probed first, :func:`probe`), or start one on
    this machine with ``cpus`` CPUs, within ``timeout_s`` (:func:`init_bounded`); returns the
    ``ray`` module."""
    if not 0 < timeout_s <= 3600:
        msg = f"--connect-timeout = {timeout_s}: must be in (0, 3600] s"
        raise RayBackendError(msg)
    ray = import_ray()
    if address:
        probe(address, min(timeout_s, PROBE_TIMEOUT_S))
        doing = f"connect to the cluster at {address}"
        init_bounded(ray, {"address": address, **RAY_INIT_OPTIONS}, doing, timeout_s)
    else:
        doing = "start a local Ray instance"
        init_bounded(ray, {"num_cpus": cpus, **RAY_INIT_OPTIONS}, doing, timeout_s)
    return ray


def worker_died(ray: Any, exc: BaseException) -> bool:
    """Whether ``exc`` (from ``ray.get``) says the task's worker or node died, the failures
    an episode is retried for (a task that raised is not retried: it would raise again)."""
    e = ray.exceptions
    died = (
        e.WorkerCrashedError,
        e.NodeDiedError,
        e.LocalRayletDiedError,
        e.OwnerDiedError,
        e.ObjectLostError,
    )
    return isinstance(exc, died)


@dataclass
class _Attempt(Generic[RunT]):
    """One submitted task: which episode of which grid cell, and how often it has been tried."""

    run: RunT
    episode: EpisodeSpec
    tries: int


class RaySweep(Generic[RunT]):
    """Runs a :class:`experiments.sweep.Sweep`'s episodes as Ray tasks and hands each result
    to the sweep, which writes every table as the local backend does."""

    def __init__(self, sweep: EpisodeBoard[RunT], ray: Any, cpus_per_episode: float) -> None:
        self.sweep = sweep
        self.ray = ray
        self.cpus_per_episode = cpus_per_episode
        self.task = ray.remote(num_cpus=cpus_per_episode, max_retries=0)(run_shipped_episode)
        self.datasets: dict[Path, tuple[str, Any]] = {}
        self.pending: dict[Any, _Attempt[RunT]] = {}
        self.cpu_s = 0.0
        self.nodes: set[str] = set()

    def _dataset(self, folder: Path) -> tuple[str, Any]:
        if folder not in self.datasets:
            archive = pack(folder)
            self.datasets[folder] = (dataset_key(archive), self.ray.put(archive))
        return self.datasets[folder]

    def submit(self, run: RunT, episode: EpisodeSpec, tries: int = 0) -> None:
        """Send one episode to the cluster."""
        key, ref = self._dataset(run.options.dataset)
        names = sorted(p.name for p in run.folder.iterdir() if p.is_file())
        shipped = ShippedEpisode(
            files=run_files(run.folder, names),
            options=run.options,
            index=episode.index,
            seed=episode.seed,
            dataset_key=key,
        )
        self.pending[self.task.remote(shipped, ref)] = _Attempt(run, episode, tries)

    def collect(self, ref: Any) -> None:
        """Take one finished task's result: unpack its folder, record its row, or retry it."""
        attempt = self.pending.pop(ref)
        run, episode = attempt.run, attempt.episode
        try:
            result: EpisodeResult = self.ray.get(ref)
        except self.ray.exceptions.RayError as exc:
            text = f"{run.cell.name} episode {episode.index} (seed {episode.seed})"
            first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else repr(exc)
            if worker_died(self.ray, exc) and attempt.tries < RETRIES:
                self.sweep.retried.append(f"{text}: {type(exc).__name__}: {first_line}")
                self.submit(run, episode, attempt.tries + 1)
                return
            self.sweep.finished(run, episode, None, f"Ray task failed: {first_line}")
            return
        if result.archive:
            unpack(result.archive, episode.folder)
        self.cpu_s += result.cpu_s
        self.nodes.add(result.node)
        self.sweep.finished(run, episode, result.metrics, result.reason)

    def execute(self) -> None:
        """Submit every episode, collect results as they finish; Ctrl-C or SIGTERM cancels
        the tasks (their workers are killed, and with them the episodes' processes)."""
        from experiments.run import raise_interrupt

        previous = {s: signal.signal(s, raise_interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            for run, episode in self.sweep.jobs:
                self.submit(run, episode)
            while self.pending:
                done, _ = self.ray.wait(list(self.pending), num_returns=1, timeout=0.5)
                for ref in done:
                    self.collect(ref)
                if self.sweep.cancel.is_set():  # a table could not be written
                    for ref in self.pending:
                        self.ray.cancel(ref, force=True)
                    self.pending.clear()
        except KeyboardInterrupt as exc:
            self.sweep.stopped.append(f"interrupted ({exc.args[0] if exc.args else 'SIGINT'})")
            self.sweep.cancel.set()
            for ref in self.pending:
                self.ray.cancel(ref, force=True)
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler)
        self.sweep.backend = BackendNote(
            name="ray",
            cpus_per_episode=self.cpus_per_episode,
            nodes=tuple(sorted(self.nodes)),
            episode_cpu_s=round(self.cpu_s, 3),
        )


def episode_cpus(cpus_per_episode: float | None) -> float:
    """The CPUs each task declares: ``--cpus-per-episode``, else :data:`EPISODE_CPUS`;
    :class:`RayBackendError` unless it is positive and finite."""
    cpus = EPISODE_CPUS if cpus_per_episode is None else cpus_per_episode
    if not 0 < cpus <= 1024:
        msg = f"--cpus-per-episode = {cpus_per_episode}: must be in (0, 1024]"
        raise RayBackendError(msg)
    return cpus


@dataclass
class RaySession:
    """A connection to Ray made before a sweep writes anything (:func:`connect`); run the
    sweep on it (:meth:`execute`), then :meth:`close` it."""

    ray: Any
    address: str | None
    cpus_per_episode: float

    def execute(self, sweep: EpisodeBoard[Any]) -> None:
        """Run every episode of ``sweep`` as a Ray task."""
        with contextlib.redirect_stdout(sys.stderr):
            RaySweep(sweep, self.ray, self.cpus_per_episode).execute()
        sweep.backend = dataclasses.replace(sweep.backend, address=self.address or "local")

    def close(self) -> None:
        """Shut the connection down (and a Ray instance started here)."""
        with contextlib.redirect_stdout(sys.stderr):
            self.ray.shutdown()


def connect(
    address: str | None,
    workers: int,
    cpus_per_episode: float | None,
    *,
    timeout_s: float = CONNECT_TIMEOUT_S,
) -> RaySession:
    """Connect to the Ray cluster at ``address`` (None: start a Ray instance here with
    ``workers`` x the episode's CPUs), bounded by ``timeout_s`` (:func:`start`)."""
    cpus = episode_cpus(cpus_per_episode)
    # Ray's driver prints its cluster's news (a worker died, ...) to standard output, which
    # belongs to the sweep's own output (``--json``): send it to standard error instead
    with contextlib.redirect_stdout(sys.stderr):
        ray = start(address, max(1, round(workers * cpus)), timeout_s=timeout_s)
    return RaySession(ray=ray, address=address, cpus_per_episode=cpus)


def execute_on_ray(
    sweep: EpisodeBoard[Any],
    address: str | None,
    workers: int,
    cpus_per_episode: float | None,
    *,
    timeout_s: float = CONNECT_TIMEOUT_S,
) -> None:
    """Run ``sweep`` on the Ray cluster at ``address`` (None: a Ray instance started here with
    ``workers`` x the episode's CPUs), then shut the connection down."""
    session = connect(address, workers, cpus_per_episode, timeout_s=timeout_s)
    try:
        session.execute(sweep)
    finally:
        session.close()


RAY_TEMP_PREFIX = "/tmp/cdwray-"
"""Prefix of a local head's temp folder (Ray's socket paths must stay short)."""


@contextlib.contextmanager
def local_head(cpus: int, *, start_timeout_s: float = 60.0) -> Iterator[str]:
    """A Ray head on this machine with ``cpus`` CPUs, for benchmarks and tests: its own temp
    folder, a fresh authentication token, a free port. Yields its address; while it runs,
    ``os.environ`` carries the token (Ray's clients, in this process or started from it, read
    it there). At the end every process it started is killed and the environment restored."""
    import secrets
    import subprocess

    temp = tempfile.mkdtemp(prefix=Path(RAY_TEMP_PREFIX).name, dir=Path(RAY_TEMP_PREFIX).parent)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    token = {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}
    saved = {k: os.environ.get(k) for k in token}
    os.environ.update(token)
    head = subprocess.Popen(
        [
            str(Path(sys.executable).parent / "ray"),
            "start",
            "--head",
            "--block",
            f"--port={port}",
            f"--num-cpus={cpus}",
            "--include-dashboard=false",
            "--disable-usage-stats",
            f"--temp-dir={temp}",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        _wait_for_port(head, port, start_timeout_s)
        yield f"127.0.0.1:{port}"
    finally:
        _stop_head(head, temp)
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
        shutil.rmtree(temp, ignore_errors=True)


def _wait_for_port(head: Any, port: int, timeout_s: float) -> None:
    import time

    deadline = time.monotonic() + timeout_s
    while True:
        if head.poll() is not None:
            err = head.stderr.read().decode(errors="replace") if head.stderr else ""
            msg = f"ray start --head exited with {head.returncode}: {err.strip()[-500:]}"
            raise RayBackendError(msg)
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        if time.monotonic() > deadline:
            msg = f"the Ray head did not open port {port} in {timeout_s:.0f} s"
            raise RayBackendError(msg)
        time.sleep(0.5)


def _stop_head(head: Any, temp: str) -> None:
    """Stop the head's process group, then kill whatever still names its temp folder."""
    import subprocess

    try:
        os.killpg(head.pid, signal.SIGTERM)
        head.wait(timeout=3)  # `ray start --block` often ignores SIGTERM for 20 s
    except (ProcessLookupError, subprocess.TimeoutExpired):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(head.pid, signal.SIGKILL)
        head.wait()
    for pid_dir in Path("/proc").iterdir():
        if not pid_dir.name.isdigit():
            continue
        try:
            cmdline = (pid_dir / "cmdline").read_bytes().decode(errors="replace")
        except OSError:
            continue
        if temp in cmdline:
            with contextlib.suppress(ProcessLookupError):
                os.kill(int(pid_dir.name), signal.SIGKILL)
