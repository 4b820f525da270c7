"""The ``--out`` folder of ``run``, ``sweep`` and ``report``: refused, replaced whole, or new.

A run's output must never mix with another's: ``cdw-twin run --out X`` over an earlier run
would overwrite ``ep000`` and keep a stale ``ep001`` beside a ``run.json`` that says
``complete: true``. So each command refuses, before it writes anything, an ``--out`` that:

- exists and is not a folder;
- is a non-empty folder, unless told to replace it (``--replace``), and then only when the
  folder holds the marker file of the same command's output (:class:`OutputKind`: ``.cdw-run``,
  ``.cdw-sweep``, ``.cdw-report``, first line its signature). A folder without the marker
  (an output written before the markers existed, or anything else) is never replaced: delete
  it by hand once;
- cannot be created (under a file, on a read-only file system, under ``/proc``).

A run or a sweep writes its folder as it goes (finished episodes are kept when it is stopped),
so :func:`fresh_output` puts the new folder in place at the start: the old one is moved aside,
the new one created with its marker, the old one deleted. A report is built in a hidden staging
folder next to ``--out`` (:func:`staging_folder`) and swapped in whole when finished
(:func:`swap_in`), so an interrupted report leaves the old one as it was, never a mix.

Example::

    out = fresh_output(Path("runs/a"), RUN, replace=args.replace)
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

from interfaces.errors import CdwTwinError
from interfaces.fileio import write_atomic


class OutputError(CdwTwinError):
    """``--out`` cannot be used: it exists and may not be replaced, or cannot be written."""


@dataclass(frozen=True)
class OutputKind:
    """What a command writes into its ``--out``: the ``command`` (for messages), the marker
    file's name and the signature its first line carries."""

    command: str
    marker: str

    @property
    def signature(self) -> str:
        """First line of the marker file."""
        return f"cdw-twin {self.command} output"

    def marker_text(self) -> str:
        """The marker file's content: what wrote the folder and what the marker means."""
        return (
            f"{self.signature}\n"
            f"written by `cdw-twin {self.command}`; `cdw-twin {self.command} --out <this "
            "folder> --replace` replaces the whole folder\n"
        )


RUN = OutputKind("run", ".cdw-run")
"""A run folder (``cdw-twin run``)."""

SWEEP = OutputKind("sweep", ".cdw-sweep")
"""A sweep folder (``cdw-twin sweep``)."""

REPORT = OutputKind("report", ".cdw-report")
"""A report folder (``cdw-twin report``)."""


def holds_marker(folder: Path, kind: OutputKind) -> bool:
    """Whether ``folder`` holds ``kind``'s marker file (its first line the signature)."""
    try:
        with (folder / kind.marker).open("rb") as handle:
            first = handle.readline(256)
    except OSError:
        return False
    return first.rstrip(b"\r\n") == kind.signature.encode()


def reason(exc: OSError) -> str:
    """An ``OSError`` in words: its ``strerror`` and the file it names."""
    text = exc.strerror or str(exc)
    return f"{text} ({exc.filename})" if exc.filename else text


def check_output(out: Path, kind: OutputKind, *, replace: bool) -> None:
    """Raise :class:`OutputError` naming ``out`` when the command may not write there (see the
    module's docstring); nothing is written."""
    try:
        if out.exists() and not out.is_dir():
            msg = f"--out {out}: exists and is not a folder; choose another --out"
            raise OutputError(msg)
        if not out.exists() or not any(out.iterdir()):
            return
    except OSError as exc:
        msg = f"--out {out}: cannot read it: {reason(exc)}"
        raise OutputError(msg) from None
    if not replace:
        msg = (
            f"--out {out}: exists and is not empty; choose another --out, or pass --replace "
            f"to replace it whole (only a folder `cdw-twin {kind.command}` wrote)"
        )
        raise OutputError(msg)
    if not holds_marker(out, kind):
        msg = (
            f"--out {out}: refusing to replace a folder that is not a `cdw-twin {kind.command}` "
            f"output (it has no {kind.marker} marker file); delete it by hand or choose "
            "another --out"
        )
        raise OutputError(msg)


def _check_parent(out: Path) -> None:
    """Raise :class:`OutputError` when a folder above ``out`` exists and is not a folder."""
    for folder in out.parents:
        if folder.exists():
            if not folder.is_dir():
                msg = f"--out {out}: cannot create it: {folder} is not a folder"
                raise OutputError(msg)
            return


def _aside(out: Path) -> Path:
    return out.parent / f".{out.name}.old-{os.getpid()}"


def fresh_output(out: Path, kind: OutputKind, *, replace: bool) -> Path:
    """Make ``out`` an empty folder holding ``kind``'s marker, after :func:`check_output`: an
    earlier output of the same command is moved aside and deleted (``replace``). Returns
    ``out``. :class:`OutputError` names ``out`` and the reason when it cannot be written."""
    check_output(out, kind, replace=replace)
    _check_parent(out)
    old: Path | None = None
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        if out.exists() and any(out.iterdir()):
            old = _aside(out)
            if old.exists():
                shutil.rmtree(old)
            os.replace(out, old)
        out.mkdir(exist_ok=True)
        write_atomic(out / kind.marker, kind.marker_text())
    except OSError as exc:
        if old is not None and old.exists() and not out.exists():
            os.replace(old, out)
        msg = f"--out {out}: cannot create the output folder: {reason(exc)}"
        raise OutputError(msg) from None
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return out


def staging_folder(out: Path, kind: OutputKind, *, replace: bool) -> Path:
    """An empty hidden folder next to ``out`` to build the output in, after
    :func:`check_output` (then :func:`swap_in`, or :func:`discard` on failure)."""
    check_output(out, kind, replace=replace)
    _check_parent(out)
    staging = out.parent / f".{out.name}.staging-{os.getpid()}"
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        if staging.exists():
            shutil.rmtree(staging)
        staging.mkdir()
    except OSError as exc:
        msg = f"--out {out}: cannot create the output folder: {reason(exc)}"
        raise OutputError(msg) from None
    return staging


def swap_in(staging: Path, out: Path, kind: OutputKind, *, replace: bool) -> None:
    """Write the marker into the finished ``staging`` folder and put it in place of ``out``
    (an earlier output moved aside first and deleted after; moved back if the second rename
    fails). The checks of :func:`check_output` are made again: another process may have
    written ``out`` meanwhile."""
    check_output(out, kind, replace=replace)
    old = _aside(out)
    try:
        write_atomic(staging / kind.marker, kind.marker_text())
        if out.exists():
            if old.exists():
                shutil.rmtree(old)
            os.replace(out, old)
        try:
            os.replace(staging, out)
        except OSError:
            if old.exists() and not out.exists():
                os.replace(old, out)
            raise
    except OSError as exc:
        msg = f"--out {out}: cannot put the finished output in place: {reason(exc)}"
        raise OutputError(msg) from None
    if old.exists():
        shutil.rmtree(old, ignore_errors=True)


def discard(staging: Path) -> None:
    """Delete an unfinished staging folder (whatever it holds)."""
    shutil.rmtree(staging, ignore_errors=True)


__all__ = [
    "REPORT",
    "RUN",
    "SWEEP",
    "OutputError",
    "OutputKind",
    "check_output",
    "discard",
    "fresh_output",
    "holds_marker",
    "reason",
    "staging_folder",
    "swap_in",
]
