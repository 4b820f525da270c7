"""Bins: where a station puts the pieces of each class, and how its slots take a dataset's classes.

A bin (:class:`BinSpec`) is an open-top box on the floor beside the belt. In a cell file a bin
either names the class it sorts (``class_name``: fixed) or names none: then it is a *slot*,
which takes one of the dataset's classes when an episode starts (:func:`assign_bins`): the
classes of the dataset's class table (:mod:`interfaces.materials`) that no bin of the station
is fixed to go into its slots in the table's order, or into the slot a scenario's ``bins:``
map names (:class:`BinsMap`); slots left over hold no bin. A station with slots and more
classes to sort than free slots is refused, naming the station and the counts. The shipped
cells' bins are all slots, so any dataset runs on them; the four shipped classes in their
shipped order take them exactly as the files used to name them.

A scenario's ``bins:`` map::

    bins:
      slots: {tiles: 0, bricks: 2}      # at every station: class -> slot (index in its bins)
      stations:
        s6: {tiles: 1}                   # at station s6 only (replaces slots' entry there)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

from interfaces.errors import ConfigError, cut, require

MAX_COORDINATE_M = 10_000.0
"""Largest absolute world coordinate of anything in a cell (also :mod:`interfaces.cell`'s)."""


@dataclass(frozen=True, kw_only=True)
class BinSpec:
    """An open-top bin on the floor; objects dropped into it are sorted as ``class_name``.

    An empty ``class_name`` makes it a slot: :func:`assign_bins` gives it a class of the
    dataset when an episode starts. ``drop_z_m`` is the TCP height a controller releases at
    above the bin's centre.
    """

    class_name: str = ""
    centre_x_m: float
    centre_y_m: float
    size_m: float = 0.24
    top_z_m: float = -0.10
    floor_z_m: float = -0.40
    wall_m: float = 0.01
    drop_z_m: float = 0.15

    def __post_init__(self) -> None:
        require(
            len(self.class_name) <= 64 and self.class_name.isprintable(),
            "bins.class_name",
            self.class_name,
            "up to 64 printable characters (none: a slot the dataset's classes fill)",
        )
        key = f"bins[{self.class_name or 'slot'}]"
        require(self.wall_m > 0, f"{key}.wall_m", self.wall_m, "must be positive")
        require(
            self.size_m > 2 * self.wall_m,
            f"{key}.size_m",
            self.size_m,
            "must exceed twice the wall thickness",
        )
        require(self.size_m <= 10.0, f"{key}.size_m", self.size_m, "must be at most 10 m")
        require(
            self.top_z_m > self.floor_z_m, f"{key}.top_z_m", self.top_z_m, "must be above floor"
        )
        require(
            self.drop_z_m > self.top_z_m,
            f"{key}.drop_z_m",
            self.drop_z_m,
            "must be above the bin's top (top_z_m): the object is released over the bin",
        )
        for name in ("centre_x_m", "centre_y_m", "top_z_m", "floor_z_m", "drop_z_m"):
            value: float = getattr(self, name)
            require(
                abs(value) <= MAX_COORDINATE_M,
                f"{key}.{name}",
                value,
                f"must be within +-{MAX_COORDINATE_M:g} m",
            )

    @property
    def slot(self) -> bool:
        """Whether the bin is a slot (no class of its own yet)."""
        return not self.class_name

    @property
    def half_m(self) -> float:
        """Half the bin's outer side."""
        return 0.5 * self.size_m

    @property
    def inner_half_m(self) -> float:
        """Half the side of the bin's inner area (inside the walls)."""
        return 0.5 * self.size_m - self.wall_m

    def contains_xy(self, x_m: float, y_m: float) -> bool:
        """Whether a point lies over the bin's inner area."""
        half = self.inner_half_m
        return abs(x_m - self.centre_x_m) <= half and abs(y_m - self.centre_y_m) <= half

    @property
    def drop_point_m(self) -> tuple[float, float, float]:
        """Where a controller releases an object over this bin (world frame)."""
        return (self.centre_x_m, self.centre_y_m, self.drop_z_m)


MAX_SLOT = 1000
"""Largest slot index a ``bins:`` map may name."""


def _check_slots(key: str, slots: Mapping[str, int]) -> None:
    for name, index in slots.items():
        require(
            0 <= index <= MAX_SLOT,
            f"{key}.{name}",
            index,
            f"a slot is the index of a bin in its station's bins list, 0 to {MAX_SLOT}",
        )


@dataclass(frozen=True, kw_only=True)
class BinsMap:
    """A scenario's ``bins:``: which slot each class goes to (a slot is the index of a bin in
    its station's ``bins`` list, from 0). ``slots`` holds at every station with slots;
    ``stations`` at the station it names, replacing ``slots``' entry for the same class
    there. A class named nowhere takes the next free slot in the class table's order."""

    slots: dict[str, int] = field(default_factory=dict)
    stations: dict[str, dict[str, int]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _check_slots("bins.slots", self.slots)
        for station, slots in self.stations.items():
            _check_slots(f"bins.stations.{station}", slots)

    def at(self, station: str) -> dict[str, int]:
        """Class -> slot at ``station``: ``slots`` with that station's entries over it."""
        return {**self.slots, **self.stations.get(station, {})}

    def classes(self) -> tuple[str, ...]:
        """Every class the map names, once."""
        seen = dict.fromkeys(self.slots)
        for slots in self.stations.values():
            seen.update(dict.fromkeys(slots))
        return tuple(seen)


def _names(names: Sequence[str], shown: int = 8) -> str:
    text = ", ".join(names[:shown])
    return text + (f", ... ({len(names)} in all)" if len(names) > shown else "")


def assign_bins(
    layout: Sequence[BinSpec],
    classes: Sequence[str],
    slots: Mapping[str, int],
    *,
    where: str,
    strict: bool = True,
) -> tuple[BinSpec, ...]:
    """One station's bins: ``layout`` (its bins as the cell file lists them, slots without a
    class) with each slot given a class.

    ``classes`` are the classes to sort, in order (the dataset's, in its class table's order);
    those a bin of ``layout`` is fixed to keep it; ``slots`` puts a class into the slot it
    names; the others take the free slots in order; a slot left over is dropped. Without
    slots, ``layout`` as it is. ``where`` (the station: ``stations[i] (name)``) starts every
    :class:`ConfigError`: a slot out of range or fixed to another class, two classes in one
    slot, or (``strict``) more classes to sort than free slots (naming the counts); not
    ``strict`` (a cell read without a dataset), the classes left over get no bin.
    """
    free = [i for i, b in enumerate(layout) if b.slot]
    if not free:
        return tuple(layout)
    fixed = {b.class_name: i for i, b in enumerate(layout) if not b.slot}
    assigned: dict[int, str] = {}
    for name, index in slots.items():
        if name not in classes:
            continue  # a class this episode does not sort (the map is checked with the scenario)
        if index >= len(layout):
            msg = (
                f"{where}: bins: class {name!r} -> slot {index}: the station has "
                f"{len(layout)} bins (slots 0 to {len(layout) - 1})"
            )
            raise ConfigError(msg)
        taken = layout[index].class_name
        if taken == name:
            continue
        if taken:
            msg = f"{where}: bins: class {name!r} -> slot {index}: that bin is fixed to {taken!r}"
            raise ConfigError(msg)
        if name in fixed:
            msg = (
                f"{where}: bins: class {name!r} -> slot {index}: the station already has a bin "
                f"fixed to it (bins[{fixed[name]}])"
            )
            raise ConfigError(msg)
        if index in assigned:
            msg = (
                f"{where}: bins: classes {assigned[index]!r} and {name!r} -> slot {index}: "
                "one class per bin"
            )
            raise ConfigError(msg)
        assigned[index] = name
    rest = [c for c in classes if c not in fixed and c not in assigned.values()]
    open_slots = [i for i in free if i not in assigned]
    if strict and len(rest) > len(open_slots):
        to_sort = [c for c in classes if c not in fixed]
        left = rest[len(open_slots) :]
        msg = (
            f"{where}: {len(to_sort)} classes to sort ({_names(to_sort)}) but "
            f"{len(free)} bin slot(s) (of {len(layout)} bins, {len(fixed)} fixed to a class): "
            f"{len(left)} class(es) without a bin ({_names(left)}); give the station more "
            "bins, or let fewer classes in (objects.classes)"
        )
        raise ConfigError(msg)
    assigned.update(zip(open_slots, rest, strict=False))
    return tuple(
        replace(b, class_name=assigned[i]) if b.slot else b
        for i, b in enumerate(layout)
        if not b.slot or i in assigned
    )


def check_map(bins: BinsMap, classes: Sequence[str], stations: Sequence[str], where: str) -> None:
    """A ``bins:`` map names only ``classes`` (the dataset's) and ``stations`` (the cell's);
    :class:`ConfigError` naming ``where`` and the key otherwise."""
    for name in bins.classes():
        if name not in classes:
            msg = (
                f"{where}: bins: class {cut(name)} is not a class of the dataset "
                f"(its classes: {_names(list(classes))})"
            )
            raise ConfigError(msg)
    for station in bins.stations:
        if station not in stations:
            msg = (
                f"{where}: bins.stations.{cut(station)}: not a station of the cell "
                f"(its stations: {_names(list(stations))})"
            )
            raise ConfigError(msg)


__all__ = ["BinSpec", "BinsMap", "assign_bins", "check_map"]
