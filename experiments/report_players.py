"""Each listed episode's player (:mod:`experiments.player`), written or refreshed by the report.

A player page is stale, and rewritten, when any file it is made from is newer than it: the
player's code and every one of its assets (:func:`experiments.player.page_sources`: a change to
the script or the style alone must reach every page), the run's cell, the episode's recording
and its events. A page that is up to date is left as it is.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from experiments.report_data import Episode
from interfaces.run_folder import EpisodeFolder


@dataclass(frozen=True)
class PlayerLinks:
    """Where each episode's player is, relative to the report (in the episodes' order), and
    what writing them noted."""

    hrefs: tuple[str, ...]
    notes: tuple[str, ...]


def player_inputs(folder: Path) -> list[Path]:
    """The files the player of episode folder ``folder`` is made from (see the module)."""
    from experiments.player import page_sources

    episode = EpisodeFolder(folder)
    return [*page_sources(), episode.run.cell, episode.recording, episode.events]


def is_stale(page: Path, inputs: Sequence[Path]) -> bool:
    """Whether ``page`` is missing or older than one of the ``inputs`` that exist."""
    stamp = page.stat().st_mtime if page.is_file() else -1.0
    return any(p.is_file() and p.stat().st_mtime > stamp for p in inputs)


def write_players(
    episodes: Sequence[Episode], out: Path, staging: Path | None = None
) -> PlayerLinks:
    """Write (or refresh) the player of each of ``episodes``; links relative to ``out``.

    An episode folder that cannot be written to gets its player in ``out/players/`` (written
    into ``staging``, the folder that becomes ``out``, when given).
    """
    from experiments.player import PAGE_NAME, write_player

    hrefs: list[str] = []
    notes: list[str] = []
    for ep in episodes:
        page = ep.folder / PAGE_NAME
        if is_stale(page, player_inputs(ep.folder)):
            try:
                written = write_player(ep.folder, ep.run_dir)
            except OSError:
                name = Path("players") / ep.run_dir.name / f"{ep.folder.name}.html"
                page = out / name
                written = write_player(ep.folder, ep.run_dir, (staging or out) / name)
            notes.extend(f"{ep.name} player: {note}" for note in written.notes)
        hrefs.append(Path(os.path.relpath(page, out)).as_posix())
    return PlayerLinks(tuple(hrefs), tuple(notes))
