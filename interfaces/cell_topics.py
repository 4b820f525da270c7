"""Every topic of one cell on the wire: the contract's (:func:`interfaces.contract.
resolved_topics`, each station's under its namespace) and each camera's three
(:func:`interfaces.camera_topics.camera_topics`). What the recording and the live view open a
channel for."""

from __future__ import annotations

from interfaces.camera_topics import camera_topics
from interfaces.cell import Cell
from interfaces.contract import Topic, resolved_topics

__all__ = ["cell_topics"]


def cell_topics(cell: Cell) -> list[tuple[str, Topic]]:
    """``(wire name, topic)`` of every topic of ``cell``: the contract's, then the cameras'."""
    out = resolved_topics(tuple(s.namespace for s in cell.stations))
    for spec in cell.cameras:
        out.extend((t.name, t) for t in camera_topics(spec.name).all)
    return out
