"""One station of the twin: its robot loaded at the station's base pose, its tool, its pursuits.

A :class:`Station` is built per :class:`interfaces.cell.StationSpec` when an episode starts
(the robot's body belongs to that episode's PyBullet scene). Commands go through it so the arm's
and the tool's joint motors are always set together, in the same order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from interfaces.cell import StationSpec
from interfaces.materials import ClassTable
from interfaces.urdf import station_urdf
from twin.errors import ConfigError, SceneError
from twin.robot import Robot
from twin.target_metric import TargetTracker
from twin.tools import Tool, make_tool


@dataclass(frozen=True)
class ArmCommand:
    """A command for one station's arm: joint targets ``(n,)``, optional velocities ``(n,)``,
    the tool's command (a gripper's opening in m, a suction cup's vacuum 1 or 0); ``station``
    is the station's index. ``age_s`` is how long before its arrival the command was stamped
    (the sim time it is for): a trajectory controller starts a point at its stamp, not at its
    arrival, so the targets of a command that came late are where it meant them to be now."""

    joint_positions: tuple[float, ...]
    joint_velocities: tuple[float, ...] | None = None
    gripper_width_m: float | None = None
    station: int = 0
    age_s: float = 0.0


@dataclass
class Station:
    """A station's robot and tool in one episode, and the pursuits its controller announces."""

    index: int
    spec: StationSpec
    robot: Robot
    tool: Tool
    targets: TargetTracker = field(default_factory=TargetTracker)

    @classmethod
    def load(
        cls,
        client: int,
        index: int,
        spec: StationSpec,
        *,
        dt_s: float = 1.0 / 240.0,
        gravity_mps2: float = 9.81,
        materials: ClassTable | None = None,
        visual_shapes: bool = True,
    ) -> Station:
        """Load the station's robot and build its tool; the arm at home, the tool open.
        ``dt_s`` is the physics step (the arm's joint limiter runs at that rate),
        ``gravity_mps2`` loads what the tool carries, ``materials`` is the cell's class table
        (None: the shipped one); ``visual_shapes=False`` loads the robot without its visual
        meshes (:class:`twin.robot.Robot`)."""
        try:
            urdf = station_urdf(spec.robot, spec.tool)
        except ConfigError as exc:
            raise SceneError(f"station {spec.name!r}: {exc}") from None
        robot = Robot(
            client,
            spec.robot,
            base_position_m=spec.base_position_m,
            base_yaw_rad=spec.base_yaw_rad,
            urdf=urdf,
            dt_s=dt_s,
            visual_shapes=visual_shapes,
        )
        tool = make_tool(spec.tool, robot, gravity_mps2=gravity_mps2, materials=materials)
        station = cls(index=index, spec=spec, robot=robot, tool=tool)
        station.reset()
        return station

    @property
    def name(self) -> str:
        """The station's name (events carry it as ``station``)."""
        return self.spec.name

    def reset(self) -> None:
        """Arm at home, tool in its start state, at rest; motors set."""
        self.robot.reset_state()
        self.tool.reset_state()
        self.apply()

    def apply(self) -> None:
        """Hand the arm's and the tool's targets to their motors."""
        self.robot.apply_commands()
        self.tool.apply()

    def command(self, action: ArmCommand) -> None:
        """Set the arm (and tool) targets; they hold until the next command. The tool's motors
        get its target at once, the arm's at the next :meth:`drive`."""
        n = len(self.robot.arm_joints)
        if len(action.joint_positions) != n:
            msg = (
                f"arm command has {len(action.joint_positions)} joint positions, "
                f"the robot of station {self.name!r} has {n}"
            )
            raise ConfigError(msg)
        qd = None if action.joint_velocities is None else np.asarray(action.joint_velocities)
        self.robot.command(np.asarray(action.joint_positions, dtype=float), qd, age_s=action.age_s)
        if action.gripper_width_m is not None:
            self.tool.command(action.gripper_width_m)
            self.tool.apply()

    def drive(self) -> None:
        """Once per physics step: the arm's targets (limited) to its motors."""
        self.robot.drive()

    def command_tool(self, value: float) -> None:
        """Set the tool's target (a gripper's opening in m, a suction cup's vacuum 1 or 0); it
        holds until the next command."""
        self.tool.command(value)
        self.tool.apply()
