"""The output folder: where a run may write, the marker naming meshgen's own output, the swap.

A run is built in a hidden staging folder next to ``OUT`` (``.OUT.staging-<pid>``) and swapped
in with ``os.replace`` only when complete, so a half-written output never looks finished and a
rerun replaces the old one whole. Because the swap replaces ``OUT`` entirely, meshgen refuses,
before doing any work:

- an ``OUT`` that is the dataset folder, lies inside it or contains it (resolved paths);
- an existing ``OUT`` that is not a folder;
- an existing non-empty folder without the marker file :data:`MARKER_NAME` (first line
  :data:`MARKER_SIGNATURE`). Other files (an ``index.csv``, a ``summary.json``) never make a
  folder replaceable. An empty folder is fine.

The marker is written into the staging folder last, just before the swap, so an ``OUT`` holds
it exactly when it is a complete meshgen output. A place that cannot hold the output (a path
under a regular file, under ``/proc``, in a read-only folder) is reported as an
:class:`~meshgen.errors.OutputError` naming ``OUT``.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from meshgen.errors import OutputError
from meshgen.export import write_text

MARKER_NAME = ".cdw-meshgen"
"""File in every complete meshgen output folder; only folders holding it are ever replaced."""
MARKER_SIGNATURE = "cdw-twin meshgen output"
"""First line of the marker file."""
MARKER_VERSION = 1
"""Version of the output layout the marker stands for."""


def marker_text() -> str:
    """Content of the marker file: what wrote the folder, the layout version, what it means."""
    return (
        f"{MARKER_SIGNATURE}\n"
        f"marker_version {MARKER_VERSION}\n"
        "written by `cdw-twin meshgen`; a later run with --out here replaces this whole folder\n"
    )


def is_meshgen_output(folder: Path) -> bool:
    """True when ``folder`` holds a marker file whose first line is :data:`MARKER_SIGNATURE`."""
    try:
        with (folder / MARKER_NAME).open("rb") as handle:
            first = handle.readline(256)
    except OSError:
        return False
    return first.rstrip(b"\r\n") == MARKER_SIGNATURE.encode()


def _reason(exc: OSError) -> str:
    """``strerror`` and the file an ``OSError`` names, on one line."""
    text = exc.strerror or str(exc)
    return f"{text} ({exc.filename})" if exc.filename else text


def output_error(out: Path, exc: OSError, doing: str) -> OutputError:
    """An :class:`OutputError` for an ``OSError`` met while ``doing`` something to ``out``."""
    return OutputError(f"{out}: cannot {doing}: {_reason(exc)}")


def check_location(dataset: Path, out: Path) -> None:
    """Raise :class:`OutputError` when ``out`` is ``dataset``, inside it or contains it."""
    data, target = Path(dataset).resolve(), Path(out).resolve()
    if target == data:
        msg = f"--out {out} is the dataset folder itself: meshgen would replace its input"
        raise OutputError(msg)
    if target.is_relative_to(data):
        msg = f"--out {out} lies inside the dataset folder {dataset}: choose a folder outside it"
        raise OutputError(msg)
    if data.is_relative_to(target):
        msg = (
            f"--out {out} contains the dataset folder {dataset}: "
            "meshgen would replace its input with its output"
        )
        raise OutputError(msg)


def check_replaceable(out: Path) -> None:
    """Raise :class:`OutputError` when ``out`` exists and is not empty or an earlier output."""
    try:
        if not out.exists():
            return
        if not out.is_dir():
            msg = f"{out}: output path exists and is not a folder"
            raise OutputError(msg)
        if any(out.iterdir()) and not is_meshgen_output(out):
            msg = (
                f"{out}: refusing to replace a non-empty folder that is not a meshgen output "
                f"(it has no {MARKER_NAME} marker file); remove it or choose another --out"
            )
            raise OutputError(msg)
    except OSError as exc:
        raise output_error(out, exc, "read the output folder") from exc


def staging_path(out: Path) -> Path:
    """Where this process builds the output for ``out``: a hidden folder next to it."""
    out = out.resolve()
    return out.parent / f".{out.name}.staging-{os.getpid()}"


def staging_dir(out: Path) -> Path:
    """Create and return the empty :func:`staging_path` of ``out`` (its parents created too)."""
    out = out.resolve()
    staging = staging_path(out)
    for folder in out.parents:
        if folder.exists():
            if not folder.is_dir():
                msg = f"{out}: cannot create the output folder: {folder} is not a folder"
                raise OutputError(msg)
            break
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        if staging.exists():
            shutil.rmtree(staging)
        staging.mkdir()
    except OSError as exc:
        raise output_error(out, exc, "create the output folder") from exc
    return staging


def swap_in(staging: Path, out: Path) -> None:
    """Write the marker into the finished ``staging`` folder and put it in place of ``out``.

    An earlier output at ``out`` is moved aside first and removed afterwards; if the second
    rename fails, it is moved back. Run it inside
    :func:`meshgen.interrupts.deferred_interrupts` so that an interrupt cannot fall between
    the two renames.
    """
    out = out.resolve()
    check_replaceable(out)
    old = out.parent / f".{out.name}.old-{os.getpid()}"
    try:
        write_text(staging / MARKER_NAME, marker_text())
        if out.exists():
            os.replace(out, old)
        try:
            os.replace(staging, out)
        except OSError:
            if old.exists():
                os.replace(old, out)
            raise
    except OSError as exc:
        raise output_error(out, exc, "put the finished output in place") from exc
    if old.exists():
        shutil.rmtree(old, ignore_errors=True)
