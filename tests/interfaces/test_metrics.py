"""The metric table: ``docs/metrics.md`` equals ``interfaces.metrics.METRICS``; counts from
hand-built event lists for the line, per station and per class."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from interfaces.events import Event, EventType
from interfaces.metrics import (
    BY_NAME,
    METRICS,
    RATES,
    class_scores,
    controller_scores,
    count_events,
    event_scores,
    exit_station,
    fault_counts,
    in_scope,
    landing_by_station,
    rate,
    station_names,
    targeted_objects,
    untargeted_objects,
)
from interfaces.run_records import PickStats

PAGE = Path(__file__).resolve().parents[2] / "docs" / "metrics.md"

E = EventType


def _e(kind: EventType, oid: int, cls: str = "brick", /, **data: object) -> Event:
    return Event(time_s=0.0, step=0, type=kind, object_id=oid, class_name=cls, data=dict(data))


def _at(time_s: float, kind: EventType, oid: int, cls: str = "brick", /, **data: object) -> Event:
    return Event(time_s=time_s, step=0, type=kind, object_id=oid, class_name=cls, data=dict(data))


def _page_rows() -> list[list[str]]:
    lines = PAGE.read_text(encoding="utf-8").splitlines()
    return [
        [cell.strip() for cell in line.strip().strip("|").split("|")]
        for line in lines
        if line.startswith("| `")
    ]


def test_the_page_lists_every_metric_of_the_table_and_nothing_else() -> None:
    rows = _page_rows()
    names = [row[0].strip("`") for row in rows]
    assert names == [m.name for m in METRICS]
    for row, metric in zip(rows, METRICS, strict=True):
        name, unit, kind, ratio_of, scopes, formula, reference = row
        ratio = f"`{metric.ratio_of[0]}` / `{metric.ratio_of[1]}`" if metric.ratio_of else ""
        expected = (
            f"`{metric.name}`",
            metric.unit,
            metric.kind,
            ratio,
            ", ".join(metric.scopes),
            metric.formula,
            metric.reference,
        )
        assert (name, unit, kind, ratio_of, scopes, formula, reference) == expected


def test_the_page_names_the_metric_of_each_of_the_references_equations() -> None:
    text = " ".join(PAGE.read_text(encoding="utf-8").split())
    equations = [m for m in METRICS if m.reference.startswith("eq.")]
    assert len(equations) == 3
    for metric in equations:
        number = re.match(r"eq\. (\d)", metric.reference)
        assert number is not None
        assert re.search(rf"\({number.group(1)}\)[^()]*?: `{metric.name}`", text), metric.name


def test_every_rate_is_a_ratio_of_two_counts_of_the_table() -> None:
    counts = {m.name for m in METRICS if m.kind == "count"}
    assert {m.name for m in RATES} == {m.name for m in METRICS if m.kind == "rate"}
    for metric in RATES:
        assert metric.ratio_of is not None
        assert set(metric.ratio_of) <= counts, metric.name
        assert metric.formula == " / ".join(metric.ratio_of)
        assert set(metric.scopes) <= set(BY_NAME[metric.ratio_of[0]].scopes)


LINE = [
    *(_e(E.SPAWNED, i, "wood" if i == 5 else "brick") for i in range(1, 7)),
    _e(E.PICK_SUCCESS, 1),
    _e(E.PLACED_IN_BIN, 1, bin="brick", correct=True),
    _e(E.PICK_SUCCESS, 2),
    _e(E.PLACED_IN_BIN, 2, bin="wood", correct=False),
    _e(E.MISSED, 3),
    _e(E.FELL_OFF, 3),  # missed stays missed
    _e(E.PICK_SUCCESS, 4),
    _e(E.PICK_DROPPED, 4),  # lost
    _e(E.MISSED, 5, "wood"),
    _e(E.PICK_SUCCESS, 5, "wood"),  # picked after a miss: picked
    _e(E.UNINTENDED_CONTACT, 6),
    _e(E.UNINTENDED_CONTACT, 6),
]


def test_count_events_gives_every_fate_of_the_line() -> None:
    counts = count_events(LINE, duration_s=120.0)
    assert (counts.spawned, counts.processed, counts.picked, counts.missed, counts.lost) == (
        6,
        5,
        3,
        1,
        1,
    )
    assert (counts.placed, counts.placed_correct, counts.unintended_contacts) == (2, 1, 2)
    scores = event_scores(counts)
    assert scores["pick_success_rate"] == pytest.approx(3 / 5)
    assert scores["miss_rate"] == pytest.approx(1 / 5)
    assert scores["pick_throughput_per_min"] == pytest.approx(1.5)
    # 6 has no fate (still on the belt): the complete cohort is 1-5, of which 1 is recovered
    assert (counts.entered, counts.recovered) == (5, 1)
    assert scores["recovery_rate"] == pytest.approx(1 / 5)
    assert scores["correct_bin_ratio"] == pytest.approx(1 / 2)
    assert scores["time_per_object_s"] == pytest.approx(40.0)
    assert scores["recovery_by_class"] == {"brick": pytest.approx(1 / 4), "wood": 0.0}
    for metric in RATES:
        if metric.name in scores:
            assert scores[metric.name] == rate(metric.name, scores), metric.name
    assert set(in_scope("class")) <= set(scores)


def test_nothing_happened_gives_zero_rates_not_errors() -> None:
    scores = event_scores(count_events([], duration_s=0.0))
    assert scores["pick_success_rate"] == scores["pick_throughput_per_min"] == 0.0
    assert controller_scores(count_events([], 0.0), targeted=0)["success_rate"] == 0.0


def test_success_counts_only_what_a_tool_picked_and_let_go_into_its_bin() -> None:
    """A piece carried into the bin along with the target, or knocked in, and one dropped on
    the way that fell in, lie in their class's bin (``placed_correct``) but were not sorted by a
    pick: the success rate's numerator leaves them out."""
    events = [
        _e(E.PICK_SUCCESS, 1, "brick", station="s1"),
        _e(E.PLACED_IN_BIN, 1, "brick", bin="brick", correct=True, station="s1"),
        _e(E.PLACED_IN_BIN, 2, "brick", bin="brick", correct=True, station="s1"),  # carried in
        _e(E.PICK_SUCCESS, 3, "wood", station="s1"),
        _e(E.PICK_DROPPED, 3, "wood", station="s1", reason="suction_overload"),
        _e(E.PLACED_IN_BIN, 3, "wood", bin="wood", correct=True, station="s1"),  # fell in
        _e(E.PICK_SUCCESS, 4, "wood", station="s1"),
        _e(E.PLACED_IN_BIN, 4, "wood", bin="brick", correct=False, station="s1"),
    ]
    counts = count_events(events, 60.0)
    assert (counts.placed, counts.placed_correct, counts.sorted) == (4, 3, 1)
    assert event_scores(counts)["sorted"] == 1
    # the station targeted 1, 3 and 4: one of three sorted (placed_correct would say 3 of 3)
    assert controller_scores(counts, targeted=3)["success_rate"] == pytest.approx(1 / 3)
    assert count_events(events, 60.0, station="s1").sorted == 1
    assert count_events(events, 60.0, class_name="wood").sorted == 0


