"""The suction cup as the controller plans with it.

Its command is the vacuum: 1 on, 0 off. The twin reports the vacuum reached, as a fraction of
the nominal vacuum, as the joint ``<name>_vacuum`` of ``joint_states``; a sealed cup reads at
least the seal efficiency of the leakiest surface once the vacuum has built up, an unsealed one
about 0, so a cup that reads less than half of that least efficiency after the build-up (and
through the lift) holds nothing. The cup grasps an object on its top face: the TCP is the
centre of the lip, lowered ``pick.top_press_m`` into the top so that the soft lip seals, at the
suction point the camera reports (where the largest disc fits on the top face) or, where it
reports none, at the footprint's centre. An object fits when that disc (or, without one, the
narrow side) holds the lip's disc with ``width_margin_m`` to spare (less is ``too_small``) and
the face there, as the camera reports its tilt, lies within the lip's ``max_tilt_rad`` less
:data:`TILT_MARGIN_RAD` (more is ``too_tilted``: a piece propped on another); nothing is too
flat or too wide for it. Only the stem's disc comes down
around the grasp point. The sequence does not dwell: the vacuum goes on as the descent to the
top starts (the cup seals as the lip touches), the TCP waits at the top for the seal (the
build-up, plus ``pick.seal_margin_s``; a seal made late, up to another build-up, once the
vacuum reads full), then lifts as soon as the vacuum is full (the seal may be complete before
the TCP reached the top); over the bin it vents for ``vent_s`` plus
``pick.vent_margin_s``. The cup is round: any yaw grasps the same.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from control.tools import Footprint, GraspTiming, suction_point_depth_m
from interfaces.tools import SuctionCupSpec

if TYPE_CHECKING:
    from control.config_sections import PickConfig
    from control.tracking import Track
    from interfaces.materials import ClassTable

VACUUM_ON = 1.0
"""The command that turns the vacuum on."""
VACUUM_OFF = 0.0
"""The command that turns it off (and vents the cup)."""
STANDARD_GRAVITY_MPS2 = 9.81
"""The gravity a carried object's weight is reckoned with."""
VACUUM_FULL = 0.99
"""The vacuum fraction at which the build-up is complete and the cup holds the object (a
vacuum switch's "part present")."""
TILT_MARGIN_RAD = math.radians(3.0)
"""A face is left when its reported tilt comes within this of the lip's limit: the camera's
normal is an estimate, and the lip pressing on a propped piece tilts it further."""


