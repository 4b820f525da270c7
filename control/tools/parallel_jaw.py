"""The parallel-jaw gripper as the controller plans with it (the Panda hand, the xArm gripper,
the wide flange gripper).

Its command is the opening between the fingers in metres, from 0 to ``max_opening_m``. The
twin reports each finger joint as half the opening, whatever the gripper's own joint map, so
the measured opening is twice the mean of the finger joints. A grasp closes to the object's
width less a squeeze; fingers that close to within a margin of that command met nothing. An
object fits when its narrow side is narrower than the opening (less a margin) and it stands as
tall as the finger pads. The open fingers and the hand need room around the grasp point. The
fingers grasp below the object's top (``pick.grasp_below_top_m``; on a tipped or propped piece
lowered by the reported suction point's depth below the top), and the sequence dwells there
before closing (the reference's grasp rule), with the pick configuration's timing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from control.tools import Footprint, GraspTiming, suction_point_depth_m
from interfaces.tools import ParallelJawSpec

if TYPE_CHECKING:
    from control.config_sections import PickConfig
    from control.tracking import Track


@dataclass(frozen=True)
class ParallelJaw:
    """Controller side of a :class:`~interfaces.tools.ParallelJawSpec`."""

    spec: ParallelJawSpec

    grasp_yaw_period_rad: ClassVar[float] = math.pi
    """The fingers grasp the same at ``yaw`` and ``yaw + pi``."""

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The finger joints."""
        return self.spec.joints

    @property
    def urdf_joint_names(self) -> tuple[str, ...]:
        """The finger joints: they are the station URDF's."""
        return self.spec.joints

    @property
    def open_command(self) -> float:
        """Fully open (m)."""
        return self.spec.max_opening_m

    def measured(self, positions: Mapping[str, float]) -> float:
        """The opening (m): twice the mean of the finger joints (each reports half of it).

        NaN when a finger joint is missing or not finite.
        """
        names = self.spec.joints
        fingers = [positions[n] for n in names if n in positions]
        if not fingers or len(fingers) != len(names):
            return math.nan
        opening = 2.0 * sum(fingers) / len(fingers)
        return opening if math.isfinite(opening) else math.nan

    def grasp_command(self, width_m: float, squeeze_m: float) -> float:
        """The object's width less ``squeeze_m``, within the opening range (m)."""
        return float(np.clip(width_m - squeeze_m, 0.0, self.spec.max_opening_m))

    def clip_command(self, value: float) -> float:
        """``value`` within ``[0, max_opening_m]``."""
        return float(np.clip(value, 0.0, self.spec.max_opening_m))

    def holds_nothing(self, measured: float, commanded: float, margin_m: float) -> bool:
        """Closed to within ``margin_m`` of the command: no object holds the fingers apart."""
        if not math.isfinite(measured):
            return False
        return measured - commanded < margin_m

    def grasp_complete(self, measured: float) -> bool:
        """Never: the fingers' opening does not tell when the grip holds; the close is timed."""
        del measured
        return False

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
        """``too_wide`` when the narrow side does not fit the opening less ``width_margin_m``;
        ``too_flat`` when the object is lower than the finger pads; else None."""
        del face_radius_m, face_tilt_rad
        if min(width_m, length_m) > (self.spec.max_opening_m - width_margin_m):
            return "too_wide"
        if height_m < self.spec.pad_height_m:
            return "too_flat"
        return None

    def grasp_offset_m(self, track: Track) -> tuple[float, float]:
        """The jaws close about the object's centre, unless the camera's suction point (the
        centre of the largest disc on the top face) lies further from it than that disc's
        radius: then the centre may lie off the piece (a bent or hooked piece's centroid is in
        its crook, where the jaws close on nothing), and they close about the suction point,
        which is on it."""
        dx_m, dy_m = track.suction_offset_m
        if math.hypot(dx_m, dy_m) > track.suction_radius_m:  # False for NaN
            return (dx_m, dy_m)
        return (0.0, 0.0)

    def grasp_drop_m(self, track: Track) -> float:
        """The reported suction point's depth below the top (not below 0); none reported: 0.
        On a piece propped on another the top is its raised end and its middle, where the
        jaws close, lies that much lower (about where its upturned face's centre is): from a
        height measured from the top the fingers would close above it."""
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
        """The lesser of the opening's room around the narrow side (less ``width_margin_m``)
        and the object's height above the finger pads."""
        del face_radius_m
        room = self.spec.max_opening_m - width_margin_m - min(width_m, length_m)
        return min(room, height_m - self.spec.pad_height_m)

    def holds(self, class_name: str, mass_kg: float, acceleration_mps2: float) -> bool:
        """True: the controller has no model of the jaws' friction on the object (the twin
        checks a gripper with a grip force for slip)."""
        del class_name, mass_kg, acceleration_mps2
        return True

    def grasp_height_m(self, height_m: float, pick: PickConfig) -> float:
        """``pick.grasp_below_top_m`` below the top, but not below
        ``pick.grasp_height_fraction`` of the height nor ``pick.min_grasp_height_m``."""
        return max(
            height_m - pick.grasp_below_top_m,
            height_m * pick.grasp_height_fraction,
            pick.min_grasp_height_m,
        )

    def footprints(self, clearance_m: float) -> tuple[Footprint, Footprint]:
        """The open fingers' rectangle (any object in it blocks) and the hand's (objects whose
        top reaches the palm block).

        Fingers: across the object as wide as the open gripper plus two finger depths, along it
        a finger's width. Hand: ``hand_width_m`` across, ``hand_depth_m`` along, its palm
        ``palm_above_tcp_m`` above the grasp point. Each grown by ``clearance_m``.
        """
        s = self.spec
        fingers = Footprint(
            half_along_m=s.finger_width_m / 2 + clearance_m,
            half_across_m=s.max_opening_m / 2 + s.finger_depth_m + clearance_m,
        )
        hand = Footprint(
            half_along_m=s.hand_depth_m / 2 + clearance_m,
            half_across_m=s.hand_width_m / 2 + clearance_m,
            clear_above_tcp_m=s.palm_above_tcp_m,
        )
        return fingers, hand

    def timing(self, pick: PickConfig) -> GraspTiming:
        """The pick configuration's dwell, close, overlap and release."""
        return GraspTiming(
            dwell_s=pick.dwell_s,
            close_s=pick.close_s,
            close_overlap_s=pick.close_overlap_s,
            release_s=pick.release_s,
        )