def _two_stations() -> list[Event]:
    up, down = {"station": "upstream"}, {"station": "downstream"}
    return [
        *(_e(E.SPAWNED, i, "concrete" if i == 4 else "brick") for i in range(1, 6)),
        # 1: picked upstream, into an upstream bin
        _e(E.ENTERED_WORKSPACE, 1, **up),
        _e(E.PICK_SUCCESS, 1, **up),
        _e(E.PLACED_IN_BIN, 1, bin="brick", correct=True, **up),
        # 2: missed upstream, picked downstream, into a downstream bin of another class
        _e(E.ENTERED_WORKSPACE, 2, **up),
        _e(E.MISSED, 2, **up),
        _e(E.ENTERED_WORKSPACE, 2, **down),
        _e(E.PICK_SUCCESS, 2, **down),
        _e(E.PLACED_IN_BIN, 2, bin="wood", correct=False, **down),
        # 3: missed by both
        _e(E.ENTERED_WORKSPACE, 3, **up),
        _e(E.MISSED, 3, **up),
        _e(E.ENTERED_WORKSPACE, 3, **down),
        _e(E.MISSED, 3, **down),
        # 4: picked upstream, dropped on the belt, then picked downstream and placed
        _e(E.ENTERED_WORKSPACE, 4, "concrete", **up),
        _e(E.PICK_SUCCESS, 4, "concrete", **up),
        _e(E.PICK_DROPPED, 4, "concrete", **up),
        _e(E.ENTERED_WORKSPACE, 4, "concrete", **down),
        _e(E.PICK_SUCCESS, 4, "concrete", **down),
        _e(E.PLACED_IN_BIN, 4, "concrete", bin="concrete", correct=True, **down),
        # 5: never reached a window; a cell-wide fault; a contact at the downstream robot
        _e(E.FAULT, 0, "", kind="injected_dropout_start"),
        _e(E.FAULT, 0, "", kind="controller_timeout", **down),
        _e(E.UNINTENDED_CONTACT, 5, **down),
    ]


