"""The line's claims on the wire: each station's ``line/claim`` onto the board, the board out.

The board itself (:class:`twin.claims.ClaimsBoard`) is pure logic: one entry per station and
track, every field checked, bounded per station and in total. This relay converts a ``Claim``
message to the board's fields and publishes the whole board on ``/line/claims`` after every
step in which it changed (and, once one was relayed, at least every :data:`CLAIMS_REFRESH_S`).
The twin only relays: it allocates nothing.
"""

from __future__ import annotations

from typing import Any

from builtin_interfaces.msg import Time
from cdw_interfaces.msg import Claim, ClaimArray

from interfaces.ros import msg_stamp_s
from twin.claims import ClaimFields, ClaimsBoard
from twin.commands import Rejected
from twin.encoders import WORLD
from twin.tapped_wire import TappedWire

CLAIMS_REFRESH_S = 1.0
"""Longest sim time between two relays of the claims board once one was relayed."""


class ClaimsRelay:
    """The claims board of a line and its ``/line/claims`` publisher (``publisher``, made on
    ``io``); ``dt_s`` is the twin's step."""

    def __init__(self, io: TappedWire, publisher: Any, board: ClaimsBoard, *, dt_s: float) -> None:
        self.io = io
        self.publisher = publisher
        self.board = board
        self._sent = False
        self._refresh_steps = max(1, round(CLAIMS_REFRESH_S / dt_s))

    def offer(self, station_index: int, station_name: str, msg: Claim) -> Rejected | None:
        """A station's claim goes on the board when every field passes
        :meth:`twin.claims.ClaimsBoard.offer`; else why not (``bad_claim`` or ``claims_full``).
        The relayed message names the station it came from, whatever it said."""
        p, v = msg.position, msg.velocity
        fields = ClaimFields(
            station=msg.station,
            track_id=int(msg.track_id),
            class_name=msg.class_name,
            frame_id=msg.header.frame_id,
            stamp_s=msg_stamp_s(msg.header.stamp),
            position_m=(p.x, p.y, p.z),
            velocity_mps=(v.x, v.y, v.z),
            radius_m=msg.radius_m,
            state=msg.state,
        )
        msg.station = station_name
        refusal = self.board.offer(station_index, fields, msg)
        if refusal is None:
            return None
        if refusal.reason == "claims_full":
            return Rejected("claims_full", refusal.detail)
        return Rejected("bad_claim", refusal.detail)

    def publish(self, stamp: Time, step: int) -> bool:
        """``/line/claims`` after step ``step``: the whole board, ordered by station then track,
        when it changed since the last relay, and once a board was relayed at least every
        :data:`CLAIMS_REFRESH_S` (a restarted controller, which missed the earlier boards, then
        gets one to wait for); ``released`` and ``picked`` entries are relayed once and
        dropped. Returns whether a board was sent."""
        refresh = self._sent and step % self._refresh_steps == 0
        if not (self.board.changed or refresh):
            return False
        self._sent = True
        msg = ClaimArray()
        msg.header.stamp = stamp
        msg.header.frame_id = WORLD
        msg.claims = self.board.take()
        self.io.send(self.publisher, msg)
        return True


__all__ = ["CLAIMS_REFRESH_S", "ClaimsRelay"]
