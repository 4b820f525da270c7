"""``docs/metrics.md`` against the code: the fate of every example of the page's fates table,
and the rule by which the twin counts a client's targets, as :mod:`interfaces.metrics` and the
twin's pursuits (:class:`twin.target_metric.TargetTracker`) compute them."""

from __future__ import annotations

import re

import pytest

from interfaces.events import Event, EventType
from interfaces.metrics import count_events
from tests.docs.conftest import Page, cells, ticked
from twin.target_metric import PURSUIT_PHASES, TargetTracker

STATION = "panda"


def _fates(page: Page) -> list[tuple[list[str], str]]:
    """The page's examples: the event types of one object, in order, and its fate."""
    section = page.section("How objects are counted")
    rows = [line for line in section.splitlines() if re.match(r"^\| \d+ \|", line)]
    assert rows, "docs/metrics.md has no fates table"
    return [(ticked(cells(line)[1]), cells(line)[2]) for line in rows]


def _event(kind: str, time_s: float) -> Event:
    data: dict[str, object] = {"station": STATION}
    if kind == "placed_in_bin":
        data |= {"bin": "brick", "correct": True}
    return Event(
        time_s=time_s,
        step=0,
        type=EventType(kind),
        object_id=1,
        class_name="brick",
        data=data,
    )


def test_every_example_of_the_fates_table_has_the_fate_the_metrics_give(
    metrics_page: Page,
) -> None:
    examples = _fates(metrics_page)
    assert {fate for _, fate in examples} == {"picked", "missed", "lost", "none"}
    for kinds, fate in examples:
        events = [_event("spawned", 0.0)] + [_event(k, 1.0 + i) for i, k in enumerate(kinds)]
        for scope in ({}, {"station": STATION}):
            counts = count_events(events, 10.0, **scope)
            got = {"picked": counts.picked, "missed": counts.missed, "lost": counts.lost}
            expected = {name: int(name == fate) for name in got}
            assert got == expected, (kinds, scope)
            assert counts.processed == int(fate != "none"), (kinds, scope)


def test_the_fate_rules_name_every_deciding_event(metrics_page: Page) -> None:
    """The rules' list names exactly the events that decide a fate."""
    text = metrics_page.flat("How objects are counted")
    rules = text[text.index("follows its events in order") : text.index("So a miss stands")]
    deciding = {"pick_success", "missed", "pick_dropped", "fell_off"}
    for kind in EventType:
        events = [_event("spawned", 0.0), _event(kind.value, 1.0)]
        decides = count_events(events, 10.0).processed == 1
        assert decides == (kind.value in deciding), kind
    assert set(ticked(rules)) - {"placed_in_bin"} == deciding


@pytest.fixture
def tracker() -> TargetTracker:
    """A station's pursuits, as the twin measures them."""
    return TargetTracker()


POSE = ((0.0, 0.5, 0.03), (0.0, 0.0, 0.0, 1.0))


def test_a_clients_targets_are_counted_as_the_page_says(
    metrics_page: Page, tracker: TargetTracker
) -> None:
    """One pursuit per target announced on an object, repeated announcements included; a
    retry after closing is a target of its own; an announcement off every object none; one
    still open at the end counts."""
    text = metrics_page.flat("How objects are counted")
    assert f"within {tracker.match_radius_m:g} m of its centre of mass" in text
    assert "`tracking.pursuits`" in text
    phase = sorted(PURSUIT_PHASES)[0]
    poses = {7: POSE}
    near = (0.0, 0.5 + 0.9 * tracker.match_radius_m, 0.02)
    far = (0.0, 0.5 + 1.1 * tracker.match_radius_m, 0.02)
    for t in (0.0, 0.1, 0.2):
        tracker.announce(t, 1, near, phase, poses)
    tracker.announce(0.3, 1, near, "close", poses)
    assert len(tracker.results) == 1
    tracker.announce(0.4, 1, near, phase, poses)  # the same track again: a retry
    tracker.announce(0.5, 1, near, "close", poses)
    assert len(tracker.results) == 2
    tracker.announce(0.6, 2, far, phase, poses)  # on no object
    tracker.announce(0.7, 2, far, "close", poses)
    assert len(tracker.results) == 2
    tracker.announce(0.8, 3, near, phase, poses)
    tracker.finish(0.9)  # the episode ends
    assert len(tracker.results) == 3
