"""Output files: CSV and JSON text, materials, and the writers that put them in the staging folder.

The staging folder, its swap into place and the rules on what may be replaced live in
:mod:`meshgen.outdir`. Every file is created with mode ``0o666`` minus the umask, like an
ordinary ``open``.
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import threading
from pathlib import Path
from typing import Any

from interfaces.scene_csv import INDEX_COLUMNS, SCENE_COLUMNS
from meshgen.classes import ClassSpec
from meshgen.errors import DatasetError

OUTPUT_VERSION = 3
"""Version of what a meshgen output folder holds; caches of meshed data key on it. 2: each
image's ``texture.jpg``, texture coordinates in the meshes, scene.csv columns ``texture_path``
and ``height_source``; 3: ``classes.yaml``, the class table the output was meshed with."""


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


FILE_MODE = 0o666
"""Mode of every file meshgen writes, before the umask (what ``open`` gives)."""
_WRITE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0)


def write_text(path: Path | str, text: str | bytes) -> None:
    """Write ``text`` to ``path`` (UTF-8, ``\\n`` line ends) with one ``os.write`` of one buffer.

    ``bytes`` are written as they are (a texture image). Files are written in place: atomicity
    is per output folder (see :func:`meshgen.outdir.swap_in`), so the files inside a staging
    folder need no temporary name each. The mode is :data:`FILE_MODE` minus the umask.
    """
    data = text if isinstance(text, bytes) else text.encode("utf-8")
    fd = os.open(path, _WRITE_FLAGS, FILE_MODE)
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

    def write(self, path: str, text: str | bytes) -> None:
        """Write ``text`` (or ``bytes`` as they are) to ``path``."""
        write_text(path, text)

    def copy(self, source: Path, path: str) -> None:
        """Copy the file ``source`` to ``path`` as it is (the kernel copies the bytes).

        A source that can no longer be read (removed since it was checked) raises
        :class:`~meshgen.errors.DatasetError` naming it.
        """
        try:
            shutil.copyfile(source, path)
        except OSError as exc:
            if exc.filename is not None and str(exc.filename) == str(source):
                msg = f"{source}: cannot read the photo any more: {exc.strerror}"
                raise DatasetError(msg) from None
            raise

    def close(self) -> None:
        """Finish all pending work (nothing to do here)."""

    def cancel(self) -> None:
        """Drop the work still pending and wait until none is under way (nothing to do here)."""


class ThreadedFileSink(FileSink):
    """A :class:`FileSink` that hands the work to one helper thread of the same process.

    Creating a file is kernel work that releases the GIL, so the next objects are computed
    while earlier files are created. Work is done strictly in call order; :meth:`close` waits
    for it and re-raises the first error (later work is dropped once one failed).
    """

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue[tuple[str, str, str | bytes | Path] | None] = (
            queue.SimpleQueue()
        )
        self._error: BaseException | None = None
        self._cancelled = False
        self._thread = threading.Thread(target=self._run, name="meshgen-writer", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while (item := self._queue.get()) is not None:
            if self._error is not None or self._cancelled:
                continue
            kind, path, payload = item
            try:
                if kind == "mkdir":
                    FileSink.mkdir(self, path)
                elif isinstance(payload, Path):
                    FileSink.copy(self, payload, path)
                else:
                    write_text(path, payload)
            except BaseException as exc:
                self._error = exc

    def mkdir(self, path: str) -> None:
        """Queue the creation of folder ``path``."""
        self._queue.put(("mkdir", path, ""))

    def write(self, path: str, text: str | bytes) -> None:
        """Queue writing ``text`` (or ``bytes``) to ``path``."""
        self._queue.put(("write", path, text))

    def copy(self, source: Path, path: str) -> None:
        """Queue copying the file ``source`` to ``path``."""
        self._queue.put(("copy", path, source))

    def close(self) -> None:
        """Wait until everything queued is done; raise the first error, if any."""
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def cancel(self) -> None:
        """Drop the work still queued and wait for the thread to end; errors are dropped too.

        Safe to call after :meth:`close` or after a :meth:`close` cut short by an interrupt.
        """
        self._cancelled = True
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        self._error = None


def write_json(path: Path, data: Any) -> None:
    """Write ``data`` as compact JSON with sorted keys (byte-stable for equal data)."""
    write_text(path, json.dumps(data, sort_keys=True, separators=(",", ":")) + "\n")


def mtl_text(classes: tuple[ClassSpec, ...]) -> str:
    """MTL text with one diffuse material per class, named after the class."""
    blocks = ["# cdw-twin meshgen class materials"]
    for spec in classes:
        r, g, b = spec.colour
        blocks.append(
            f"newmtl {spec.name}\nKa 0.000000 0.000000 0.000000\n"
            f"Kd {r:.6f} {g:.6f} {b:.6f}\nKs 0.000000 0.000000 0.000000\nd 1.0\nillum 1"
        )
    return "\n\n".join(blocks) + "\n"


__all__ = [
    "FILE_MODE",
    "INDEX_COLUMNS",
    "OUTPUT_VERSION",
    "SCENE_COLUMNS",
    "FileSink",
    "ThreadedFileSink",
    "csv_field",
    "csv_text",
    "mtl_text",
    "write_json",
    "write_text",
]
"""``SCENE_COLUMNS`` and ``INDEX_COLUMNS`` are :mod:`interfaces.scene_csv`'s (the twin reads them
there), re-exported for meshgen's modules."""