def test_count_events_per_station_and_for_the_line() -> None:
    events = _two_stations()
    assert station_names(events) == ["upstream", "downstream"]
    line = count_events(events, 60.0)
    up = count_events(events, 60.0, station="upstream")
    down = count_events(events, 60.0, station="downstream")
    fields = ("spawned", "processed", "picked", "missed", "lost", "placed", "placed_correct")
    assert [getattr(line, f) for f in fields] == [5, 4, 3, 1, 0, 3, 2]
    assert [getattr(up, f) for f in fields] == [4, 4, 1, 2, 1, 1, 1]
    assert [getattr(down, f) for f in fields] == [3, 3, 2, 1, 0, 2, 1]
    assert (line.unintended_contacts, up.unintended_contacts, down.unintended_contacts) == (1, 0, 1)
    assert fault_counts(events) == {"faults": 1, "injected_faults": 1}
    assert fault_counts(events, station="downstream") == {"faults": 1, "injected_faults": 0}
    assert fault_counts(events, station="upstream") == {"faults": 0, "injected_faults": 0}


def test_for_the_line_only_the_last_station_decides_a_miss() -> None:
    """An object the upstream station missed is on its way to the next window: undecided for
    the line until it is picked, lost or missed there (here object 6 at the episode's end)."""
    from interfaces.cell import load_cell

    up = {"station": "upstream"}
    events = [
        *_two_stations(),
        _e(E.SPAWNED, 6),
        _e(E.ENTERED_WORKSPACE, 6, **up),
        _e(E.MISSED, 6, **up),
        _e(E.SPAWNED, 7),
        _e(E.ENTERED_WORKSPACE, 7, **up),
        _e(E.MISSED, 7, **up),
        _e(E.FELL_OFF, 7),  # off the belt between the windows: lost
    ]
    last = exit_station(load_cell("two_pandas").stations)
    assert last == "downstream"
    assert exit_station(load_cell("default").stations) == "panda"
    line = count_events(events, 60.0, line_exit=last)
    assert (line.spawned, line.processed, line.picked, line.missed, line.lost) == (7, 5, 3, 1, 1)
    naive = count_events(events, 60.0)
    assert (naive.processed, naive.missed, naive.lost) == (6, 3, 0)
    up_counts = count_events(events, 60.0, station="upstream", line_exit=last)
    assert (up_counts.missed, up_counts.processed) == (4, 6)
    assert class_scores(events, 60.0, line_exit=last)["brick"]["missed"] == 1


def test_count_events_per_class() -> None:
    events = _two_stations()
    concrete = count_events(events, 60.0, class_name="concrete")
    assert (concrete.spawned, concrete.picked, concrete.placed_correct) == (1, 1, 1)
    brick = count_events(events, 60.0, class_name="brick")
    assert (brick.spawned, brick.processed, brick.picked, brick.missed) == (4, 3, 2, 1)
    up_concrete = count_events(events, 60.0, station="upstream", class_name="concrete")
    assert (up_concrete.spawned, up_concrete.picked, up_concrete.lost) == (1, 0, 1)
    per_class = class_scores(events, 60.0)
    assert list(per_class) == ["brick", "concrete"]
    assert set(per_class["brick"]) == set(in_scope("class"))
    # 5 (brick) never reached a window: undecided, the cut; bricks 1-3 entered, 1 recovered
    assert per_class["brick"]["recovery_rate"] == pytest.approx(1 / 3)
    assert per_class["concrete"]["recovery_rate"] == 1.0
    assert per_class["brick"]["miss_rate"] == pytest.approx(1 / 3)
    assert class_scores(events, 60.0, station="upstream")["concrete"]["lost"] == 1


