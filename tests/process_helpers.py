"""Start and finish the real processes a test runs (twin nodes, scripted peers)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Sequence


def start(env: dict[str, str], *args: str) -> subprocess.Popen[bytes]:
    """``python ARGS`` in ``env``: stdout discarded, stderr kept for the failure message."""
    return subprocess.Popen(
        [sys.executable, *args], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )


def start_twin_node(env: dict[str, str], args: Sequence[str]) -> subprocess.Popen[bytes]:
    """``cdw-twin twin-node ARGS`` in ``env``."""
    return start(env, "-m", "twin.cli", "twin-node", *args)


def finish(proc: subprocess.Popen[bytes], timeout_s: float) -> int:
    """Wait for ``proc`` and return its exit code; killed (and the timeout raised) when it
    outlives ``timeout_s``."""
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    return proc.returncode
