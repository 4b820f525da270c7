"""The episode recording: every message of the cell contract, as serialized CDR, in one MCAP.

The twin node writes its episode's recording from inside its own process (``--record``):
:class:`McapRecording` takes each message's bytes as sent or received. The topics come from
the contract for the cell's station namespaces::

    from interfaces.contract import resolved_topics
    from twin.recording import DEFAULT_FLUSH_INTERVAL_S, McapRecording

    recording = McapRecording(
        Path("ep0/recording.mcap"),
        resolved_topics(("s1", "s2")),
        flush_interval_s=DEFAULT_FLUSH_INTERVAL_S,
    )
    recording.write("/s1/joint_states", data, time.time_ns())
    recording.close()

The file is a ROS 2 MCAP (profile ``ros2``, schemas ``ros2msg`` with the ``====``/``MSG:``
dependency sections rosbag2 writes, message encoding ``cdr``, channel metadata
``offered_qos_profiles``), readable by ``mcap_ros2``, by rosbags' ``AnyReader`` (a bare
``.mcap`` with embedded schemas is enough) and by Foxglove.

Crash safety: the file is written as ``OUT.partial`` and renamed to ``OUT`` by :meth:`close`,
so a file named ``OUT`` is always complete (with its summary and index). With
``flush_interval_s`` the chunk in progress is closed and handed to the operating system at
least that often, so after a SIGKILL ``OUT.partial`` holds everything up to that interval
before the kill (``experiments.offline`` reads such a file up to the cut,
``experiments.record.recover_recording`` rewrites it whole). The stand-alone recorder for a
cell the twin does not run is ``cdw-twin record`` (:mod:`experiments.record`).
"""

from __future__ import annotations

import math
import os
import re
import sys
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import yaml

from interfaces.contract import Qos, Topic
from interfaces.errors import CdwTwinError

if TYPE_CHECKING:
    from interfaces.cell import Cell

PARTIAL_SUFFIX = ".partial"
"""Suffix of a recording being written (or left by a crash)."""

DEFAULT_FLUSH_INTERVAL_S = 0.5
"""Seconds between chunk flushes: what a SIGKILL may lose at most."""

SEPARATOR = "=" * 80
_PRIMITIVES = frozenset(
    {
        "bool",
        "byte",
        "char",
        "float32",
        "float64",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "string",
        "wstring",
    }
)
_INFINITE = {"sec": 9223372036, "nsec": 854775807}


class RecordingError(CdwTwinError):
    """A recording cannot be written or read (bad path, missing message definition, no data)."""


# -- message definitions ------------------------------------------------------------------------
def share_dirs() -> list[Path]:
    """Where ``<pkg>/msg/<Type>.msg`` files are looked up: ``AMENT_PREFIX_PATH``, then the venv."""
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(Path(sys.prefix))
    return [p / "share" for p in prefixes]


def split_type(msgtype: str) -> tuple[str, str]:
    """``(package, Type)`` of ``pkg/msg/Type`` or ``pkg/Type``."""
    parts = msgtype.split("/")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[1] != "msg"):
        msg = f"message type {msgtype!r} is not 'pkg/msg/Type' or 'pkg/Type'"
        raise RecordingError(msg)
    return parts[0], parts[-1]


def _msg_text(package: str, name: str, dirs: Sequence[Path]) -> str:
    for share in dirs:
        path = share / package / "msg" / f"{name}.msg"
        if path.is_file():
            return path.read_text(encoding="utf-8")
    searched = ", ".join(str(d / package / "msg" / f"{name}.msg") for d in dirs)
    msg = f"no message definition for {package}/{name}: searched {searched}"
    raise RecordingError(msg)


def _field_types(text: str, package: str) -> list[tuple[str, str]]:
    """The non-primitive (package, Type) of every field or constant in a ``.msg`` text."""
    found: list[tuple[str, str]] = []
    for line in text.splitlines():
        code = line.split("#", 1)[0].strip()
        if not code:
            continue
        base = re.sub(r"\[.*\]$", "", code.split()[0])
        base = base.split("<=", 1)[0]
        if base in _PRIMITIVES:
            continue
        if "/" in base:
            found.append(split_type(base))
        elif base == "Header":
            found.append(("std_msgs", "Header"))
        else:
            found.append((package, base))
    return found


def message_definition(msgtype: str, dirs: Sequence[Path] | None = None) -> str:
    """The ``ros2msg`` schema text of ``msgtype`` as rosbag2 writes it.

    The type's own ``.msg`` text, then each type it depends on (depth first, once each) after a
    line of 80 ``=`` and a ``MSG: pkg/Type`` line.
    """
    dirs = share_dirs() if dirs is None else dirs
    package, name = split_type(msgtype)
    root = _msg_text(package, name, dirs)
    seen = {(package, name)}
    sections: list[str] = []
    stack = list(reversed(_field_types(root, package)))
    while stack:
        dep = stack.pop()
        if dep in seen:
            continue
        seen.add(dep)
        text = _msg_text(*dep, dirs)
        sections.append(f"{SEPARATOR}\nMSG: {dep[0]}/{dep[1]}\n{text}")
        stack.extend(reversed(_field_types(text, dep[0])))
    return "\n".join([root.rstrip("\n"), *(s.rstrip("\n") for s in sections)]) + "\n"


