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
