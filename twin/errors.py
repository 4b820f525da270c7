"""Errors raised by the twin package.

The base error and :class:`ConfigError` live in :mod:`interfaces.errors` (every package may
import it), the FMU errors in :mod:`fmus.errors`; they are re-exported here for the twin's
modules.
"""

from __future__ import annotations

from fmus.errors import FmuError
from interfaces.errors import CdwTwinError, ConfigError


class SceneError(CdwTwinError):
    """A scene input (scene CSV, mesh, URDF) is missing or malformed."""


__all__ = ["CdwTwinError", "ConfigError", "FmuError", "SceneError"]