def _placed(time_s: float, oid: int, cls: str = "brick", /, **station: object) -> list[Event]:
    return [
        _at(time_s, E.PICK_SUCCESS, oid, cls, **station),
        _at(time_s + 1.0, E.PLACED_IN_BIN, oid, cls, bin=cls, correct=True, **station),
    ]


def test_an_undecided_object_cuts_the_cohort_before_itself_and_every_later_one() -> None:
    """Object 3 is still on the belt at the end: it and every object spawned after it (4, 5,
    although placed in their bins) are left out of ``entered`` and ``recovered``; the cohort
    follows the spawn times, not the order of the events."""
    from interfaces.metrics import complete_cohort

    spawns = [_at(float(i), E.SPAWNED, i, "wood" if i == 5 else "brick") for i in range(1, 6)]
    fates = [
        *_placed(10.0, 1),
        _at(11.0, E.MISSED, 2),
        *_placed(12.0, 4),
        *_placed(13.0, 5, "wood"),
    ]
    for events in ([*spawns, *fates], [*reversed(spawns), *fates]):
        counts = count_events(events, 60.0)
        assert (counts.spawned, counts.processed, counts.placed_correct) == (5, 4, 3)
        assert (counts.entered, counts.recovered) == (2, 1)
        assert complete_cohort(events) == {1, 2}
        assert (counts.entered_by_class, counts.recovered_by_class) == ({"brick": 2}, {"brick": 1})
        scores = event_scores(counts)
        assert (scores["entered"], scores["recovered"]) == (2, 1)
        assert scores["recovery_rate"] == pytest.approx(1 / 2)
        assert scores["recovery_by_class"] == {"brick": pytest.approx(1 / 2), "wood": 0.0}


def test_recovery_over_the_takeable_pieces_at_every_scope() -> None:
    """Seven pieces through a line of two stations, ``up`` then ``down``. Pieces 3 and 5 no
    station could take (their ``spawned`` events say ``takeable: false``); piece 6 has no mark
    (an older log: takeable); piece 7 is still on the belt at the end (out of the cohort). Up
    sorts 1; down sorts 2 and 6 and lets 4 pass; 5 fell into the right bin unpicked (knocked
    in: recovered, not takeable). The line's cohort 1-6 recovers 4 (1, 2, 5, 6); its takeable
    pieces 1, 2, 4, 6 recover 3: 0.75. Each station counts the pieces that entered its window,
    judged for the line."""
    up, down = {"station": "up"}, {"station": "down"}

    def spawn(oid: int, cls: str, **mark: object) -> Event:
        return _at(float(oid), E.SPAWNED, oid, cls, **mark)

    def enter(time_s: float, oid: int, cls: str, station: dict[str, object]) -> Event:
        return _at(time_s, E.ENTERED_WORKSPACE, oid, cls, x_m=0.0, **station)

    events = [
        spawn(1, "brick", takeable=True),
        spawn(2, "wood", takeable=True),
        spawn(3, "brick", takeable=False, refusal="too_wide"),
        spawn(4, "brick", takeable=True),
        spawn(5, "wood", takeable=False, refusal="too_flat+too_small"),
        spawn(6, "wood"),
        spawn(7, "brick", takeable=True),
        *(enter(10.0 + oid, oid, c, up) for oid, c in ((1, "brick"), (2, "wood"), (3, "brick"))),
        *_placed(20.0, 1, "brick", **up),
        _at(21.0, E.MISSED, 2, "wood", **up),
        _at(22.0, E.MISSED, 3, "brick", **up),
        enter(30.0, 2, "wood", down),
        enter(31.0, 3, "brick", down),
        enter(32.0, 4, "brick", down),
        enter(33.0, 6, "wood", down),
        *_placed(40.0, 2, "wood", **down),
        _at(41.0, E.MISSED, 3, "brick", **down),
        _at(42.0, E.MISSED, 4, "brick", **down),
        *_placed(43.0, 6, "wood", **down),
        _at(44.0, E.PLACED_IN_BIN, 5, "wood", bin="wood", correct=True, **down),
    ]
    line = event_scores(count_events(events, 60.0, line_exit="down"))
    assert (line["entered"], line["recovered"]) == (6, 4)  # 1-6; 7 undecided
    assert (line["entered_takeable"], line["recovered_takeable"]) == (4, 3)  # 1, 2, 4, 6
    assert line["recovery_rate"] == pytest.approx(4 / 6)
    assert line["recovery_takeable"] == pytest.approx(3 / 4)
    first = event_scores(count_events(events, 60.0, station="up"))
    assert (first["entered"], first["entered_takeable"], first["recovered_takeable"]) == (3, 2, 1)
    assert first["recovery_takeable"] == pytest.approx(1 / 2)
    last = event_scores(count_events(events, 60.0, station="down"))
    assert (last["entered"], last["entered_takeable"], last["recovered_takeable"]) == (4, 3, 2)
    by_class = class_scores(events, 60.0, line_exit="down")
    assert (by_class["brick"]["entered_takeable"], by_class["brick"]["recovered_takeable"]) == (
        2,
        1,
    )
    assert by_class["wood"]["recovery_takeable"] == pytest.approx(1.0)  # 2 and 6; 5 refused
    assert by_class["wood"]["recovery_rate"] == pytest.approx(1.0)  # 5 knocked in
    unmarked = [e for e in events if e.type is not E.SPAWNED] + [
        _at(e.time_s, E.SPAWNED, e.object_id, e.class_name) for e in events if e.type is E.SPAWNED
    ]
    old = event_scores(count_events(unmarked, 60.0, line_exit="down"))
    assert old["recovery_takeable"] == old["recovery_rate"]  # a log without marks


