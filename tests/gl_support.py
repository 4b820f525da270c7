"""The OpenGL renderer's tests share one check for an EGL context."""

from __future__ import annotations

import os

import pytest

from twin.camera.errors import RenderError
from twin.camera.gl import gl_context


def require_gl() -> None:
    """Skip the calling test without an EGL context; fail instead under CI (``CI`` set),
    where ``.ci/run`` installs libegl1, libegl-mesa0 and libgl1-mesa-dri."""
    try:
        gl_context()
    except RenderError as exc:
        if os.environ.get("CI"):
            pytest.fail(f"{exc}; CI is set, so the OpenGL renderer's tests may not be skipped")
        pytest.skip(str(exc))
