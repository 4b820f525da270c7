"""The values ``cdw-twin run`` passes around: how to run a scenario's episodes
(:class:`RunOptions`), one episode (:class:`EpisodeSpec`), the transports and the progress
callback. Shared by the run command, the supervision of an episode's processes, the sweep and
its Ray backend.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

TRANSPORTS = ("ros", "inproc")
"""How an episode's twin and controllers talk: ROS 2 between processes, or the in-process
bus (:mod:`experiments.inproc`; lockstep only)."""


Transport = Literal["ros", "inproc"]


@dataclass(frozen=True, kw_only=True)
class RunOptions:
    """How to run the episodes of one scenario.

    ``scenario_path`` is the resolved scenario file (overrides applied, validated); ``dataset``
    the meshgen output folder; ``cell_path`` the resolved cell file and ``stations`` its station
    names (one controller process each); ``restart_at_s`` the controller restart times (sim
    seconds); ``controller_params`` the controller's parameter file (None: its default);
    ``transport`` how the twin and the controllers talk (:data:`TRANSPORTS`); ``record``
    whether the twin writes the episode's ``recording.mcap``;
    ``foxglove_port`` (None: no live view), ``foxglove_host`` and ``gui`` are passed to the twin
    node, whose live view serves each episode in turn on the same port.
    """

    scenario_path: Path
    dataset: Path
    cell_path: Path | None = None
    stations: tuple[str, ...] = ()
    controller_params: Path | None = None
    mode: Literal["lockstep", "realtime"] = "lockstep"
    duration_s: float = 60.0
    restart_at_s: tuple[float, ...] = ()
    ack_timeout_s: float = 2.0
    foxglove_port: int | None = None
    foxglove_host: str = "127.0.0.1"
    gui: bool = False
    record_images_hz: float | None = None
    transport: Transport = "ros"
    record: bool = True


@dataclass(frozen=True)
class EpisodeSpec:
    """One episode to run."""

    index: int
    seed: int
    folder: Path


Progress = Callable[[float, float], None]
"""Called with (sim seconds, wall seconds) while an episode runs."""
