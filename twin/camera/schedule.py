"""When a camera's frame is due in the twin's step loop: integer steps, no accumulated time.

A camera at ``rate_hz`` in a twin stepping at ``physics_hz`` exposes at the first step at or
after each multiple of its period: step ``n`` is due when ``floor(n * rate_hz / physics_hz)``
grows from step ``n - 1`` (step 0 is due). 15 Hz at 240 Hz is every 16th step; a rate that does
not divide the physics rate alternates between the two nearest step counts and keeps its mean
rate exactly, over any run length.
"""

from __future__ import annotations

import math

from twin.camera.errors import RenderError

__all__ = ["frame_due"]


def frame_due(step: int, rate_hz: float, physics_hz: float) -> bool:
    """Whether step ``step`` (>= 0) takes a frame of a camera at ``rate_hz``."""
    if not (0.0 < rate_hz <= physics_hz and math.isfinite(physics_hz)):
        msg = f"rate_hz = {rate_hz!r}: must lie in (0, physics_hz = {physics_hz!r}]"
        raise RenderError(msg)
    if step < 0:
        msg = f"step = {step!r}: must be >= 0"
        raise RenderError(msg)
    if step == 0:
        return True
    ratio = rate_hz / physics_hz
    # a small tolerance so that 15 / 240 * 16 counts as exactly 1 despite rounding
    return math.floor(step * ratio + 1e-9) > math.floor((step - 1) * ratio + 1e-9)
