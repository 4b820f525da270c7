"""The tool a station's robot carries, as the controller plans with it: one module per kind.

The cell file describes the tool (:mod:`interfaces.tools`); :func:`make_tool` gives the
controller's side of it, a :class:`ControllerTool`. The pick sequence, the scheduler and the
node ask the tool what they need (its command values, whether it holds something, whether an
object fits, the footprint that must be free around a grasp, its grasp symmetry) and nothing
else in the controller knows what kind of tool it is.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol

from control.errors import ControlConfigError
from interfaces.tools import ToolSpec


@dataclass(frozen=True, kw_only=True)
class Footprint:
    """A rectangle about the grasp point that must be free of other objects.

    Aligned with the target: ``half_along_m`` along its long side, ``half_across_m`` across it
    (the grasp yaw's direction). An object blocks the grasp when its footprint overlaps the
    rectangle and, with ``clear_above_tcp_m`` given, its top reaches that high above the grasp
    point (less the clearance); None: every object in the rectangle blocks.
    """

    half_along_m: float
    half_across_m: float
    clear_above_tcp_m: float | None = None


class ControllerTool(Protocol):
    """What the controller knows about its tool.

    The command is one number (``/gripper/command``): for a gripper the opening in metres.
    """

    @property
    def grasp_yaw_period_rad(self) -> float:
        """Grasp yaws ``yaw + k * period`` are the same grasp (pi for a parallel gripper)."""
        ...

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The tool's joints in ``/joint_states`` (empty when it reports none)."""
        ...

    @property
    def open_command_m(self) -> float:
        """The command that releases (and keeps the tool ready for the next grasp)."""
        ...

    def measured_m(self, positions_rad: Mapping[str, float]) -> float:
        """The measured command value from the tool's joint positions; NaN when not measured."""
        ...

    def grasp_command_m(self, width_m: float, squeeze_m: float) -> float:
        """The command that grasps an object ``width_m`` across (``squeeze_m`` into it)."""
        ...

    def clip_command_m(self, value_m: float) -> float:
        """``value_m`` limited to the tool's command range (NaN stays NaN)."""
        ...

    def holds_nothing(self, measured_m: float, commanded_m: float, margin_m: float) -> bool:
        """Whether the tool, commanded to grasp, reached the command within ``margin_m``:
        nothing held it back (False when ``measured_m`` is NaN: not measured)."""
        ...

    def misfit(
        self, *, length_m: float, width_m: float, height_m: float, width_margin_m: float
    ) -> str | None:
        """Why an object of this size cannot be grasped (one of
        :data:`control.scheduler.UNTARGETED_REASONS`), or None."""
        ...

    def footprints(self, clearance_m: float) -> tuple[Footprint, ...]:
        """The areas about a grasp point the tool comes down on, each grown by ``clearance_m``."""
        ...


def make_tool(spec: ToolSpec) -> ControllerTool:
    """The controller's side of the tool ``spec`` describes."""
    from control.tools.parallel_jaw import ParallelJaw

    kinds: dict[str, Callable[[ToolSpec], ControllerTool]] = {"parallel_jaw": ParallelJaw}
    factory = kinds.get(spec.kind)
    if factory is None:
        msg = f"tool.kind = {spec.kind!r}: the controller has no model of this tool kind"
        raise ControlConfigError(msg)
    return factory(spec)


__all__ = ["ControllerTool", "Footprint", "make_tool"]
