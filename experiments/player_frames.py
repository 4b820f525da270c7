"""The player's frames: an episode's recording (``recording.mcap``) read into the compact,
difference-coded arrays its page draws (:mod:`experiments.player`).

Every object's ground truth per frame (``/objects/ground_truth``, 30 Hz: position in mm,
quaternion in 1e-4 with ``w >= 0``, velocity in mm/s, a flag word), the belt's travelled distance
per frame, each station's TCP path (``tcp_pose`` at :data:`SAMPLE_HZ`) and every target its
controller sent (``controller/target``). Integer columns are stored as differences from the
previous value (the first from 0); flags only where they change.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any, TypedDict

from experiments.player_footprints import (
    Footprint,
    MeshFinder,
    PlayerError,
    box_outline,
    footprint_outline,
)
from interfaces.contract import BELT_STATE, GROUND_TRUTH_TOPIC, PICK_TARGET, TCP_POSE

SAMPLE_HZ = 30.0
"""Rate at which TCP poses are kept (ground truth is recorded at this rate already)."""

FLAG_BITS = ("on_belt", "in_workspace", "held", "in_bin")
"""The ground truth's flags, bit 0 upwards, in the per-frame flag words."""
ABSENT_BIT = 16
"""Flag bit of a frame in which the object is missing from the ground truth."""

Message = Any
"""A message decoded from the recording (its ROS type's fields as attributes)."""

States = dict[int, dict[int, Message]]
"""Per object id, its ground-truth state per frame index."""

Target = list[float | str]
"""``[t, track_id, phase, class, x, y, z, vx, vy]`` (s, -, -, -, mm, mm, mm, mm/s, mm/s)."""


class Track(TypedDict):
    """One object's frames, from its first to its last: ``first`` frame index, ``n`` frames,
    ``flags`` as ``[frame offset, flag word]`` where the word changes, and difference-coded
    position (mm), quaternion (1e-4) and velocity (mm/s) columns, each ``(n,) int``."""

    first: int
    n: int
    flags: list[list[int]]
    x: list[int]
    y: list[int]
    z: list[int]
    qx: list[int]
    qy: list[int]
    qz: list[int]
    qw: list[int]
    vx: list[int]
    vy: list[int]
    vz: list[int]


class ObjectData(Track):
    """An object on the page: what it is, its footprint (``outline``: ``(k, 2)`` points in
    1e-4 m, ``zspan`` its low and high z in 1e-4 m, ``outline_from`` ``mesh`` or ``box``), its
    recorded extents (``dims``, SI units) and its :class:`Track`."""

    id: int
    cls: str
    src: str
    outline_from: str
    outline: list[list[int]]
    zspan: list[int]
    dims: dict[str, float | None]


class TcpPath(TypedDict):
    """A station's TCP at :data:`SAMPLE_HZ`: stamps (s) and difference-coded positions (mm)."""

    t: list[float]
    x: list[int]
    y: list[int]
    z: list[int]


def stamp_s(header: Message) -> float:
    """A message header's stamp in seconds."""
    return float(header.stamp.sec) + 1e-9 * float(header.stamp.nanosec)


def mm(value: float) -> int:
    """Metres to whole millimetres."""
    return round(value * 1000.0)


def deltas(values: Iterable[int]) -> list[int]:
    """``values`` as differences from the previous one (the first from 0)."""
    out, last = [], 0
    for v in values:
        out.append(v - last)
        last = v
    return out


def round4(value: float) -> float | None:
    """A float to 4 decimals (a non-finite one to None: JSON has no NaN)."""
    return round(value, 4) if math.isfinite(value) else None


def _read(recording: Path, topic: str) -> Iterator[Message]:
    from experiments.offline import read_topic

    for _, msg in read_topic(recording, topic):
        yield msg


def _flags(obj: Message) -> int:
    return sum(1 << i for i, name in enumerate(FLAG_BITS) if getattr(obj, name))


def ground_truth(recording: Path) -> tuple[list[float], States]:
    """Frame stamps (s, ascending, distinct) and, per object id, its state per frame index."""
    by_stamp: dict[float, Message] = {}
    for msg in _read(recording, GROUND_TRUTH_TOPIC.name):
        by_stamp[round(stamp_s(msg.header), 6)] = msg
    times = sorted(by_stamp)
    states: States = {}
    for k, t in enumerate(times):
        for obj in by_stamp[t].objects:
            states.setdefault(int(obj.id), {})[k] = obj
    return times, states