def test_an_object_knocked_into_a_bin_unpicked_does_not_cut_the_cohort() -> None:
    """The first object, pushed off the belt into a bin by an arm (``placed_in_bin`` with no
    ``pick_success``), has no fate but is out of the stream: the cohort runs on past it (it
    cut the whole stream off before, an episode of 102 correct placements scoring a recovery
    of 0). In its own class's bin it is recovered; it is not picked nor processed."""
    from interfaces.metrics import complete_cohort

    spawns = [_at(float(i), E.SPAWNED, i) for i in range(1, 4)]
    knocked = _at(9.0, E.PLACED_IN_BIN, 1, "brick", bin="brick", correct=True, station="s4")
    events = [*spawns, knocked, *_placed(10.0, 2), _at(11.0, E.MISSED, 3)]
    assert complete_cohort(events) == {1, 2, 3}
    counts = count_events(events, 60.0)
    assert (counts.entered, counts.recovered) == (3, 2)
    assert (counts.processed, counts.picked, counts.placed_correct) == (2, 1, 2)
    assert event_scores(counts)["recovery_rate"] == pytest.approx(2 / 3)


def test_with_nothing_undecided_every_spawned_object_entered() -> None:
    """Every object has a fate: the cohort is the whole stream. One picked but still carried at
    the end (3) is decided: it entered, but is not recovered."""
    events = [
        *(_at(float(i), E.SPAWNED, i) for i in range(1, 4)),
        *_placed(10.0, 1),
        _at(11.0, E.MISSED, 2),
        _at(12.0, E.PICK_SUCCESS, 3),
    ]
    counts = count_events(events, 60.0)
    assert (counts.spawned, counts.entered, counts.placed_correct, counts.recovered) == (3, 3, 1, 1)
    assert event_scores(counts)["recovery_rate"] == pytest.approx(1 / 3)
    line = count_events(_sorting_line(), 60.0, line_exit="downstream")
    assert (line.entered, line.recovered) == (line.spawned, line.placed_correct) == (8, 3)
    assert line.entered_by_class == line.spawned_by_class


