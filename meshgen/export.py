"""Output files: scene CSV/JSON rows, materials, index, and the atomic swap of the output folder.

A run is built in a staging folder next to ``OUT`` and swapped in with ``os.replace`` only when
complete, so a half-written output never looks finished and a rerun replaces the old one whole.
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import threading
from pathlib import Path
from typing import Any

from meshgen.classes import ClassSpec
from meshgen.errors import OutputError

SCENE_COLUMNS: tuple[str, ...] = (
    "object_id",
    "source_image",
    "class_id",
    "class_name",
    "centroid_x_m",
    "centroid_y_m",
    "yaw_rad",
    "length_m",
    "width_m",
    "area_m2",
    "height_m",
    "volume_m3",
    "mass_kg",
    "mesh_path",
    "convex_path",
    "n_convex_pieces",
    "area_change_ratio",
    "repairs",
)
"""Columns of ``<image_stem>/scene.csv``, in order."""

INDEX_COLUMNS: tuple[str, ...] = (
    "image",
    "width_px",
    "height_px",
    "m_per_px",
    "objects",
    "skipped",
    "scene_csv",
)
"""Columns of ``index.csv``, in order."""

MARKERS: tuple[str, ...] = ("summary.json", "index.csv")


def csv_field(value: object) -> str:
    """Format one CSV value: floats with 9 significant digits, text quoted when needed."""
    if isinstance(value, float):
        return f"{value:.9g}"
    text = str(value)
    if any(c in text for c in ',"\n'):
        return '"' + text.replace('"', '""') + '"'
    return text


def csv_text(columns: tuple[str, ...], rows: list[tuple[object, ...]]) -> str:
    """A CSV document with a header line and ``\\n`` line ends."""
    lines = [",".join(columns)]
    lines.extend(",".join(csv_field(v) for v in row) for row in rows)
    return "\n".join(lines) + "\n"


_WRITE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0)


def write_text(path: Path | str, text: str) -> None:
    """Write ``text`` to ``path`` (UTF-8, ``\\n`` line ends) with one ``os.write`` of one buffer.

    Files are written in place: atomicity is per output folder (see :func:`swap_in`), so the
    files inside a staging folder need no temporary name each.
    """
    data = text.encode("utf-8")
    fd = os.open(path, _WRITE_FLAGS, 0o644)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
    finally:
        os.close(fd)


class FileSink:
    """Creates folders and writes files, in call order, right away (see :func:`write_text`)."""

    def mkdir(self, path: str) -> None:
        """Create folder ``path`` (fine when it already exists as a folder)."""
        try:
            os.mkdir(path)
        except FileExistsError:
            if not os.path.isdir(path):
                raise

    def write(self, path: str, text: str) -> None:
        """Write ``text`` to ``path``."""
        write_text(path, text)

    def close(self) -> None:
        """Finish all pending work (nothing to do here)."""


class ThreadedFileSink(FileSink):
    """A :class:`FileSink` that hands the work to one helper thread of the same process.

    Creating a file is kernel work that releases the GIL, so the next objects are computed
    while earlier files are created. Work is done strictly in call order; :meth:`close` waits
    for it and re-raises the first error (later work is dropped once one failed).
    """

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue[tuple[bool, str, str] | None] = queue.SimpleQueue()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="meshgen-writer", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while (item := self._queue.get()) is not None:
            if self._error is not None:
                continue
            is_dir, path, text = item
            try:
                if is_dir:
                    FileSink.mkdir(self, path)
                else:
                    write_text(path, text)
            except BaseException as exc:
                self._error = exc

    def mkdir(self, path: str) -> None:
        """Queue the creation of folder ``path``."""
        self._queue.put((True, path, ""))

    def write(self, path: str, text: str) -> None:
        """Queue writing ``text`` to ``path``."""
        self._queue.put((False, path, text))

    def close(self) -> None:
        """Wait until everything queued is done; raise the first error, if any."""
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        if self._error is not None:
            error, self._error = self._error, None
            raise error


def write_json(path: Path, data: Any) -> None:
    """Write ``data`` as compact JSON with sorted keys (byte-stable for equal data)."""
    write_text(path, json.dumps(data, sort_keys=True, separators=(",", ":")) + "\n")


def mtl_text(classes: tuple[ClassSpec, ...]) -> str:
    """MTL text with one diffuse material per class, named after the class."""
    blocks = ["# cdw-twin meshgen class materials"]
    for spec in classes:
        r, g, b = spec.rgb
        blocks.append(
            f"newmtl {spec.name}\nKa 0.000000 0.000000 0.000000\n"
            f"Kd {r:.6f} {g:.6f} {b:.6f}\nKs 0.000000 0.000000 0.000000\nd 1.0\nillum 1"
        )
    return "\n\n".join(blocks) + "\n"


def staging_dir(out: Path) -> Path:
    """Create and return an empty staging folder next to ``out``."""
    out = out.resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = out.parent / f".{out.name}.staging-{os.getpid()}"
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir()
    return staging


def check_replaceable(out: Path) -> None:
    """Raise :class:`OutputError` when ``out`` exists and is not an earlier meshgen output."""
    if not out.exists():
        return
    if not out.is_dir():
        msg = f"{out}: output path exists and is not a folder"
        raise OutputError(msg)
    if any(out.iterdir()) and not any((out / m).is_file() for m in MARKERS):
        msg = f"{out}: refusing to replace a non-empty folder that is not a meshgen output"
        raise OutputError(msg)


def swap_in(staging: Path, out: Path) -> None:
    """Replace ``out`` by the finished ``staging`` folder (old output removed afterwards)."""
    out = out.resolve()
    check_replaceable(out)
    old = out.parent / f".{out.name}.old-{os.getpid()}"
    if out.exists():
        os.replace(out, old)
    os.replace(staging, out)
    if old.exists():
        shutil.rmtree(old, ignore_errors=True)
