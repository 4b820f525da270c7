"""Errors about FMUs: building ours, loading or stepping any."""

from __future__ import annotations

from interfaces.errors import CdwTwinError


class FmuError(CdwTwinError):
    """An FMU is missing, malformed, or rejected a call."""


class FmuBuildError(FmuError):
    """The C compiler or the packaging of an FMU failed."""
