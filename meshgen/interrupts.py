"""Interrupts of a run (Ctrl-C, SIGTERM): when they may cut in, and when they must wait.

Python raises ``KeyboardInterrupt`` wherever the main thread happens to be when SIGINT arrives.
Most of a run can be cut anywhere (its files are only in the hidden staging folder), but two
steps must run to their end: the renames that swap a finished output in, and the clean-up after
an interrupt (waiting for the writer thread and the worker processes, then removing the staging
folder). Those run inside :func:`deferred_interrupts`. ``cdw-twin meshgen`` turns SIGTERM into
the same ``KeyboardInterrupt`` (:func:`terminate_as_interrupt`), and worker processes ignore both
signals (:func:`ignore_interrupts`): the main process stops them in order.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

INTERRUPT_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM)
"""The signals a run treats as a request to stop."""

_Handler = Callable[[int, FrameType | None], Any] | int | None


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def _restore(previous: dict[signal.Signals, _Handler]) -> None:
    for sig, handler in previous.items():
        signal.signal(sig, signal.SIG_DFL if handler is None else handler)


@contextmanager
def deferred_interrupts(*, redeliver: bool = True) -> Iterator[None]:
    """Hold SIGINT and SIGTERM until the block is done, then raise the first one again.

    With ``redeliver=False`` signals that arrive during the block are dropped (used while
    stopping after an interrupt: the run is ending anyway). Outside the main thread (where
    Python cannot install handlers) the block runs unprotected.
    """
    if not _in_main_thread():
        yield
        return
    pending: list[int] = []

    def hold(signum: int, frame: FrameType | None) -> None:
        pending.append(signum)

    previous: dict[signal.Signals, _Handler] = {
        sig: signal.signal(sig, hold) for sig in INTERRUPT_SIGNALS
    }
    try:
        yield
    finally:
        _restore(previous)
        if pending and redeliver:
            signal.raise_signal(pending[0])


def _raise_interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


@contextmanager
def terminate_as_interrupt() -> Iterator[None]:
    """Within the block SIGTERM raises ``KeyboardInterrupt``, like Ctrl-C (main thread only)."""
    if not _in_main_thread():
        yield
        return
    previous: dict[signal.Signals, _Handler] = {
        signal.SIGTERM: signal.signal(signal.SIGTERM, _raise_interrupt)
    }
    try:
        yield
    finally:
        _restore(previous)


def ignore_interrupts() -> None:
    """Make this process ignore SIGINT and SIGTERM (initializer of the worker processes)."""
    for sig in INTERRUPT_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)
