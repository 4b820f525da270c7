"""The episode log a twin run leaves behind: events, scores, counters, tracking results.

Files:

- ``events.jsonl``: one event per line (:meth:`Event.to_json`), appended while the episode runs
  by :class:`EventLog` and flushed at least every ``flush_interval_s`` of wall time (0.5 s), so
  a killed process leaves every event up to its last second; the lines are the events in the
  order of :attr:`twin.sim.Twin.events`;
- ``status.json``: written when the episode starts (``"state": "running"``) and again when it
  ends (``"finished"`` or ``"interrupted"``); a folder whose status still says ``running`` and
  that has no ``summary.json`` belongs to a process that was killed;
- ``summary.json``: scores, tracking, counters, timing, written atomically when the episode
  ends (``"complete": false`` when it was interrupted). A folder without it is incomplete.

A write that fails (a full disk, a folder made read-only) ends the episode: the event log
keeps the error of its flushing thread and raises :class:`EpisodeWriteError` at the next event
or at :meth:`EventLog.close`; ``status.json`` then says ``failed`` with the error, rewritten in
place over the old one when no new file can be created (:func:`write_status`).
"""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path
from types import TracebackType
from typing import Any

from interfaces.errors import CdwTwinError
from interfaces.events import Event
from interfaces.fileio import overwrite_in_place, write_atomic
from interfaces.run_folder import EVENTS_FILE, STATUS_FILE, SUMMARY_FILE, TELEMETRY_FILE
from interfaces.run_records import EpisodeSummary

DEFAULT_FLUSH_INTERVAL_S = 0.5
"""Wall seconds between two flushes of :class:`EventLog` (at most)."""

EPISODE_END_FILES = (SUMMARY_FILE, TELEMETRY_FILE)
"""Files an episode writes when it ends: removed when a new episode starts in the folder."""


class EpisodeWriteError(CdwTwinError):
    """A file of the episode folder cannot be written (the message names it and why)."""


def _write_error(path: Path, exc: OSError) -> EpisodeWriteError:
    return EpisodeWriteError(f"{path}: cannot write: {exc.strerror or exc}")


class EventLog:
    """``events.jsonl`` written as the events happen: append-only, flushed by wall time.

    :meth:`append` (the twin's ``event_sink``) only queues the event's line; a background
    thread writes and flushes the queue every ``flush_interval_s`` of wall time, so the step
    loop never waits for the disk and there is no fsync. :meth:`close` writes what is left.
    Opening truncates an older log of the same path. A failed write stops the thread and is
    raised (:class:`EpisodeWriteError`) by the next :meth:`append`, :meth:`flush` or
    :meth:`close`.
    """

    def __init__(self, path: Path, *, flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        try:
            self._handle = path.open("w", encoding="utf-8")
        except OSError as exc:
            raise _write_error(path, exc) from None
        self.error: EpisodeWriteError | None = None
        self._interval_s = flush_interval_s
        self._pending: list[str] = []
        self._queue_lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._flush_loop, name="events.jsonl", daemon=True)
        self._thread.start()

    def __enter__(self) -> EventLog:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def append(self, event: Event) -> None:
        """Queue one event's line; it is on disk within ``flush_interval_s``."""
        if self.error is not None:
            raise self.error
        line = event.to_json() + "\n"
        with self._queue_lock:
            self._pending.append(line)

    def flush(self) -> None:
        """Write and flush every queued line now."""
        with self._write_lock:
            if self.error is not None:
                raise self.error
            with self._queue_lock:
                lines, self._pending = self._pending, []
            if lines and not self._handle.closed:
                try:
                    self._handle.write("".join(lines))
                    self._handle.flush()
                except OSError as exc:
                    self.error = _write_error(self.path, exc)
                    raise self.error from None

    def _flush_loop(self) -> None:
        while not self._closing.wait(self._interval_s):
            try:
                self.flush()
            except EpisodeWriteError:
                return  # kept in self.error: the step loop raises it

    def close(self) -> None:
        """Stop the flushing thread, write what is left and close the file."""
        if self._handle.closed:
            return
        self._closing.set()
        self._thread.join()
        try:
            self.flush()
        finally:
            try:
                self._handle.close()
            except OSError as exc:
                self.error = self.error or _write_error(self.path, exc)
        if self.error is not None:
            raise self.error


def write_status(out: Path, state: str, **fields: Any) -> None:
    """Write ``status.json``: the episode's ``state`` and whether it is ``complete``.

    When no new file can be created (a full disk) the old ``status.json`` is rewritten over
    its own blocks (:func:`interfaces.fileio.overwrite_in_place`), so a failed episode never
    keeps saying ``running``; :class:`EpisodeWriteError` when even that fails."""
    data = {"state": state, "complete": state == "finished", "pid": os.getpid(), **fields}
    path = out / STATUS_FILE
    try:
        write_atomic(path, json.dumps(data, indent=2, sort_keys=True) + "\n")
    except OSError as exc:
        try:
            overwrite_in_place(path, json.dumps(data, sort_keys=True) + "\n")
        except OSError:
            raise _write_error(path, exc) from None


def write_episode_file(out: Path, name: str, text: str) -> None:
    """Write ``out/name`` atomically; :class:`EpisodeWriteError` naming it when it fails."""
    try:
        write_atomic(out / name, text)
    except OSError as exc:
        raise _write_error(out / name, exc) from None


def start_episode_folder(out: Path, **fields: Any) -> EventLog:
    """Prepare ``out`` for a new episode: remove the end files of an older one, write
    ``status.json`` (``running``) and open the streaming ``events.jsonl``."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        for name in EPISODE_END_FILES:
            (out / name).unlink(missing_ok=True)
    except OSError as exc:
        raise _write_error(out, exc) from None
    write_status(out, "running", **fields)
    return EventLog(out / EVENTS_FILE)


def write_summary(out: Path, summary: EpisodeSummary) -> None:
    """Write ``summary.json`` (atomically) into ``out``."""
    try:
        summary.write(out / SUMMARY_FILE)
    except OSError as exc:
        raise _write_error(out / SUMMARY_FILE, exc) from None
