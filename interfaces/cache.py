"""Where cached, regenerable data lives: the built-in dataset, merged collision shapes and the
URDFs the stations load.

``$CDW_TWIN_CACHE``, else ``$XDG_CACHE_HOME/cdw-twin``, else ``~/.cache/cdw-twin``; deleting it
only costs the time to regenerate.
"""

from __future__ import annotations

import os
from pathlib import Path


def cache_root() -> Path:
    """The cache folder (not created here)."""
    env = os.environ.get("CDW_TWIN_CACHE")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "cdw-twin"
