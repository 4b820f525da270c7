"""The claims board checks every field of a claim, takes a claim only on its own station's
topic, and stays bounded per station and in total (pure logic, no ROS)."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import pytest

from interfaces.cell import load_cell
from twin.claims import ClaimFields, ClaimLimits, ClaimsBoard

BELT = load_cell("two_pandas").belt


def _claim(track_id: int = 7, **changes: Any) -> ClaimFields:
    good = ClaimFields(
        station="",
        track_id=track_id,
        class_name="brick",
        frame_id="world",
        stamp_s=1.0,
        position_m=(-1.5, 0.5, 0.0),
        velocity_mps=(0.4, 0.0, 0.0),
        radius_m=0.05,
        state="claimed",
    )
    return replace(good, **changes)


def _board(**limits: int) -> ClaimsBoard:
    return ClaimsBoard(
        ("upstream", "downstream"), BELT, duration_s=60.0, limits=ClaimLimits(**limits)
    )


BAD = [
    ("state", {"state": "grabbed"}, "state 'grabbed' is not one of claimed, released, picked"),
    ("forged station", {"station": "downstream"},
     "station 'downstream' is not this topic's station 'upstream'"),
    ("NaN position", {"position_m": (math.nan, 0.5, 0.0)}, "position (nan, 0.5, 0.0) is not"),
    ("infinite position", {"position_m": (-1.5, math.inf, 0.0)}, "is not finite"),
    ("far position", {"position_m": (1e6, 0.5, 0.0)}, "is not within 1 m of the belt"),
    ("below the belt", {"position_m": (-1.5, 0.5, -5.0)}, "is not within 1 m of the belt"),
    ("NaN velocity", {"velocity_mps": (math.nan, 0.0, 0.0)}, "velocity (nan, 0.0, 0.0) is not"),
    ("fast velocity", {"velocity_mps": (300.0, 0.0, 0.0)}, "is faster than 10 m/s"),
    ("negative radius", {"radius_m": -0.05}, "radius_m -0.05 is not in (0, 1] m"),
    ("huge radius", {"radius_m": 1e300}, "radius_m 1e+300 is not in (0, 1] m"),
    ("NaN radius", {"radius_m": math.nan}, "radius_m nan is not in"),
    ("zero radius", {"radius_m": 0.0}, "radius_m 0.0 is not in"),
    ("stamp past the episode", {"stamp_s": 1e9}, "header.stamp 1000000000.0 s is outside"),
    ("another frame", {"frame_id": "map"}, "header.frame_id 'map' is not 'world'"),
    ("long class", {"class_name": "x" * 10_000}, "class_name 'xxx"),
    ("class with a newline", {"class_name": "brick\nfault"}, "is over 64 characters or not"),
]  # fmt: skip


@pytest.mark.parametrize(("name", "changes", "detail"), BAD, ids=[b[0] for b in BAD])
def test_a_claim_with_a_bad_field_is_refused_and_leaves_the_board_unchanged(
    name: str, changes: dict[str, Any], detail: str
) -> None:
    board = _board()
    refusal = board.offer(0, _claim(**changes), "payload")
    assert refusal is not None, name
    assert refusal.reason == "bad_claim"
    assert detail in refusal.detail
    assert len(refusal.detail) < 300
    assert (len(board), board.changed) == (0, False)


def test_a_good_claim_goes_on_the_board_and_a_station_may_name_itself() -> None:
    board = _board()
    assert board.offer(0, _claim(7), "a") is None
    assert board.offer(0, _claim(8, station="upstream"), "b") is None
    assert board.offer(1, _claim(7, station="downstream"), "c") is None
    assert board.changed
    assert board.take() == ["a", "b", "c"]  # by station, then track
    assert not board.changed


def test_released_and_picked_entries_are_relayed_once_then_dropped() -> None:
    board = _board()
    board.offer(0, _claim(7), "claim 7")
    board.offer(0, _claim(8), "claim 8")
    assert board.take() == ["claim 7", "claim 8"]
    board.offer(0, _claim(7, state="released"), "release 7")
    board.offer(0, _claim(8, state="picked"), "pick 8")
    assert board.take() == ["release 7", "pick 8"]
    assert (len(board), board.take()) == (0, [])


def test_the_board_is_bounded_per_station_and_in_total() -> None:
    board = _board(max_per_station=3, max_total=5)
    assert all(board.offer(0, _claim(t), t) is None for t in range(3))
    full = board.offer(0, _claim(99), 99)
    assert full is not None
    assert full.reason == "claims_full"
    assert "station 'upstream' has 3 claims on the board already" in full.detail
    assert board.offer(0, _claim(1, state="released"), "r1") is None  # a replacement is taken
    assert all(board.offer(1, _claim(t), t) is None for t in range(2))
    total = board.offer(1, _claim(50), 50)
    assert total is not None
    assert "the board holds 5 claims already" in total.detail
    board.take()  # the released entry goes: room for one more
    assert board.offer(1, _claim(50), 50) is None
    assert len(board) == 5


def test_a_flood_of_claims_costs_the_relay_a_bounded_board() -> None:
    board = _board()
    refused = sum(board.offer(0, _claim(t), t) is not None for t in range(10_000))
    limits = ClaimLimits()
    assert refused == 10_000 - limits.max_per_station
    assert len(board.take()) == limits.max_per_station
