"""Errors of the camera's renderers (:mod:`twin.camera`)."""

from __future__ import annotations

from interfaces.errors import CdwTwinError


class RenderError(CdwTwinError):
    """A renderer cannot start or draw (no OpenGL context, an unknown mesh or texture key, a
    malformed mesh or image); the message names the key, file or value that was wrong."""


__all__ = ["RenderError"]
