"""Errors raised while building the FMUs."""

from __future__ import annotations

from twin.errors import FmuError


class FmuBuildError(FmuError):
    """The C compiler or the packaging of an FMU failed."""