def test_per_class_the_cut_is_the_whole_streams() -> None:
    """Brick 3 is undecided: the cut falls there for every class. Wood 5, spawned after it and
    missed, is out of the wood cohort too (cut over wood alone it would count: 1 / 2)."""
    events = [
        *(_at(float(i), E.SPAWNED, i, "wood" if i in (2, 5) else "brick") for i in range(1, 6)),
        *_placed(10.0, 1),
        *_placed(11.0, 2, "wood"),
        *_placed(12.0, 4),
        _at(13.0, E.MISSED, 5, "wood"),
    ]
    line = count_events(events, 60.0)
    assert (line.entered, line.recovered) == (2, 2)
    assert line.entered_by_class == {"brick": 1, "wood": 1}
    assert sum(line.recovered_by_class.values()) == line.recovered
    wood = count_events(events, 60.0, class_name="wood")
    assert (wood.spawned, wood.missed, wood.entered, wood.recovered) == (2, 1, 1, 1)
    per_class = class_scores(events, 60.0)
    assert per_class["wood"]["recovery_rate"] == 1.0
    assert (per_class["brick"]["entered"], per_class["brick"]["recovered"]) == (1, 1)
    assert {k: v["recovery_rate"] for k, v in per_class.items()} == event_scores(line)[
        "recovery_by_class"
    ]


def test_on_a_line_an_object_missed_upstream_is_undecided_until_the_exit() -> None:
    """Object 2, missed upstream and not yet at the exit station's window, is undecided for the
    line and cuts the cohort there (3, placed upstream, is left out); once the exit station
    misses it, the cohort is the whole stream."""
    up, down = {"station": "upstream"}, {"station": "downstream"}
    events = [
        *(_at(float(i), E.SPAWNED, i) for i in range(1, 4)),
        _at(5.0, E.ENTERED_WORKSPACE, 1, **up),
        *_placed(6.0, 1, **up),
        _at(7.0, E.ENTERED_WORKSPACE, 2, **up),
        _at(8.0, E.MISSED, 2, **up),
        _at(9.0, E.ENTERED_WORKSPACE, 3, **up),
        *_placed(10.0, 3, **up),
    ]
    line = count_events(events, 60.0, line_exit="downstream")
    assert (line.spawned, line.entered, line.recovered) == (3, 1, 1)
    naive = count_events(events, 60.0)  # every miss counts: exact for one station only
    assert (naive.entered, naive.recovered) == (3, 2)
    upstream = count_events(events, 60.0, station="upstream", line_exit="downstream")
    assert (upstream.entered, upstream.recovered) == (3, 2)  # missed there: decided for it
    events += [_at(20.0, E.ENTERED_WORKSPACE, 2, **down), _at(21.0, E.MISSED, 2, **down)]
    line = count_events(events, 60.0, line_exit="downstream")
    assert (line.entered, line.recovered) == (3, 2)
    assert event_scores(line)["recovery_rate"] == pytest.approx(2 / 3)


def test_a_stations_cohort_follows_its_own_window_and_fates() -> None:
    """Upstream, 3 is still in the window at the end: its cohort is 1 and 2 (4, placed there,
    is left out); downstream only 2 entered the window, picked there; for the line the cut is 3
    too (2 was picked downstream)."""
    up, down = {"station": "upstream"}, {"station": "downstream"}
    events = [
        *(_at(float(i), E.SPAWNED, i) for i in range(1, 5)),
        _at(5.0, E.ENTERED_WORKSPACE, 1, **up),
        *_placed(5.5, 1, **up),
        _at(6.0, E.ENTERED_WORKSPACE, 2, **up),
        _at(6.5, E.MISSED, 2, **up),
        _at(7.0, E.ENTERED_WORKSPACE, 3, **up),
        _at(8.0, E.ENTERED_WORKSPACE, 4, **up),
        *_placed(8.5, 4, **up),
        _at(9.0, E.ENTERED_WORKSPACE, 2, **down),
        *_placed(9.5, 2, **down),
    ]
    upstream = count_events(events, 60.0, station="upstream")
    assert (upstream.spawned, upstream.entered, upstream.recovered) == (4, 2, 1)
    assert event_scores(upstream)["recovery_rate"] == pytest.approx(1 / 2)
    downstream = count_events(events, 60.0, station="downstream")
    assert (downstream.spawned, downstream.entered, downstream.recovered) == (1, 1, 1)
    line = count_events(events, 60.0, line_exit="downstream")
    assert (line.spawned, line.entered, line.recovered) == (4, 2, 2)


