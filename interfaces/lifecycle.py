"""Child processes that die with the runner that started them.

``cdw-twin run`` and ``sweep`` start the twin node and the controllers with
:data:`PARENT_PID_VARIABLE` naming the runner; each child calls :func:`die_with_parent` first,
so no twin or controller outlives a runner that was killed, however it was killed.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
from types import FrameType

PARENT_PID_VARIABLE = "CDW_TWIN_PARENT_PID"
"""Environment variable naming the process a child must not outlive (set by the runner)."""

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
"""Signals that end an episode or a node early (its files written, exit status 130)."""

_PR_SET_PDEATHSIG = 1


def die_with_parent(variable: str = PARENT_PID_VARIABLE) -> None:
    """Get SIGTERM when the process named by ``variable`` (our parent) dies (Linux only).

    ``prctl(PR_SET_PDEATHSIG)`` asks the kernel to send the signal when the parent thread that
    started us exits, however it exits (``kill -9`` included). The parent may have died before
    the call: then our parent id is no longer the one named, and we send ourselves the
    signal. The variable is removed so that processes we start do not inherit it. Does nothing
    when the variable is not set (a node started by hand).
    """
    value = os.environ.pop(variable, None)
    if value is None or not sys.platform.startswith("linux"):
        return
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
        errno = ctypes.get_errno()
        msg = f"prctl(PR_SET_PDEATHSIG) failed: {os.strerror(errno)}"
        raise OSError(errno, msg)
    if os.getppid() != int(value):
        os.kill(os.getpid(), signal.SIGTERM)


class StopRequests:
    """SIGINT and SIGTERM recorded instead of raised, from construction until :meth:`restore`:
    a node's spin loop (``while not stop:``) ends at its next turn and still writes its files.
    True once a stop signal arrived; :attr:`signals` lists them in order."""

    def __init__(self) -> None:
        self.signals: list[int] = []
        self._previous = {sig: signal.signal(sig, self._record) for sig in STOP_SIGNALS}

    def _record(self, signum: int, frame: FrameType | None) -> None:
        del frame
        self.signals.append(signum)

    def __bool__(self) -> bool:
        return bool(self.signals)

    def restore(self) -> None:
        """Put back the handlers that were in place before."""
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