def track(states: dict[int, Message]) -> Track:
    """One object's per-frame arrays: from its first frame to its last, difference-coded (a
    frame it is missing from repeats the last state it had, flagged :data:`ABSENT_BIT`)."""
    first, last = min(states), max(states)
    cols: dict[str, list[int]] = {
        k: [] for k in ("x", "y", "z", "qx", "qy", "qz", "qw", "vx", "vy", "vz")
    }
    flags: list[list[int]] = []
    prev: Message = None
    prev_flags = -1
    for k in range(first, last + 1):
        obj = states.get(k)
        word = ABSENT_BIT if obj is None else _flags(obj)
        obj = obj if obj is not None else prev
        p, q, v = obj.pose.position, obj.pose.orientation, obj.twist.linear
        for key, value in (("x", p.x), ("y", p.y), ("z", p.z), ("vx", v.x), ("vy", v.y)):
            cols[key].append(mm(value))
        cols["vz"].append(mm(v.z))
        sign = -1.0 if q.w < 0 else 1.0  # q and -q are one rotation: keep w >= 0
        for key, value in (("qx", q.x), ("qy", q.y), ("qz", q.z), ("qw", q.w)):
            cols[key].append(round(sign * value * 1e4))
        if word != prev_flags:
            flags.append([k - first, word])
            prev_flags = word
        prev = obj
    d = {key: deltas(values) for key, values in cols.items()}
    return Track(
        first=first,
        n=last - first + 1,
        flags=flags,
        x=d["x"],
        y=d["y"],
        z=d["z"],
        qx=d["qx"],
        qy=d["qy"],
        qz=d["qz"],
        qw=d["qw"],
        vx=d["vx"],
        vy=d["vy"],
        vz=d["vz"],
    )


def _sampled(recording: Path, topic: str, hz: float) -> list[tuple[float, Message]]:
    """Messages of ``topic`` at most ``hz`` per second of their stamps (the first of each
    period), with their stamps."""
    out: list[tuple[float, Message]] = []
    period = 1.0 / hz
    next_t = -math.inf
    for msg in _read(recording, topic):
        t = stamp_s(msg.header)
        if t + 1e-9 >= next_t:
            out.append((t, msg))
            next_t = (math.floor(t / period + 1e-6) + 1) * period
    return out


def tcp_path(recording: Path, namespace: str) -> TcpPath:
    """The TCP path of the station under ``namespace``."""
    samples = _sampled(recording, TCP_POSE.resolve(namespace), SAMPLE_HZ)
    pos = [m.pose.position for _, m in samples]
    return TcpPath(
        t=[round(t, 4) for t, _ in samples],
        x=deltas(mm(p.x) for p in pos),
        y=deltas(mm(p.y) for p in pos),
        z=deltas(mm(p.z) for p in pos),
    )


def targets(recording: Path, namespace: str) -> list[Target]:
    """Every target the controller under ``namespace`` sent (:data:`Target`)."""
    out = []
    for msg in _read(recording, PICK_TARGET.resolve(namespace)):
        g, v = msg.grasp_point, msg.velocity
        row: Target = [
            round(stamp_s(msg.header), 4),
            int(msg.track_id),
            str(msg.phase),
            str(msg.class_name),
            *(mm(c) for c in (g.x, g.y, g.z, v.x, v.y)),
        ]
        out.append(row)
    return out


def belt_positions(recording: Path, times: Sequence[float]) -> list[int]:
    """The belt's travelled distance (mm) at each frame, difference-coded."""
    states = [(stamp_s(m.header), m.position_m) for m in _read(recording, BELT_STATE.name)]
    out, j, pos = [], 0, 0.0
    for t in times:
        while j < len(states) and states[j][0] <= t + 1e-6:
            pos = states[j][1]
            j += 1
        out.append(mm(pos))
    return deltas(out)


def objects(
    states: States, source_ids: dict[int, str], meshes: MeshFinder
) -> tuple[list[ObjectData], dict[str, int]]:
    """Every object's static data, outline (1e-4 m) and track; how many outlines each source
    (``mesh``: its mesh's footprint; ``box``: its recorded extents, without the mesh)."""
    out = []
    counts = {"mesh": 0, "box": 0}
    for oid in sorted(states):
        per_frame = states[oid]
        first = per_frame[min(per_frame)]
        source = source_ids.get(oid, "")
        mesh = meshes.find(source)
        outline: Footprint | None = None
        kind = "box"
        if mesh is not None:
            try:
                outline, kind = footprint_outline(mesh).scaled_z(first.height_m), "mesh"
            except (PlayerError, OSError):
                outline = None
        if outline is None:
            outline = box_outline(first.length_m, first.width_m, first.height_m)
        counts[kind] += 1
        dims = {
            "length_m": first.length_m,
            "width_m": first.width_m,
            "height_m": first.height_m,
            "area_m2": first.area_m2,
            "volume_m3": first.volume_m3,
            "mass_kg": first.mass_kg,
        }
        out.append(
            ObjectData(
                id=oid,
                cls=str(first.class_name),
                src=source,
                outline_from=kind,
                outline=[[round(x * 1e4), round(y * 1e4)] for x, y in outline.ring],
                zspan=[round(outline.z_low_m * 1e4), round(outline.z_high_m * 1e4)],
                dims={k: round4(v) for k, v in dims.items()},
                **track(per_frame),
            )
        )
    return out, counts
