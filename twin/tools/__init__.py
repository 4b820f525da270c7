"""The tools a station's robot carries, twin side: one module per kind of tool.

A tool is built on its robot's PyBullet body (:func:`make_tool`) and owns everything about the
end effector the twin simulates: the command (a number a controller sends on the station's
``gripper/command``) and the tool joints it drives, what the tool reports on the station's
``joint_states``, the TCP, which of its links make contact for a grasp, and the grasp rule
itself (when a touched object becomes held, when it is let go). The monitor asks the tool;
it knows nothing of fingers. Each kind's shared description is in :mod:`interfaces.tools`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Protocol

from interfaces.tools import ParallelJawSpec, ToolSpec

if TYPE_CHECKING:
    from twin.robot import Robot

Pose = tuple[tuple[float, float, float], tuple[float, float, float, float]]
"""A position and an xyzw orientation, world frame."""

Normal = tuple[float, float, float]
"""A contact normal, world frame."""


class Tool(Protocol):
    """What the twin needs of a station's tool."""

    spec: ToolSpec
    tcp_link: int
    """The link the TCP is attached to (a held object is fixed to it)."""
    contact_links: Mapping[int, int]
    """PyBullet link index -> index in ``spec.links`` of every link whose contacts decide a
    grasp (the fingers)."""
    joint_names: tuple[str, ...]
    """The tool joints the station's ``joint_states`` reports after the arm's."""
    max_command: float
    """The largest command value (a parallel jaw: its full opening in m; the least is 0)."""
    engaged_radius_m: float
    """Horizontal distance from the TCP within which a touched object counts as being handled
    (no unintended contact)."""

    def reset_state(self) -> None:
        """Put the tool in its start state (a gripper open); the motors follow on :meth:`apply`."""

    def command(self, value: float) -> None:
        """Set the tool's target (clipped to ``[0, max_command]``); applied by :meth:`apply`."""

    def apply(self) -> None:
        """Hand the current target to the tool's joint motors (only when it changed)."""

    def measured(self) -> float:
        """The tool's state in command units, from its joints (a gripper: its opening, m)."""

    def joint_report(self) -> tuple[list[float], list[float]]:
        """Positions and velocities the station's ``joint_states`` carries for ``joint_names``."""

    def tcp_pose(self) -> Pose:
        """The TCP's pose in the world frame (forward kinematics now)."""

    def link_pose(self) -> Pose:
        """The pose of ``tcp_link``'s frame in the world frame (forward kinematics now)."""

    def contact_name(self, index: int) -> str:
        """The name of contact link ``index`` (of ``spec.links``)."""

    def grasps(self, touching: Mapping[int, Normal]) -> bool:
        """Whether the contacts ``touching`` (contact link index -> normal) and the tool's
        state make a grasp (the dwell and the TCP overlap are checked by the monitor)."""

    def releases(self) -> bool:
        """Whether a held object is let go now."""


def make_tool(spec: ToolSpec, robot: Robot) -> Tool:
    """The twin's tool of ``spec``'s kind, built on ``robot``'s body."""
    if isinstance(spec, ParallelJawSpec):
        from twin.tools.parallel_jaw import ParallelJaw

        return ParallelJaw(spec, robot)
    msg = f"tool {spec.name!r}: no twin model for tool kind {spec.kind!r}"
    raise NotImplementedError(msg)


__all__ = ["Normal", "Pose", "Tool", "make_tool"]
