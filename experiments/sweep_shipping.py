"""What travels between a sweep's driver and a Ray worker, and how (``--backend ray``,
:mod:`experiments.ray_backend`).

A task gets its episode by value (:class:`ShippedEpisode`: the grid cell's small run-folder
files, the run options, index, seed and the dataset's key), the dataset once per sweep as a tar
archive (:func:`pack`) unpacked once per worker machine under its SHA-256
(:func:`local_dataset`), runs the episode in a temporary run folder
(:func:`run_shipped_episode`) and sends back an :class:`EpisodeResult`: the metrics, the
episode folder as a tar archive and the CPU seconds used. Nothing relies on a shared file
system.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import resource
import shutil
import socket
import tarfile
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from interfaces.run_folder import RunFolder
from interfaces.run_records import EpisodeMetrics

if TYPE_CHECKING:
    from experiments.run_types import RunOptions


@dataclass(frozen=True, kw_only=True)
class ShippedEpisode:
    """Everything a worker needs to run one episode, by value.

    ``files`` are the grid cell's run-folder files by name; ``options`` the driver's run
    options, whose paths the worker maps onto its own copy (:func:`worker_options`).
    """

    files: dict[str, bytes]
    options: RunOptions
    index: int
    seed: int
    dataset_key: str


@dataclass(frozen=True, kw_only=True)
class EpisodeResult:
    """What a task sends back: the metrics (None when the episode failed, with ``reason``),
    the episode folder as a tar archive, and the CPU seconds the episode's processes used."""

    metrics: EpisodeMetrics | None
    reason: str
    archive: bytes
    cpu_s: float
    node: str


def pack(folder: Path) -> bytes:
    """``folder``'s content as an uncompressed tar archive, names relative to it, in sorted
    order (the same folder gives the same bytes)."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        for path in sorted(folder.rglob("*")):
            info = tar.gettarinfo(str(path), arcname=str(path.relative_to(folder)))
            info.mtime = 0
            info.uid = info.gid = 0
            info.uname = info.gname = ""
            if info.isfile():
                with path.open("rb") as handle:
                    tar.addfile(info, handle)
            elif info.isdir():
                tar.addfile(info)
    return buffer.getvalue()


def unpack(archive: bytes, folder: Path) -> None:
    """Unpack ``archive`` as ``folder`` whole: into a temporary sibling renamed into place,
    so a folder of that name is never half-written. An existing ``folder`` is replaced."""
    folder.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    try:
        with tarfile.open(fileobj=io.BytesIO(archive), mode="r") as tar:
            tar.extractall(staging, filter="data")
        if folder.exists():
            shutil.rmtree(folder)
        staging.rename(folder)
    finally:
        if staging.exists():
            shutil.rmtree(staging)


def dataset_key(archive: bytes) -> str:
    """The key a worker caches an unpacked dataset under: the archive's SHA-256."""
    return hashlib.sha256(archive).hexdigest()


def worker_cache() -> Path:
    """Where a worker machine keeps the datasets it has unpacked."""
    return Path(tempfile.gettempdir()) / "cdw-twin-ray" / "datasets"


def local_dataset(key: str, archive: bytes) -> Path:
    """The dataset of ``key`` on this machine, unpacked from ``archive`` the first time."""
    folder = worker_cache() / key
    if not folder.is_dir():
        try:
            unpack(archive, folder)
        except OSError:
            if not folder.is_dir():  # another task unpacked it first: theirs is as good
                raise
    return folder


def worker_options(options: RunOptions, run_dir: Path, dataset: Path) -> RunOptions:
    """``options`` with every path of the driver's run folder moved to ``run_dir`` (its copy
    on the worker) and the dataset to ``dataset``."""

    def moved(path: Path | None) -> Path | None:
        return None if path is None else run_dir / path.name

    return dataclasses.replace(
        options,
        scenario_path=run_dir / options.scenario_path.name,
        cell_path=moved(options.cell_path),
        controller_params=moved(options.controller_params),
        dataset=dataset,
    )


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_shipped_episode(shipped: ShippedEpisode, dataset_archive: bytes) -> EpisodeResult:
    """The Ray task: run one episode in a temporary run folder; return its result."""
    from experiments.episode_processes import EpisodeFailedError, run_episode
    from experiments.run_types import EpisodeSpec

    dataset = local_dataset(shipped.dataset_key, dataset_archive)
    cpu0 = _children_cpu_s()
    with tempfile.TemporaryDirectory(prefix="cdw-ray-run-") as tmp:
        run_dir = Path(tmp) / "run"
        run_dir.mkdir()
        for name, data in shipped.files.items():
            (run_dir / name).write_bytes(data)
        options = worker_options(shipped.options, run_dir, dataset)
        episode = EpisodeSpec(
            index=shipped.index,
            seed=shipped.seed,
            folder=RunFolder(run_dir).episode(shipped.index).path,
        )
        metrics: EpisodeMetrics | None
        try:
            metrics, reason = run_episode(options, episode), ""
        except EpisodeFailedError as exc:
            metrics, reason = None, exc.reason
        archive = pack(episode.folder) if episode.folder.is_dir() else b""
    return EpisodeResult(
        metrics=metrics,
        reason=reason,
        archive=archive,
        cpu_s=_children_cpu_s() - cpu0,
        node=socket.gethostname(),
    )


def run_files(folder: Path, names: Iterable[str]) -> dict[str, bytes]:
    """The named files of a run folder, by name (what a worker needs of it)."""
    return {name: (folder / name).read_bytes() for name in names}
