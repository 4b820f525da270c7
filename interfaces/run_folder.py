"""Where everything of a run and of its episodes lies: the one place that knows the file names.

A run folder (``cdw-twin run --out``, or one cell of a sweep) holds::

    scenario.yaml   cell.yaml   controller.yaml      what ran (copies, so it reruns as it ran)
    episodes.json   episodes.csv                     one row per episode (its metrics)
    run.json                                         the means over the episodes
    ep000/                                           one folder per episode:
        twin/   events.jsonl  status.json  summary.json  telemetry.json
        recording.mcap                               (recording.mcap.partial while it runs)
        twin.log
        controller.json  controller.log              one station (controller_1.json after a restart)
        controller-<station>.json ...                several stations

The twin writes ``twin/``, each controller its stats file, the runner the rest; every reader
(run, sweep, Ray, report, player, offline) finds the files through :class:`RunFolder` and
:class:`EpisodeFolder` and reads the typed records of :mod:`interfaces.run_records`.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

SCENARIO_FILE = "scenario.yaml"
"""The run's scenario (with the command line's overrides), what every process reads."""
CELL_FILE = "cell.yaml"
"""The resolved cell the run's scenario names."""
CONTROLLER_FILE = "controller.yaml"
"""The controller's parameter file the run's scenario names."""
EPISODES_JSON = "episodes.json"
EPISODES_CSV = "episodes.csv"
RUN_JSON = "run.json"

TWIN_DIR = "twin"
EVENTS_FILE = "events.jsonl"
STATUS_FILE = "status.json"
SUMMARY_FILE = "summary.json"
TELEMETRY_FILE = "telemetry.json"
RECORDING_FILE = "recording.mcap"
CAMERA_FRAME_PREFIX = "camera_"
"""With the camera source, the twin's folder holds one example frame per camera with its
detections drawn, ``camera_NAME.png`` (:func:`camera_frame_name`)."""
PARTIAL_SUFFIX = ".partial"
"""Appended to the recording's name while it is written (and left after a crash)."""

_EPISODE_DIR = re.compile(r"ep(\d+)")


def camera_frame_name(camera: str) -> str:
    """The file name of camera ``camera``'s example frame in the twin's folder."""
    return f"{CAMERA_FRAME_PREFIX}{camera}.png"


def episode_dir_name(index: int) -> str:
    """``ep000`` for episode 0."""
    return f"ep{index:03d}"


def controller_stem(station: str | None, stations: Sequence[str]) -> str:
    """The stem of a station's controller files: ``controller`` in a one-station cell (or for
    ``station`` None), ``controller-<station>`` otherwise."""
    return "controller" if station is None or len(stations) <= 1 else f"controller-{station}"


def stats_name(stem: str, instance: int) -> str:
    """The stats file of controller ``instance`` (0 first, > 0 after restarts)."""
    return f"{stem}.json" if instance == 0 else f"{stem}_{instance}.json"


def stats_instance(name: str, stem: str) -> int | None:
    """The instance a file name is the stats of (:func:`stats_name`), None when it is not."""
    match = re.fullmatch(rf"{re.escape(stem)}(?:_(\d+))?\.json", name)
    return None if match is None else int(match.group(1) or 0)


@dataclass(frozen=True)
class EpisodeFolder:
    """One episode's folder (``ep000``) and the files in it."""

    path: Path

    @property
    def index(self) -> int | None:
        """The episode's index from the folder's name, None for another name."""
        match = _EPISODE_DIR.fullmatch(self.path.name)
        return None if match is None else int(match.group(1))

    @property
    def run(self) -> RunFolder:
        """The run folder this episode belongs to."""
        return RunFolder(self.path.parent)

    @property
    def twin(self) -> Path:
        """The twin's episode log folder (what ``cdw-twin node --out`` writes)."""
        return self.path / TWIN_DIR

    @property
    def events(self) -> Path:
        return self.twin / EVENTS_FILE

    @property
    def status(self) -> Path:
        return self.twin / STATUS_FILE

    @property
    def summary(self) -> Path:
        return self.twin / SUMMARY_FILE

    @property
    def telemetry(self) -> Path:
        return self.twin / TELEMETRY_FILE

    @property
    def recording(self) -> Path:
        return self.path / RECORDING_FILE

    def camera_frames(self) -> list[Path]:
        """The example camera frames the twin wrote (none with the oracle), by name."""
        return sorted(self.twin.glob(f"{CAMERA_FRAME_PREFIX}*.png"))

    @property
    def twin_log(self) -> Path:
        return self.path / "twin.log"

    def controller_stats(self, station: str | None, stations: Sequence[str], instance: int) -> Path:
        """The stats file of a station's controller ``instance`` (0, then 1, ... after restarts)."""
        return self.path / stats_name(controller_stem(station, stations), instance)

    def controller_log(self, station: str | None, stations: Sequence[str]) -> Path:
        """The log of a station's controllers (every instance appends to it)."""
        return self.path / f"{controller_stem(station, stations)}.log"

    def stats_files(self, station: str | None, stations: Sequence[str]) -> list[Path]:
        """A station's controller stats files that exist, in instance order."""
        stem = controller_stem(station, stations)
        found = [
            (instance, path)
            for path in self.path.glob(f"{stem}*.json")
            if (instance := stats_instance(path.name, stem)) is not None
        ]
        return [path for _, path in sorted(found)]


@dataclass(frozen=True)
class RunFolder:
    """A run's folder: what ran, the episodes' folders and the tables over them."""

    path: Path

    @property
    def scenario(self) -> Path:
        return self.path / SCENARIO_FILE

    @property
    def cell(self) -> Path:
        return self.path / CELL_FILE

    @property
    def controller(self) -> Path:
        return self.path / CONTROLLER_FILE

    @property
    def episodes_json(self) -> Path:
        return self.path / EPISODES_JSON

    @property
    def episodes_csv(self) -> Path:
        return self.path / EPISODES_CSV

    @property
    def run_json(self) -> Path:
        return self.path / RUN_JSON

    def episode(self, index: int) -> EpisodeFolder:
        """Episode ``index``'s folder (it may not exist yet)."""
        return EpisodeFolder(self.path / episode_dir_name(index))

    def episodes(self) -> list[EpisodeFolder]:
        """The episode folders present, in index order."""
        found = [EpisodeFolder(p) for p in self.path.glob("ep[0-9]*") if p.is_dir()]
        return sorted((e for e in found if e.index is not None), key=lambda e: e.index or 0)
