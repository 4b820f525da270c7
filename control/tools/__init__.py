"""The tool a station's robot carries, as the controller plans with it: one module per kind.

The cell file describes the tool (:mod:`interfaces.tools`); :func:`make_tool` gives the
controller's side of it, a :class:`ControllerTool`. The pick sequence, the scheduler and the
node ask the tool what they need (its command values, whether it holds something, whether an
object fits, where on the object it grasps, the footprint that must be free around a grasp, its
grasp symmetry, how long the sequence waits for it) and nothing else in the controller knows
what kind of tool it is.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from control.errors import ControlConfigError
from interfaces.tools import ParallelJawSpec, SuctionCupSpec, ToolSpec

if TYPE_CHECKING:
    from control.config_sections import PickConfig
    from control.tracking import Track
    from interfaces.materials import ClassTable


@dataclass(frozen=True, kw_only=True)
class Footprint:
    """An area about the grasp point that must be free of other objects.

    A rectangle aligned with the target: ``half_along_m`` along its long side, ``half_across_m``
    across it (the grasp yaw's direction); with ``disc`` a disc of radius ``half_along_m``
    (the same as ``half_across_m``). An object blocks the grasp when its footprint overlaps the
    area and, with ``clear_above_tcp_m`` given, its top reaches that high above the grasp point
    (less the clearance); None: every object in the area blocks.
    """

    half_along_m: float
    half_across_m: float
    clear_above_tcp_m: float | None = None
    disc: bool = False


@dataclass(frozen=True, kw_only=True)
class GraspTiming:
    """How long the pick sequence waits for the tool, s.

    At the grasp point the TCP follows the object for ``dwell_s`` (0: none), then the tool
    acts (closes, or seals) for ``close_s`` while following, the last ``close_overlap_s`` of
    the dwell overlapping the start of that; over the bin it releases for ``release_s``. With
    ``grasp_on_descent`` the tool is commanded to grasp from the start of the descent (a
    suction cup's vacuum is on before the lip touches, so it seals as it does). A tool that
    measures when its grasp is complete (:meth:`ControllerTool.grasp_complete`) lifts as soon
    as it is, and waits for it up to ``close_max_s`` (None: the close ends after ``close_s``).
    """

    dwell_s: float
    close_s: float
    close_overlap_s: float
    release_s: float
    grasp_on_descent: bool = False
    close_max_s: float | None = None

    @property
    def held_after_s(self) -> float:
        """Time (s) from the arrival at the grasp point until the tool holds the object: a tool
        that measures its grasp holds it at the end of its close (a cup: the build-up), a
        gripper at the end of the dwell (the grasp rule checks its grip then). A grasp counts
        only inside the station's pick window, so the object must still be in it then."""
        if self.close_max_s is not None:
            return self.dwell_s - self.close_overlap_s + self.close_s
        return self.dwell_s


class ControllerTool(Protocol):
    """What the controller knows about its tool.

    The command is one number (``gripper/command``): a gripper's opening in metres, a suction
    cup's vacuum (1 on, 0 off). The measured value is in the same unit.
    """

    @property
    def grasp_yaw_period_rad(self) -> float:
        """Grasp yaws ``yaw + k * period`` are the same grasp (pi for a parallel gripper); 0:
        the grasp does not depend on the object's yaw (any yaw of the tool will do)."""
        ...

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The tool's joints in ``joint_states`` (empty when it reports none)."""
        ...

    def grasp_offset_m(self, track: Track) -> tuple[float, float]:
        """Where on the object the tool grasps: ``(dx, dy)`` from the track's position, world
        frame (a gripper: its centre; a suction cup: the suction point the camera reports)."""
        ...

    def grasp_drop_m(self, track: Track) -> float:
        """How far below the object's top the tool grasps at its grasp point, before
        :meth:`grasp_height_m` (a suction cup: the reported suction point's depth below the top,
        where a tipped piece's upturned face slopes down; a gripper: 0)."""
        ...

    @property
    def urdf_joint_names(self) -> tuple[str, ...]:
        """Those of :attr:`joint_names` that are joints of the station's URDF (a gripper's
        fingers; a suction cup's vacuum reading is not a joint of any model)."""
        ...

    @property
    def open_command(self) -> float:
        """The command that releases (and keeps the tool ready for the next grasp)."""
        ...

    def measured(self, positions: Mapping[str, float]) -> float:
        """The measured command value from the tool's joint positions; NaN when not measured."""
        ...

    def grasp_command(self, width_m: float, squeeze_m: float) -> float:
        """The command that grasps an object ``width_m`` across (``squeeze_m`` into it)."""
        ...

    def clip_command(self, value: float) -> float:
        """``value`` limited to the tool's command range (NaN stays NaN)."""
        ...

    def holds_nothing(self, measured: float, commanded: float, margin_m: float) -> bool:
        """Whether the tool, commanded to grasp, holds nothing by its measurement (False when
        ``measured`` is NaN: not measured). ``margin_m``: a gripper's closing margin."""
        ...

    def grasp_complete(self, measured: float) -> bool:
        """Whether the measurement shows the grasp complete, the object held (a cup's vacuum
        built up); False when the tool cannot tell (a gripper: its close is timed) or
        ``measured`` is NaN."""
        ...

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
        """Why an object of this size cannot be grasped (one of
        :data:`interfaces.untargeted.UNTARGETED_REASONS`), or None. ``face_radius_m`` is the
        radius of the largest disc on its top face the camera reports and ``face_tilt_rad``
        that face's tilt from level (NaN: none)."""
        ...

    def fit_margin_m(
        self,
        *,
        length_m: float,
        width_m: float,
        height_m: float,
        width_margin_m: float,
        face_radius_m: float = math.nan,
    ) -> float:
        """How much room the tool has on the object's tightest dimension, m (negative: it does
        not fit); comparable between tools, for leaving an object to the one that fits it
        better."""
        ...

    def holds(self, class_name: str, mass_kg: float, acceleration_mps2: float) -> bool:
        """Whether the tool can carry an object of ``class_name`` and ``mass_kg`` at
        ``acceleration_mps2`` on top of gravity (a tool that holds by force checks it; a
        gripper with no such model says True)."""
        ...

    def grasp_height_m(self, height_m: float, pick: PickConfig) -> float:
        """Height of the grasp point (the TCP at the grasp) above the underside of an object
        ``height_m`` tall."""
        ...

    def footprints(self, clearance_m: float) -> tuple[Footprint, ...]:
        """The areas about a grasp point the tool comes down on, each grown by ``clearance_m``."""
        ...

    def timing(self, pick: PickConfig) -> GraspTiming:
        """The pick sequence's waits for this tool."""
        ...


def suction_point_depth_m(track: Track) -> float:
    """How far the track's reported suction point lies below its top (not below 0); 0 when
    none is reported. On a tipped or propped piece the upturned face slopes down from the top,
    and the piece's middle lies about that much lower than its top."""
    below_m = track.suction_below_top_m
    return max(below_m, 0.0) if math.isfinite(below_m) else 0.0


def make_tool(spec: ToolSpec, materials: ClassTable) -> ControllerTool:
    """The controller's side of the tool ``spec`` describes (by its ``kind``); ``materials``
    is the cell's class table (a suction cup's seal efficiency per class)."""
    from control.tools.parallel_jaw import ParallelJaw
    from control.tools.suction_cup import SuctionCup

    if spec.kind == "parallel_jaw" and isinstance(spec, ParallelJawSpec):
        return ParallelJaw(spec)
    if spec.kind == "suction_cup" and isinstance(spec, SuctionCupSpec):
        return SuctionCup(spec, materials)
    msg = f"tool.kind = {spec.kind!r}: the controller has no model of this tool kind"
    raise ControlConfigError(msg)


__all__ = ["ControllerTool", "Footprint", "GraspTiming", "make_tool", "suction_point_depth_m"]
