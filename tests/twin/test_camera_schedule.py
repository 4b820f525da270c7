"""A camera's frames come at its rate, from integer steps."""

from __future__ import annotations

import itertools

import pytest

from twin.camera.errors import RenderError
from twin.camera.schedule import frame_due


def test_fifteen_hertz_at_240_hertz_is_every_sixteenth_step() -> None:
    due = [step for step in range(241) if frame_due(step, 15.0, 240.0)]
    assert due == list(range(0, 241, 16))


@pytest.mark.parametrize("rate_hz", [7.0, 25.0, 30.0, 100.0, 240.0])
def test_any_rate_keeps_its_mean_and_spacing(rate_hz: float) -> None:
    steps = 2400  # 10 s at 240 Hz
    due = [step for step in range(steps) if frame_due(step, rate_hz, 240.0)]
    assert len(due) == pytest.approx(rate_hz * 10.0, abs=1)
    gaps = {b - a for a, b in itertools.pairwise(due)}
    period = 240.0 / rate_hz
    assert gaps <= {int(period), int(period) + 1}


def test_a_rate_above_the_physics_rate_is_refused() -> None:
    with pytest.raises(RenderError, match="rate_hz = 300"):
        frame_due(1, 300.0, 240.0)
