"""The line's allocation (control/allocation.py): pure, no ROS, on the shipped two-station cell."""

from __future__ import annotations

from dataclasses import replace

import pytest

from control.allocation import Allocator, Claim, ClaimState, claim_of
from control.config import AllocationConfig, ControllerConfig
from control.errors import ControlConfigError
from control.tracking import Track
from interfaces.cell import load_cell


def _config(station: str, **allocation: object) -> ControllerConfig:
    return ControllerConfig(
        cell=load_cell("two_pandas"),
        station_name=station,
        allocation=AllocationConfig(**allocation),  # type: ignore[arg-type]
    )


def _track(x_m: float, *, track_id: int = 7, cls: str = "brick", width_m: float = 0.04) -> Track:
    return Track(
        track_id=track_id,
        stamp_s=1.0,
        class_name=cls,
        class_confidence=1.0,
        position_m=(x_m, 0.5),
        velocity_mps=(0.4, 0.0),
        position_std_m=0.001,
        yaw_rad=0.0,
        length_m=0.1,
        width_m=width_m,
        height_m=0.04,
        hits=10,
        confirmed=True,
        last_update_s=1.0,
    )


def _claim(station: str, track: Track, state: ClaimState = "claimed") -> Claim:
    # claimed half a second before the track's stamp, where the object was then
    return claim_of(station, track, 0.5, state, 0.01)


def test_first_fit_leaves_what_another_station_claimed_and_takes_the_rest() -> None:
    allocator = Allocator(_config("downstream"))
    claimed = _track(-1.0)
    allocator.apply_board([_claim("upstream", claimed)])
    assert allocator.reason(claimed, 1.0) == "claimed_by_other"
    # 3 cm beside the claimed position: another object (the claim's radius is 2 cm)
    beside = replace(claimed, track_id=8, position_m=(-1.0, 0.53))
    assert allocator.reason(beside, 1.0) is None
    # its own claims never stop a station
    own = Allocator(_config("upstream"))
    own.apply_board([_claim("upstream", claimed)])
    assert own.reason(claimed, 1.0) is None


def test_a_conflict_is_kept_by_the_station_further_upstream() -> None:
    track = _track(-1.5)
    upstream, downstream = Allocator(_config("upstream")), Allocator(_config("downstream"))
    board = [_claim("upstream", track), _claim("downstream", track)]
    upstream.apply_board(board)
    downstream.apply_board(board)
    assert not upstream.must_yield(track, 1.0)
    assert downstream.must_yield(track, 1.0)


def test_released_claims_free_the_object_and_picked_ones_keep_it_taken() -> None:
    allocator = Allocator(_config("downstream"))
    track = _track(-1.0)
    allocator.apply_board([_claim("upstream", track)])
    allocator.apply_board([_claim("upstream", track, "released")])
    assert allocator.reason(track, 1.0) is None
    # a picked object stays taken though the board no longer lists it (the track coasts on)
    allocator.apply_board([_claim("upstream", track, "picked")])
    allocator.apply_board([])
    assert allocator.reason(track, 1.0) == "claimed_by_other"


def test_a_claim_past_its_station_window_is_stale() -> None:
    allocator = Allocator(_config("downstream", claim_expiry_m=0.3))
    track = _track(-0.6)
    allocator.apply_board([_claim("upstream", track)])
    # upstream's window ends at -1.15 m; the claimed object is at -0.6 m, 0.55 m past it
    assert allocator.reason(track, 1.0) is None


def test_class_priority_leaves_a_class_to_the_downstream_station_that_prefers_it() -> None:
    prefs = {"downstream": ("wood",)}
    upstream = Allocator(_config("upstream", strategy="class_priority", preferred_classes=prefs))
    assert upstream.reason(_track(-1.5, cls="wood"), 1.0) == "left_for_downstream"
    assert upstream.reason(_track(-1.5, cls="brick"), 1.0) is None
    # a wood board too wide for the downstream hand: the upstream station takes it after all
    assert upstream.reason(_track(-1.5, cls="wood", width_m=0.2), 1.0) is None
    # the most downstream station has no one to leave anything to
    downstream = Allocator(
        _config("downstream", strategy="class_priority", preferred_classes=prefs)
    )
    assert downstream.reason(_track(-0.2, cls="brick"), 1.0) is None
    first_fit = Allocator(_config("upstream", preferred_classes=prefs))
    assert first_fit.reason(_track(-1.5, cls="wood"), 1.0) is None


def test_allocation_settings_are_checked_against_the_cell() -> None:
    with pytest.raises(ControlConfigError, match=r"allocation\.strategy"):
        _config("upstream", strategy="round_robin")
    with pytest.raises(ControlConfigError, match=r"allocation\.preferred_classes\.middle"):
        _config("upstream", preferred_classes={"middle": ("wood",)})
    with pytest.raises(ControlConfigError, match=r"not classes of the cell"):
        _config("upstream", preferred_classes={"upstream": ("gypsum",)})
