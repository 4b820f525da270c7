"""Whether a station could take a piece is the scheduler's own static rule: what
:func:`control.fit.takeable` refuses, the scheduler leaves untargeted for the same reason, and
a line refuses a piece only when every station does."""

from __future__ import annotations

import math

import pytest

from control.config import PARAMS_DIR, ControllerConfig, station_configs
from control.fit import REFUSALS, Piece, line_refusal, piece_track, takeable
from control.scheduler import schedule, static_reason
from interfaces.cell import load_cell
from interfaces.untargeted import STATIC_REASONS

PIECES = (
    Piece(class_name="brick", length_m=0.10, width_m=0.05, height_m=0.04),
    Piece(class_name="brick", length_m=0.16, width_m=0.14, height_m=0.04),  # wide
    Piece(class_name="rubber", length_m=0.10, width_m=0.05, height_m=0.01),  # flat
    Piece(class_name="wood", length_m=0.08, width_m=0.03, height_m=0.03, face_radius_m=0.015),
    Piece(class_name="glass", length_m=0.10, width_m=0.05, height_m=0.04),  # no bin
    Piece(class_name="concrete", length_m=0.12, width_m=0.12, height_m=0.10, face_radius_m=0.06),
    Piece(class_name="wood", length_m=0.1, width_m=0.08, height_m=0.04, face_radius_m=0.04,
          face_tilt_rad=0.5),  # propped
)  # fmt: skip


@pytest.fixture(scope="module")
def line() -> tuple[ControllerConfig, ...]:
    """Every station of the shipped line with its shipped parameter file."""
    return station_configs(PARAMS_DIR / "line.yaml", load_cell("line"))


def test_the_judgement_is_the_schedulers_first_checks(line: tuple[ControllerConfig, ...]) -> None:
    """For every piece and every station of the line, :func:`takeable` is the reason the
    scheduler gives a certain track standing for it (or it schedules it past its static
    checks)."""
    assert REFUSALS == STATIC_REASONS
    seen: set[str | None] = set()
    for config in line:
        for piece in PIECES:
            reason = takeable(piece, config)
            assert reason == static_reason(piece_track(piece), config)
            seen.add(reason)
            far = piece_track(piece)
            result = schedule([far], now_s=0.0, tcp_position_m=(0.0, 0.0, 0.5), config=config)
            if reason is not None:
                assert [u.reason for u in result.untargeted] == [reason]
            else:
                assert all(u.reason not in STATIC_REASONS for u in result.untargeted)
    assert {"no_bin", "too_small", "too_tilted", "too_heavy", "too_wide", "too_flat"} <= seen


def test_a_line_refuses_only_what_every_station_refuses(line: tuple[ControllerConfig, ...]) -> None:
    configs = list(line)
    cups = [c for c in configs if c.station.tool.kind == "suction_cup"]
    jaws = [c for c in configs if c.station.tool.kind == "parallel_jaw"]
    narrow = PIECES[3]  # 3 cm wide, a 15 mm disc: too small for every cup, fine for the jaws
    assert line_refusal(narrow, cups) == "too_small"
    assert line_refusal(narrow, configs) is None
    flat_narrow = Piece(class_name="rubber", length_m=0.05, width_m=0.03, height_m=0.01)
    assert line_refusal(flat_narrow, configs) == "too_flat+too_small"  # REFUSALS order
    assert line_refusal(PIECES[4], configs) == "no_bin"
    assert takeable(PIECES[0], jaws[0]) is None
    assert math.isnan(PIECES[0].face_radius_m)  # no disc reported: the narrow side judged
