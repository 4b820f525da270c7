"""Files in and out: atomic writes (a file that exists is complete), bounded text reads.

Writing goes through a temporary file in the target's folder and a rename, so a reader never
sees half a file. :func:`overwrite_in_place` is the last resort when even that fails (a full
disk): a small file that already exists is rewritten over its own blocks, to say that a run
failed. Reading a configuration or a result file goes through :func:`read_text_capped`: at
most a given number of bytes (a file that is larger is refused, naming its size), strict UTF-8
(invalid bytes are refused naming line and column) and no NUL character, so a binary file
given by mistake is one clear line instead of a traceback or a parser chewing on gigabytes.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from interfaces.errors import CdwTwinError, ConfigError

MAX_CONFIG_BYTES = 1_000_000
"""The largest YAML configuration file read (cells, scenarios, grids, controller parameters,
the catalogue): every shipped one is under 20 kB."""

MAX_JSON_BYTES = 256_000_000
"""The largest JSON result file read (``summary.json``, ``telemetry.json``, ``run.json``,
``episodes.json``, a controller's stats): a 1-hour episode's telemetry is about 40 MB."""


def _umask() -> int:
    """The process's umask, read without changing it where Linux shows it (``os.umask`` sets
    it to 0 for an instant, which other threads creating files would see)."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename.

    The file gets the permissions an ordinary ``open`` would give it (0666 minus the umask),
    not the 0600 of a temporary file.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
        Path(tmp).replace(path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def overwrite_in_place(path: Path, text: str) -> None:
    """Rewrite the existing file ``path`` with ``text`` over its own blocks (no new file).

    For a small status file on a full disk, where :func:`write_atomic` cannot create its
    temporary file: the bytes go where the old content was (no block needs allocating while
    the new text is no longer than the blocks the file holds), then the file is cut to the
    new length. Not atomic: a reader may catch it half-written, which then parses as nothing
    rather than as a complete result. Raises ``OSError`` when even this fails.
    """
    data = text.encode("utf-8")
    with path.open("r+b") as handle:
        handle.write(data)
        handle.truncate(len(data))
        handle.flush()


def read_text_capped(
    path: Path,
    *,
    max_bytes: int = MAX_CONFIG_BYTES,
    what: str = "file",
    error: type[CdwTwinError] = ConfigError,
) -> str:
    """The UTF-8 text of ``path``, refused with ``error`` naming ``path`` when it cannot be
    read, holds more than ``max_bytes`` bytes, is not UTF-8 (line and column of the first bad
    byte) or holds a NUL character (its line). A UTF-8 byte order mark is dropped."""
    try:
        with path.open("rb") as handle:
            data = handle.read(max_bytes + 1)
    except OSError as exc:
        msg = f"{path}: cannot read {what}: {exc.strerror or exc}"
        raise error(msg) from None
    if len(data) > max_bytes:
        msg = f"{path}: {what} larger than {max_bytes} bytes: refused (not a {what}?)"
        raise error(msg)
    data = data.removeprefix(b"\xef\xbb\xbf")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        byte = data[exc.start : exc.start + 1].hex()
        msg = f"{path}:{line}:{column}: {what} is not UTF-8 text (byte 0x{byte})"
        raise error(msg) from None
    nul = text.find("\0")
    if nul >= 0:
        line = text.count("\n", 0, nul) + 1
        column = nul - (text.rfind("\n", 0, nul) + 1) + 1
        msg = f"{path}:{line}:{column}: {what} holds a NUL character (not a text file?)"
        raise error(msg)
    return text