def test_targeted_subtracts_the_landing_objects_per_station() -> None:
    events = _two_stations()
    stats = [
        PickStats(completed=3, aborted={"lost_track": 1}, untargeted={"too_wide": 2}),
        PickStats(completed=1, untargeted={"too_wide": 1, "flat": 4}),
    ]
    # objects 1 (released upstream) and 4 (last released downstream) are still falling
    assert landing_by_station(events, [1, 4]) == {"upstream": 1, "downstream": 1}
    assert targeted_objects(stats, landing=2) == 3
    assert targeted_objects(stats[:1], landing=1) == 3
    assert targeted_objects([], landing=3) == 0
    assert untargeted_objects(stats) == {"too_wide": 3, "flat": 4}
    line = count_events(events, 60.0)
    assert controller_scores(line, targeted=4) == {
        "success_rate": pytest.approx(2 / 4),
        "throughput_per_min": pytest.approx(2.0),
    }


def _sorting_line() -> list[Event]:
    """Two stations; what came to rest in which bin: upstream's brick bin holds bricks 1 and 2
    and wood 3, its wood bin nothing; downstream's brick bin holds concrete 4, its concrete bin
    concrete 5 and brick 6; brick 7 was dropped twice (slipped, then released without a
    reason, as events before drops carried one): lost; brick 8 was missed by both stations."""
    up, down = {"station": "upstream"}, {"station": "downstream"}
    classes = {1: "brick", 2: "brick", 3: "wood", 4: "concrete", 5: "concrete", 6: "brick"}
    classes[7] = classes[8] = "brick"
    events = [_e(E.SPAWNED, oid, cls) for oid, cls in classes.items()]
    for oid, station, bin_name in (
        (1, up, "brick"),
        (2, up, "brick"),
        (3, up, "brick"),
        (4, down, "brick"),
        (5, down, "concrete"),
        (6, down, "concrete"),
    ):
        cls = classes[oid]
        events.append(_e(E.ENTERED_WORKSPACE, oid, cls, **station))
        events.append(_e(E.PICK_SUCCESS, oid, cls, **station))
        events.append(
            _e(E.PLACED_IN_BIN, oid, cls, bin=bin_name, correct=cls == bin_name, **station)
        )
    events += [
        _e(E.ENTERED_WORKSPACE, 7, **up),
        _e(E.PICK_SUCCESS, 7, **up),
        _e(E.PICK_DROPPED, 7, reason="slipped", **up),
        _e(E.PICK_SUCCESS, 7, **up),
        _e(E.PICK_DROPPED, 7, **up),
        _e(E.MISSED, 7, **up),
        _e(E.ENTERED_WORKSPACE, 7, **down),
        _e(E.MISSED, 7, **down),
        _e(E.ENTERED_WORKSPACE, 8, **up),
        _e(E.MISSED, 8, **up),
        _e(E.ENTERED_WORKSPACE, 8, **down),
        _e(E.MISSED, 8, **down),
    ]
    return events


def test_purity_of_each_bin_and_of_each_class_over_the_line() -> None:
    from interfaces.metrics import bin_scores

    events = _sorting_line()
    bins = bin_scores(events)
    assert list(bins) == ["upstream", "downstream"]
    assert bins["upstream"] == {
        "brick": {"binned": 3, "placed_correct": 2, "purity": pytest.approx(2 / 3)}
    }
    assert bins["downstream"]["brick"] == {"binned": 1, "placed_correct": 0, "purity": 0.0}
    assert bins["downstream"]["concrete"]["purity"] == pytest.approx(1 / 2)
    assert list(bin_scores(events, station="downstream")) == ["downstream"]
    assert set(in_scope("bin")) == set(bins["upstream"]["brick"])
    # per class over the line: the class's own objects among everything in the bins sorting it
    per_class = class_scores(events, 60.0, line_exit="downstream")
    assert (per_class["brick"]["binned"], per_class["brick"]["placed_correct"]) == (4, 2)
    assert per_class["brick"]["purity"] == pytest.approx(2 / 4)
    assert per_class["concrete"]["purity"] == pytest.approx(1 / 2)
    assert per_class["wood"]["binned"] == 0
    assert per_class["wood"]["purity"] == 0.0
    # the line's and a station's purity: every one of their bins together
    assert event_scores(count_events(events, 60.0))["purity"] == pytest.approx(3 / 6)
    assert count_events(events, 60.0, station="downstream").binned == 2 + 1


