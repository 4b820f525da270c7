"""Which renderer the camera uses: OpenGL (EGL, Mesa) when the machine has it, else
PyBullet's TinyRenderer, said once per process in one line on stderr."""

from __future__ import annotations

import logging
from typing import Literal

from twin.camera.errors import RenderError
from twin.camera.gl import gl_context

__all__ = ["RENDERERS", "Renderer", "choose_renderer"]

Renderer = Literal["gl", "tiny"]
RENDERERS = ("auto", "gl", "tiny")
"""What a caller may ask for: ``auto`` (OpenGL if a context can be created, else tiny)."""

FAST_PATH_PACKAGES = "libegl1 libegl-mesa0 libgl1-mesa-dri"
"""The Debian packages the OpenGL renderer needs (``.ci/run`` installs them)."""

_log = logging.getLogger("twin.camera")
_said = False


def choose_renderer(preference: str = "auto") -> Renderer:
    """``gl`` or ``tiny`` for a preference of :data:`RENDERERS`.

    ``gl`` raises :class:`RenderError` when no OpenGL context can be created; ``auto`` then
    falls back to ``tiny`` and logs one warning line saying why (once per process; the
    logging module's last-resort handler prints it on stderr when the application configured
    no logging).
    """
    global _said  # noqa: PLW0603 (said once per process, by design)
    if preference not in RENDERERS:
        msg = f"renderer = {preference!r}: must be one of {', '.join(RENDERERS)}"
        raise RenderError(msg)
    if preference == "tiny":
        return "tiny"
    if preference == "gl":
        gl_context()
        return "gl"
    try:
        gl_context()
    except RenderError as exc:
        if not _said:
            reason = str(exc).splitlines()[0] if str(exc) else "unknown"
            _log.warning(
                "cdw-twin camera: %s; rendering with PyBullet's TinyRenderer (slower, no photo "
                "textures); install %s for the fast renderer",
                reason,
                FAST_PATH_PACKAGES,
            )
            _said = True
        return "tiny"
    return "gl"
