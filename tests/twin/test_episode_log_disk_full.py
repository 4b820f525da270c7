"""The episode log on a full disk: the event log's failed flush ends the episode with a clear
error, and ``status.json`` still says ``failed`` (rewritten over its own blocks), never
``running`` for ever."""

from __future__ import annotations

import contextlib
import json
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from interfaces.events import Event, EventType
from twin.episode_log import EpisodeWriteError, EventLog, start_episode_folder, write_status


@contextlib.contextmanager
def _tiny_disk(folder: Path) -> Iterator[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    mount = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=16k", "tmpfs", str(folder)],
        capture_output=True,
        check=False,
    )
    if mount.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mount.stderr.decode().strip()}")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)


def _fill(disk: Path) -> None:
    """Take every free block of ``disk``."""
    with contextlib.suppress(OSError), (disk / "filler").open("wb") as handle:
        while True:
            handle.write(b"\0" * 4096)
            handle.flush()


def _event(i: int) -> Event:
    return Event(time_s=i / 240, step=i, type=EventType.FAULT, object_id=0, data={"i": i})


def test_a_failed_flush_is_raised_by_the_next_event_and_status_says_failed(
    tmp_path: Path,
) -> None:
    with _tiny_disk(tmp_path / "disk") as disk:
        out = disk / "episode"
        log = start_episode_folder(out, scenario="s", seed=1)
        _fill(disk)
        for i in range(2000):
            log.append(_event(i))
        with pytest.raises(EpisodeWriteError, match=r"events\.jsonl: cannot write: No space"):
            log.flush()
        with pytest.raises(EpisodeWriteError, match=r"events\.jsonl: cannot write: No space"):
            log.append(_event(0))  # what the twin's step does next
        with pytest.raises(EpisodeWriteError):
            log.close()
        write_status(out, "failed", error="EpisodeWriteError: no space")
        status = json.loads((out / "status.json").read_text(encoding="utf-8"))
        assert (status["state"], status["complete"]) == ("failed", False)


def test_the_flushing_thread_keeps_its_error_for_the_step_loop(tmp_path: Path) -> None:
    with _tiny_disk(tmp_path / "disk") as disk:
        log = EventLog(disk / "events.jsonl", flush_interval_s=0.01)
        _fill(disk)
        for i in range(2000):
            log.append(_event(i))
        for _ in range(200):  # the thread flushes within a few intervals
            if log.error is not None:
                break
            time.sleep(0.01)
        assert log.error is not None
        with pytest.raises(EpisodeWriteError):
            log.append(_event(0))
        with pytest.raises(EpisodeWriteError):
            log.close()
