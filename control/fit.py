"""Whether a station could take a piece at all, by the rules its controller applies.

A controller leaves a piece untargeted for reasons of two kinds: static ones, that no timing or
clutter changes (no bin for its class, the tool does not fit it, it is too heavy for the tool),
and the rest (too late, out of reach, blocked, claimed...). This module answers the static
question without a simulator, for one piece and one station's
:class:`~control.config.ControllerConfig`: :func:`takeable` hands the scheduler's own check
(:func:`control.scheduler.static_reason`) a certain, confirmed track standing for the piece, so
a piece it refuses is one the station's controller would never target, and the rule cannot
drift from the scheduler's. It is cheap (no mesh, no PyBullet): the twin asks it for every
piece it spawns (``takeable`` on the ``spawned`` event), ``cdw-twin fit`` for every piece of a
dataset.

A :class:`Piece` is what the camera reports of a piece: its class, seen box and the suction
point's disc radius and face tilt (:mod:`twin.suction_point`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from control.config import ControllerConfig
from control.scheduler import static_reason
from control.tracking import Track
from interfaces.untargeted import STATIC_REASONS

REFUSALS: tuple[str, ...] = STATIC_REASONS
"""The static reasons a station refuses a piece, in the order the scheduler checks them."""


@dataclass(frozen=True, kw_only=True)
class Piece:
    """What the camera reports of one piece on the belt, all a station's static rules need.

    ``length_m`` and ``width_m`` are its footprint as seen from above, ``height_m`` its height;
    ``face_radius_m`` the radius of the largest disc on its upturned face and ``face_tilt_rad``
    that face's tilt from level (the detection's ``suction_radius_m``, ``suction_tilt_rad``;
    NaN: none reported, as a camera without a suction-point finder).
    """

    class_name: str
    length_m: float
    width_m: float
    height_m: float
    face_radius_m: float = math.nan
    face_tilt_rad: float = math.nan

    @property
    def narrow_m(self) -> float:
        """The narrow side of the footprint, what a gripper's opening must take."""
        return min(self.length_m, self.width_m)


def piece_track(piece: Piece) -> Track:
    """A confirmed, certain track at rest standing for ``piece`` (what the scheduler judges)."""
    return Track(
        track_id=0,
        stamp_s=0.0,
        class_name=piece.class_name,
        class_confidence=1.0,
        position_m=(0.0, 0.0),
        velocity_mps=(0.0, 0.0),
        position_std_m=0.0,
        yaw_rad=0.0,
        length_m=max(piece.length_m, piece.width_m),
        width_m=piece.narrow_m,
        height_m=piece.height_m,
        hits=1,
        confirmed=True,
        last_update_s=0.0,
        suction_radius_m=piece.face_radius_m,
        suction_tilt_rad=piece.face_tilt_rad,
    )


def takeable(piece: Piece, config: ControllerConfig) -> str | None:
    """Why the station ``config`` drives would never target ``piece`` (one of
    :data:`REFUSALS`), or None when it could take it: the scheduler's
    :func:`~control.scheduler.static_reason` of :func:`piece_track` (a certain detection:
    confidence is not judged)."""
    return static_reason(piece_track(piece), config)


def line_refusal(piece: Piece, configs: Sequence[ControllerConfig]) -> str | None:
    """None when some station of ``configs`` could take ``piece``; otherwise every station's
    reason (:func:`takeable`), the distinct ones in :data:`REFUSALS` order joined by ``+``
    (``too_flat+too_small``: the jaws found it too flat, the cups too small)."""
    reasons: set[str] = set()
    for config in configs:
        reason = takeable(piece, config)
        if reason is None:
            return None
        reasons.add(reason)
    return "+".join(r for r in REFUSALS if r in reasons)


__all__ = ["REFUSALS", "Piece", "line_refusal", "piece_track", "takeable"]