def offered_qos_yaml(qos: Qos) -> str:
    """The ``offered_qos_profiles`` channel metadata rosbag2 (Jazzy) writes, for ``qos``."""
    profile = {
        "history": "keep_last",
        "depth": qos.depth,
        "reliability": "reliable" if qos.reliable else "best_effort",
        "durability": "transient_local" if qos.latched else "volatile",
        "deadline": _INFINITE,
        "lifespan": _INFINITE,
        "liveliness": "automatic",
        "liveliness_lease_duration": _INFINITE,
        "avoid_ros_namespace_conventions": False,
    }
    return yaml.safe_dump([profile], sort_keys=False)


# -- the file -----------------------------------------------------------------------------------
def partial_path(out: Path) -> Path:
    """Where the recording of ``out`` is written until it is finished cleanly."""
    return out.with_name(out.name + PARTIAL_SUFFIX)


class McapRecording:
    """An open ROS 2 MCAP file taking raw CDR messages; :meth:`close` renames it into place.

    ``topics`` are ``(wire name, contract topic)`` pairs, as
    :func:`interfaces.contract.resolved_topics` gives them for a cell's station namespaces: one
    channel each, with the topic's type and QoS. With ``flush_interval_s``, :meth:`write` also
    flushes once that long has passed since the last flush (for a writer with no loop of its
    own, such as the twin node's tap).
    """

    def __init__(
        self,
        out: Path,
        topics: Iterable[tuple[str, Topic]],
        dirs: Sequence[Path] | None = None,
        *,
        flush_interval_s: float | None = None,
        library: str = "cdw-twin",
    ) -> None:
        from mcap.writer import CompressionType, Writer

        if out.suffix != ".mcap":
            msg = f"recording path {out} must end in .mcap"
            raise RecordingError(msg)
        self.out = out
        self.partial = partial_path(out)
        out.parent.mkdir(parents=True, exist_ok=True)
        self._stream: IO[bytes] = self.partial.open("wb")
        # mcap's Writer is partly unannotated
        self._writer: Any = Writer(self._stream, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library=library)
        self.channels: dict[str, int] = {}
        self.counts: dict[str, int] = {}
        self.n_bytes = 0
        schema_ids: dict[str, int] = {}
        for name, topic in topics:
            if name in self.channels:
                continue
            if topic.msgtype not in schema_ids:
                text = message_definition(topic.msgtype, dirs)
                schema_ids[topic.msgtype] = self._writer.register_schema(
                    name=topic.msgtype, encoding="ros2msg", data=text.encode()
                )
            self.channels[name] = self._writer.register_channel(
                topic=name,
                message_encoding="cdr",
                schema_id=schema_ids[topic.msgtype],
                metadata={"offered_qos_profiles": offered_qos_yaml(topic.qos)},
            )
            self.counts[name] = 0
        self._flush_interval_s = flush_interval_s
        self._next_flush = math.inf
        self.flush()

    def write(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Append one serialized message on ``topic`` (its wire name) received at
        ``log_time_ns``."""
        try:
            channel = self.channels[topic]
        except KeyError:
            msg = f"{self.out}: topic {topic!r} is not one of the recorded channels"
            raise RecordingError(msg) from None
        self._writer.add_message(channel, log_time=log_time_ns, data=data, publish_time=log_time_ns)
        self.counts[topic] += 1
        self.n_bytes += len(data)
        if time.monotonic() >= self._next_flush:
            self.flush()

    def flush(self) -> None:
        """Close the chunk in progress and hand everything to the operating system."""
        self._writer.flush()
        if self._flush_interval_s is not None:
            self._next_flush = time.monotonic() + self._flush_interval_s

    def close(self) -> Path:
        """Write the summary and footer, close, rename ``OUT.partial`` to ``OUT``; returns OUT."""
        self._writer.finish()
        self._stream.close()
        self.partial.replace(self.out)
        return self.out


def open_cell_recording(out: Path | None, cell: Cell) -> McapRecording | None:
    """The episode's MCAP of every topic of the cell (every station's under its namespace, each
    camera's: :func:`interfaces.cell_topics.cell_topics`), written as ``OUT.partial`` until it
    is closed.

    Chunks are flushed every 0.5 s, so a killed twin leaves a readable ``OUT.partial``.
    """
    if out is None:
        return None
    from interfaces.cell_topics import cell_topics

    return McapRecording(out, cell_topics(cell), flush_interval_s=DEFAULT_FLUSH_INTERVAL_S)


__all__ = [
    "DEFAULT_FLUSH_INTERVAL_S",
    "PARTIAL_SUFFIX",
    "McapRecording",
    "RecordingError",
    "message_definition",
    "offered_qos_yaml",
    "open_cell_recording",
    "partial_path",
    "share_dirs",
    "split_type",
]
