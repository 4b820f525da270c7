"""Bin slots: the shipped cells' bins take a dataset's classes in its class table's order, or as
a ``bins:`` map says, at every station; fixed bins keep their class; what does not fit is one
error naming the station and the counts."""

from __future__ import annotations

import pytest

from interfaces.bins import BinsMap, BinSpec, assign_bins
from interfaces.cell import CellError, load_cell, resolve_cell
from interfaces.errors import ConfigError
from interfaces.materials import ClassTable, shipped_table, table_from_data

SHIPPED = ("concrete", "brick", "wood", "rubber")


def _table(*names: str) -> ClassTable:
    return table_from_data({"classes": {n: {} for n in names}}, "table", shipped_table())


def _layout(*names: str) -> tuple[BinSpec, ...]:
    """Bins 0.3 m apart along x, slots where the name is empty."""
    return tuple(
        BinSpec(class_name=n, centre_x_m=0.3 * i, centre_y_m=0.0) for i, n in enumerate(names)
    )


def test_every_shipped_cell_resolves_the_shipped_classes_to_the_bins_it_always_had() -> None:
    """The slots of every shipped cell, given the shipped classes in their order, are the bins
    the files used to name (the first slot concrete, then brick, wood, rubber)."""
    for name in ("default", "two_pandas", "line", "suction", "suction_ur10", "wide_gripper"):
        cell = load_cell(name)
        resolved = resolve_cell(cell, shipped_table())
        assert resolved == cell
        for station in resolved.stations:
            assert tuple(b.class_name for b in station.bins) == SHIPPED
            xs = [b.centre_x_m for b in station.bins]
            assert xs == sorted(xs)  # upstream first, as the files list them


def test_slots_take_another_datasets_classes_and_leftover_slots_hold_no_bin() -> None:
    line = load_cell("line")
    cell = resolve_cell(line, _table("bricks", "concrete", "tiles"))
    for raw, station in zip(line.stations, cell.stations, strict=True):
        assert [b.class_name for b in station.bins] == ["bricks", "concrete", "tiles"]
        assert [b.centre_x_m for b in station.bins] == [b.centre_x_m for b in raw.bins[:3]]
    assert cell.classes == ("bricks", "concrete", "tiles")
    # resolved again, for the shipped classes: the layout is the file's, not the last result
    assert resolve_cell(cell, shipped_table()) == line


def test_a_bins_map_names_slots_for_every_station_or_one() -> None:
    bins = BinsMap(slots={"tiles": 3}, stations={"s6": {"tiles": 0, "bricks": 1}})
    cell = resolve_cell(load_cell("line"), _table("bricks", "concrete", "tiles"), bins=bins)
    s1, s6 = cell.station("s1"), cell.station("s6")
    raw = load_cell("line").station("s1").bins
    assert [(b.class_name, b.centre_x_m) for b in s1.bins] == [
        ("bricks", raw[0].centre_x_m),
        ("concrete", raw[1].centre_x_m),
        ("tiles", raw[3].centre_x_m),
    ]
    assert [b.class_name for b in s6.bins] == ["tiles", "bricks", "concrete"]


def test_fixed_bins_keep_their_class_and_slots_take_the_rest() -> None:
    layout = _layout("", "tiles", "", "")
    assigned = assign_bins(layout, ("bricks", "concrete", "tiles"), {}, where="s")
    assert [(b.class_name, b.centre_x_m) for b in assigned] == [
        ("bricks", 0.0),
        ("tiles", 0.3),
        ("concrete", 0.6),
    ]
    fixed = _layout("tiles", "glass")  # no slots: as the file says, whatever the dataset
    assert assign_bins(fixed, ("bricks",), {}, where="s") == fixed


@pytest.mark.parametrize(
    ("slots", "match"),
    [
        ({"tiles": 7}, r"s: bins: class 'tiles' -> slot 7: the station has 4 bins"),
        ({"bricks": 1}, r"slot 1: that bin is fixed to 'tiles'"),
        ({"tiles": 2}, r"class 'tiles' -> slot 2: the station already has a bin fixed to it"),
        ({"bricks": 2, "concrete": 2}, r"classes 'bricks' and 'concrete' -> slot 2"),
    ],
)
def test_a_map_that_cannot_be_followed_is_refused(slots: dict[str, int], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        assign_bins(_layout("", "tiles", "", ""), ("bricks", "concrete", "tiles"), slots, where="s")


def test_more_classes_than_slots_names_the_station_and_the_counts() -> None:
    five = _table("a", "b", "c", "d", "e")
    with pytest.raises(
        CellError,
        match=r"scenario\.yaml: the cell .*two_pandas\.yaml: stations\[0\] \(upstream\): 5 "
        r"classes to sort \(a, b, c, d, e\) but 4 bin slot\(s\) \(of 4 bins, 0 fixed to a "
        r"class\): 1 class\(es\) without a bin \(e\)",
    ):
        resolve_cell(load_cell("two_pandas"), five, where="scenario.yaml")
    # read without a dataset (not strict), the first classes take the slots
    loose = resolve_cell(load_cell("two_pandas"), five, strict=False)
    assert loose.classes == ("a", "b", "c", "d")
