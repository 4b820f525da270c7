"""The tools a station's robot carries, twin side: one module per kind of tool.

A tool is built on its robot's PyBullet body (:func:`make_tool`) and owns everything about the
end effector the twin simulates: the command (a number a controller sends on the station's
``gripper/command``) and the tool joints it drives, what the tool reports on the station's
``joint_states``, the TCP, which of its links make contact for a grasp, the grasp rule itself
(when an object under the TCP becomes held, :meth:`Tool.grasps`) and the carry (every step an
object is held, whether it is still held or let go and why, :meth:`Tool.carry`). The monitor
asks the tool; it knows nothing of fingers or vacuum. Each kind's shared description is in
:mod:`interfaces.tools`.

Drop reasons (:meth:`Tool.carry`): ``released`` (the tool let go as commanded), ``slipped``
(a jaw's friction could not carry the load), ``suction_overload`` (a suction cup's holding force
could not), ``seal_lost`` (the object moved off a suction cup's lip).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
import numpy.typing as npt
import pybullet as pb

from interfaces.tools import ParallelJawSpec, SuctionCupSpec, ToolSpec

if TYPE_CHECKING:
    from interfaces.materials import ClassTable
    from twin.robot import Robot

Pose = tuple[tuple[float, float, float], tuple[float, float, float, float]]
"""A position and an xyzw orientation, world frame."""

Normal = tuple[float, float, float]
"""A contact normal, world frame."""

FloatArray = npt.NDArray[np.float64]

RELEASED = "released"
SLIPPED = "slipped"
SUCTION_OVERLOAD = "suction_overload"
SEAL_LOST = "seal_lost"
DROP_REASONS = (RELEASED, SLIPPED, SUCTION_OVERLOAD, SEAL_LOST)
"""Why a held object is let go (``pick_dropped``'s ``reason``)."""


@dataclass(frozen=True)
class Candidate:
    """An object the TCP box of a free tool overlaps, at one physics step (what a grasp rule
    may look at).

    ``touching``: contact link index -> contact normal of every contact link touching it;
    ``overlap_s``: how long the TCP box has overlapped it; ``tcp_pose``: the tool's TCP at this
    step; ``mesh_pose``: its mesh frame's
    pose in the world; ``triangles``: its mesh's triangles ``(n, 3, 3)`` in the mesh frame (m,
    scaled to its height), the same array for every object of ``shape_key``.
    """

    object_id: int
    time_s: float
    overlap_s: float
    touching: Mapping[int, Normal]
    tcp_pose: Pose
    shape_key: tuple[str, float]
    mesh_pose: Callable[[], Pose]
    triangles: Callable[[], FloatArray]


@dataclass(frozen=True)
class HeldObject:
    """The object a tool holds: what the carry checks need (mass kg, friction coefficient as
    spawned)."""

    object_id: int
    body: int
    class_name: str
    mass_kg: float
    friction: float


class Tool(Protocol):
    """What the twin needs of a station's tool."""

    @property
    def spec(self) -> ToolSpec:
        """The tool's description."""

    @property
    def tcp_link(self) -> int:
        """The link the TCP is attached to (a held object is fixed to it)."""

    @property
    def contact_links(self) -> Mapping[int, int]:
        """PyBullet link index -> index in the tool's contact names of every link whose
        contacts decide a grasp (a jaw's fingers; none for a suction cup)."""

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The names the station's ``joint_states`` reports for the tool, after the arm's."""

    @property
    def max_command(self) -> float:
        """The largest command value (a parallel jaw: its full opening in m; a suction cup:
        1, vacuum on; the least is 0)."""

    @property
    def engaged_radius_m(self) -> float:
        """Horizontal distance from the TCP within which a touched object counts as being
        handled (no unintended contact)."""

    def reset_state(self) -> None:
        """Put the tool in its start state (a gripper open, a cup vented); the motors follow on
        :meth:`apply`."""

    def command(self, value: float) -> None:
        """Set the tool's target (clipped to ``[0, max_command]``); applied by :meth:`apply`."""

    def apply(self) -> None:
        """Hand the current target to the tool's joint motors (only when it changed)."""

    def measured(self) -> float:
        """The tool's state in command units (a gripper: its opening, m; a cup: its vacuum as a
        fraction of full vacuum)."""

    def joint_report(self) -> tuple[list[float], list[float]]:
        """Positions and velocities the station's ``joint_states`` carries for ``joint_names``."""

    def tcp_pose(self) -> Pose:
        """The TCP's pose in the world frame (forward kinematics now)."""

    def link_pose(self) -> Pose:
        """The pose of ``tcp_link``'s frame in the world frame (forward kinematics now)."""

    def contact_name(self, index: int) -> str:
        """The name of contact link ``index``."""

    def tick(self, time_s: float) -> None:
        """Once per physics step, before the monitor evaluates it (the step ending at
        ``time_s``)."""

    def grasps(self, candidate: Candidate) -> bool:
        """Whether the tool grasps ``candidate`` at this step (the monitor adds the pick window
        and credits one object per step: the one nearest the TCP)."""

    def hold(self, held: HeldObject, time_s: float) -> None:
        """The monitor fixed ``held`` to the TCP."""

    def carry(self, time_s: float) -> str | None:
        """Every step the tool holds an object: None while it holds, else why it lets it go
        (one of :data:`DROP_REASONS`)."""

    def release(self) -> None:
        """The held object is no longer held (let go, or out of the scene)."""


ACCELERATION_WINDOW_S = 0.02
"""The TCP's acceleration is its velocity change over this long: the joint motors settle a new
target within a physics step or two, and a per-step difference sees those one-step transients
as accelerations no object in the tool would feel."""


class TcpAccelerometer:
    """The TCP's measured acceleration: the change of the TCP link's velocity (PyBullet) over
    the last :data:`ACCELERATION_WINDOW_S`, what the carry checks load the held object with.

    The tool samples it every physics step (:meth:`sample`, from its ``tick``), held or not, so
    the window is full from the first step of a carry: fixing the object to the TCP makes the
    arm's velocity jump within one step, and a difference over that step alone would load the
    object with an acceleration no object in the tool would feel.
    """

    def __init__(self, body: int, link: int, client: int) -> None:
        self.body, self.link, self.client = body, link, client
        self._samples: deque[tuple[float, tuple[float, float, float]]] = deque()

    def reset(self) -> None:
        """Forget the samples (the next acceleration is 0)."""
        self._samples.clear()

    def sample(self, time_s: float) -> None:
        """Record the TCP's velocity at ``time_s`` (once per time; samples older than the
        window needs are dropped)."""
        state = pb.getLinkState(
            self.body, self.link, computeLinkVelocity=1, physicsClientId=self.client
        )
        velocity: tuple[float, float, float] = state[6]
        samples = self._samples
        while len(samples) > 1 and samples[1][0] <= time_s - ACCELERATION_WINDOW_S + 1e-9:
            samples.popleft()
        if samples and samples[-1][0] == time_s:
            samples.pop()
        samples.append((time_s, velocity))

    def magnitude(self, time_s: float) -> float:
        """``|a|`` (m/s^2) at ``time_s``: over the window, or since the first sample."""
        self.sample(time_s)
        t0, v0 = self._samples[0]
        t1, v1 = self._samples[-1]
        if t1 <= t0:
            return 0.0
        return math.dist(v1, v0) / (t1 - t0)


def link_pose(body: int, link: int, client: int) -> Pose:
    """World pose of a link's frame (forward kinematics computed now)."""
    state = pb.getLinkState(body, link, computeForwardKinematics=True, physicsClientId=client)
    return state[4], state[5]


def offset_pose(pose: Pose, offset_m: tuple[float, float, float] | None) -> Pose:
    """``pose`` moved by ``offset_m`` in its own frame (unchanged for None)."""
    pos, orn = pose
    if offset_m is None:
        return pose
    moved, _ = pb.multiplyTransforms(pos, orn, offset_m, (0.0, 0.0, 0.0, 1.0))
    return (moved[0], moved[1], moved[2]), orn


def make_tool(
    spec: ToolSpec,
    robot: Robot,
    *,
    gravity_mps2: float = 9.81,
    materials: ClassTable | None = None,
) -> Tool:
    """The twin's tool of ``spec``'s kind, built on ``robot``'s body; ``gravity_mps2`` loads
    a held object in the carry checks; ``materials`` is the cell's class table (a suction
    cup's seal efficiency per class; None: the shipped table)."""
    if isinstance(spec, ParallelJawSpec):
        from twin.tools.parallel_jaw import ParallelJaw

        return ParallelJaw(spec, robot, gravity_mps2=gravity_mps2)
    if isinstance(spec, SuctionCupSpec):
        from twin.tools.suction_cup import SuctionCup

        return SuctionCup(spec, robot, gravity_mps2=gravity_mps2, materials=materials)
    msg = f"tool {spec.name!r}: no twin model for tool kind {spec.kind!r}"
    raise NotImplementedError(msg)


__all__ = [
    "DROP_REASONS",
    "Candidate",
    "HeldObject",
    "Normal",
    "Pose",
    "TcpAccelerometer",
    "Tool",
    "make_tool",
]