def test_drops_are_counted_by_reason_per_station_and_class() -> None:
    events = _sorting_line()
    line = event_scores(count_events(events, 60.0, line_exit="downstream"))
    assert line["dropped"] == 2
    assert line["dropped_by_reason"] == {"released": 1, "slipped": 1}
    up = count_events(events, 60.0, station="upstream")
    assert (up.dropped, dict(up.dropped_by_reason)) == (2, {"released": 1, "slipped": 1})
    assert count_events(events, 60.0, station="downstream").dropped == 0
    assert class_scores(events, 60.0)["brick"]["dropped"] == 2
    assert class_scores(events, 60.0)["concrete"]["dropped"] == 0


def test_line_scores_recovery_per_class_line_miss_rate_and_picks_per_minute() -> None:
    """The line's scores of the issue: recovery per class, the most downstream station's misses
    as the line's, picks per minute and the reference's equations per station."""
    events = _sorting_line()
    line = event_scores(count_events(events, 120.0, line_exit="downstream"))
    assert line["recovery_by_class"] == {
        "brick": pytest.approx(2 / 5),
        "concrete": pytest.approx(1 / 2),
        "wood": 0.0,
    }
    per_class = class_scores(events, 120.0, line_exit="downstream")
    assert {k: v["recovery_rate"] for k, v in per_class.items()} == line["recovery_by_class"]
    # 8: missed upstream (still on its way), then downstream: missed by the line, once;
    # 7: dropped on the belt before its misses: lost
    assert (line["missed"], line["lost"], line["processed"]) == (1, 1, 8)
    assert line["miss_rate"] == pytest.approx(1 / 8)
    assert line["pick_throughput_per_min"] == pytest.approx(6 / 2)
    up = event_scores(count_events(events, 120.0, station="upstream"))
    down = event_scores(count_events(events, 120.0, station="downstream"))
    assert (up["picked"], up["processed"], up["missed"], up["lost"]) == (3, 5, 1, 1)
    assert up["pick_success_rate"] == pytest.approx(3 / 5)  # eq. 1
    assert up["miss_rate"] == pytest.approx(1 / 5)  # eq. 2
    assert up["pick_throughput_per_min"] == pytest.approx(1.5)  # eq. 3
    assert (down["picked"], down["missed"], down["pick_throughput_per_min"]) == (3, 2, 1.5)
    for name in ("pick_success_rate", "miss_rate", "pick_throughput_per_min"):
        assert "station" in BY_NAME[name].scopes


def test_allocation_decisions_and_the_unfit_share_per_station() -> None:
    """Every reason a controller gives (new ones such as ``claimed_by_other`` included) is
    counted; the unfit share counts only the reasons that say the tool cannot take the object,
    of every object the station's controllers decided about (targeted or not)."""
    from interfaces.metrics import UNFIT_REASONS, considered_objects, untargeted_scores

    stats = [
        PickStats(targeted=4, untargeted={"too_wide": 3, "claimed_by_other": 5}),
        PickStats(
            untargeted={"too_flat": 1, "too_small": 2, "too_tilted": 1, "left_for_downstream": 4}
        ),
        PickStats(targeted=1),
        None,  # a controller that wrote no pick counters
    ]
    untargeted = untargeted_objects(stats)
    assert untargeted == {
        "too_wide": 3,
        "claimed_by_other": 5,
        "too_flat": 1,
        "too_small": 2,
        "too_tilted": 1,
        "left_for_downstream": 4,
    }
    assert considered_objects(stats) == 5 + 16
    scores = untargeted_scores(untargeted, considered_objects(stats))
    assert set(UNFIT_REASONS) == {"too_wide", "too_flat", "too_small", "too_tilted"}
    assert (scores["untargeted_total"], scores["untargeted_unfit"]) == (16, 7)
    assert scores["considered"] == 21
    assert scores["unfit_share"] == pytest.approx(7 / 21)
    assert scores["untargeted_share"]["claimed_by_other"] == pytest.approx(5 / 21)
    assert list(scores["untargeted_share"]) == sorted(untargeted)
    assert sum(scores["untargeted_share"].values()) <= 1.0
    assert untargeted_scores({}, considered=0)["unfit_share"] == 0.0