@dataclass(frozen=True)
class SuctionCup:
    """Controller side of a :class:`~interfaces.tools.SuctionCupSpec`; ``materials`` is the
    cell's class table, whose seal efficiencies the holding force takes
    (:meth:`~interfaces.tools.SuctionCupSpec.efficiency`)."""

    spec: SuctionCupSpec
    materials: ClassTable

    grasp_yaw_period_rad: ClassVar[float] = 0.0
    """A round cup: the grasp does not depend on the object's yaw."""

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The vacuum reading, ``<name>_vacuum``."""
        return (self.spec.vacuum_joint,)

    @property
    def urdf_joint_names(self) -> tuple[str, ...]:
        """None: the vacuum reading is no joint of the station's URDF."""
        return ()

    @property
    def open_command(self) -> float:
        """Vacuum off."""
        return VACUUM_OFF

    @property
    def seal_threshold(self) -> float:
        """The vacuum fraction below which the cup holds nothing: half the seal efficiency of
        the leakiest surface it may meet (every class of the cell's table, any other class,
        every class the tool names)."""
        spec, table = self.spec, self.materials
        default = (
            spec.default_seal_efficiency
            if spec.default_seal_efficiency is not None
            else table.default.seal_efficiency
        )
        named = [spec.efficiency(name, table) for name in table.names]
        return 0.5 * min(default, *named, *spec.seal_efficiency.values())

    def measured(self, positions: Mapping[str, float]) -> float:
        """The vacuum fraction reached (0 to 1); NaN when not reported or not finite."""
        value = positions.get(self.spec.vacuum_joint, math.nan)
        return float(value) if math.isfinite(value) else math.nan

    def grasp_command(self, width_m: float, squeeze_m: float) -> float:
        """Vacuum on, whatever the object's width."""
        del width_m, squeeze_m
        return VACUUM_ON

    def clip_command(self, value: float) -> float:
        """``value`` within ``[0, 1]``."""
        return float(np.clip(value, VACUUM_OFF, VACUUM_ON))

    def holds_nothing(self, measured: float, commanded: float, margin_m: float) -> bool:
        """The vacuum is below :attr:`seal_threshold`: nothing sealed the cup."""
        del commanded, margin_m
        if not math.isfinite(measured):
            return False
        return measured < self.seal_threshold

    def grasp_complete(self, measured: float) -> bool:
        """The vacuum has built up (:data:`VACUUM_FULL`): the cup holds the object."""
        return math.isfinite(measured) and measured >= VACUUM_FULL

    def misfit(
        self,
        *,
        length_m: float,
        width_m: float,
        height_m: float,
        width_margin_m: float,
        face_radius_m: float = math.nan,
        face_tilt_rad: float = math.nan,
    ) -> str | None:
        """``too_small`` when the top has no room for the lip's disc with ``width_margin_m``
        to spare (:meth:`fit_margin_m` negative); ``too_tilted`` when the face is tilted
        beyond the lip's limit less :data:`TILT_MARGIN_RAD`; else None (an unknown tilt
        fits)."""
        if face_tilt_rad > self.spec.max_tilt_rad - TILT_MARGIN_RAD:  # False for NaN
            return "too_tilted"
        margin_m = self.fit_margin_m(
            length_m=length_m,
            width_m=width_m,
            height_m=height_m,
            width_margin_m=width_margin_m,
            face_radius_m=face_radius_m,
        )
        return "too_small" if margin_m < 0.0 else None

    def grasp_offset_m(self, track: Track) -> tuple[float, float]:
        """The suction point the camera reports, from the track's position; none reported:
        the centre."""
        dx_m, dy_m = track.suction_offset_m
        if not (math.isfinite(dx_m) and math.isfinite(dy_m)):
            return (0.0, 0.0)
        return (dx_m, dy_m)

    def grasp_drop_m(self, track: Track) -> float:
        """The reported suction point's depth below the top (not below 0); none reported: 0."""
        return suction_point_depth_m(track)

    def fit_margin_m(
        self,
        *,
        length_m: float,
        width_m: float,
        height_m: float,
        width_margin_m: float,
        face_radius_m: float = math.nan,
    ) -> float:
        """The room around the lip (less ``width_margin_m``): across the largest disc on the
        top face where the camera reports one (``face_radius_m``; on a concave or bent piece
        much less than its narrow side), else across the narrow side."""
        del height_m
        room_m = 2.0 * face_radius_m if math.isfinite(face_radius_m) else min(width_m, length_m)
        return room_m - self.spec.cup_diameter_m - width_margin_m

    def holds(self, class_name: str, mass_kg: float, acceleration_mps2: float) -> bool:
        """The sealed cup's holding force on ``class_name`` (vacuum x lip area x the class's
        seal efficiency, as the twin checks it) carries ``mass_kg`` at gravity plus
        ``acceleration_mps2``."""
        load = mass_kg * (STANDARD_GRAVITY_MPS2 + acceleration_mps2)
        return self.spec.holding_force(class_name, self.materials) >= load

    def grasp_height_m(self, height_m: float, pick: PickConfig) -> float:
        """``pick.top_press_m`` below the top (not below the underside)."""
        return max(height_m - pick.top_press_m, 0.0)

    def footprints(self, clearance_m: float) -> tuple[Footprint]:
        """The stem's disc (``body_radius_m``, grown by ``clearance_m``): an object in it whose
        top reaches the lip blocks."""
        radius = self.spec.body_radius_m + clearance_m
        return (
            Footprint(half_along_m=radius, half_across_m=radius, clear_above_tcp_m=0.0, disc=True),
        )

    def timing(self, pick: PickConfig) -> GraspTiming:
        """No dwell; the seal waits for the build-up, the release for the vent."""
        return GraspTiming(
            dwell_s=0.0,
            close_s=self.spec.build_up_s + pick.seal_margin_s,
            close_overlap_s=0.0,
            release_s=self.spec.vent_s + pick.vent_margin_s,
            grasp_on_descent=True,
            close_max_s=2.0 * self.spec.build_up_s + pick.seal_margin_s,
        )
