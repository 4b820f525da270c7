"""The parallel-jaw gripper, twin side: the Panda hand, the xArm gripper, any two-finger jaw.

Command: the opening in metres, 0 (closed) to ``max_opening_m``. Each finger joint is driven
linearly from ``joint_closed`` to ``joint_open`` as the opening goes from 0 to the full opening
(position control, each finger with its URDF effort limit, at least ``min_finger_force_N``);
the measured opening is the mean of the finger joints' fractions times the full opening. On
``joint_states`` each finger joint reports half the measured opening (velocity 0), whatever
the joint's own unit, so a controller reads the opening as twice their mean.

Grasp rule (the reference's; the monitor adds the TCP dwell and the pick window): both finger
links touch the object from opposite sides (their contact normals point against each other)
while the gripper presses: its commanded opening is narrower than its measured one by more
than :data:`GRIP_TOLERANCE_M` (the fingers stop on the object while the target lies inside it,
whatever the object's width). A held object is let go once the gripper no longer presses:
commanded no narrower than measured, within half the tolerance (:data:`RELEASE_GAP_M`; so a
jaw-wide object, which holds the fingers at full opening where commanding "open" cannot exceed
the measured opening, is let go too; ``pick_dropped`` reason ``released`` if away from the bins).
An object whose centre of mass is within the full opening of the TCP horizontally is being
handled: touching it is no unintended contact.

Slip (a jaw with ``grip_force_N``): every physics step of the carry, the friction the two pads
can carry, ``2 mu grip_force_N`` (``mu`` the held object's friction coefficient, as spawned), is
checked against ``mass (g + |a|)`` (``a`` the TCP's measured acceleration,
:class:`twin.tools.TcpAccelerometer`): exceeded, the object slips out (reason ``slipped``). The
finger links of such a jaw get a lateral friction of 1, so the contact's friction in PyBullet
(the product of both bodies') is the object's, as the rule assumes; once an object slipped, the
pads have no friction (it slides out, whatever PyBullet's friction would still carry) and the
jaw grasps nothing until it has opened (no longer presses).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pybullet as pb

from interfaces.tools import ParallelJawSpec
from twin.robot import Robot
from twin.tools import (
    RELEASED,
    SLIPPED,
    Candidate,
    HeldObject,
    Normal,
    Pose,
    TcpAccelerometer,
    link_pose,
    offset_pose,
)

GRIP_TOLERANCE_M = 0.0005
"""How much narrower than the measured opening the gripper must be commanded to count as
pressing (a grip starts)."""

PAD_FRICTION = 1.0
"""Lateral friction of the finger pads of a jaw with a grip force (the contact's is then the
object's)."""

RELEASE_GAP_M = -0.5 * GRIP_TOLERANCE_M
"""Commanded minus measured opening above which a held object is let go: the gripper no longer
presses. Between this and ``-GRIP_TOLERANCE_M`` a grip neither starts nor ends (no flicker)."""


class ParallelJaw:
    """A parallel-jaw gripper on ``robot``'s body (see the module docstring)."""

    def __init__(self, spec: ParallelJawSpec, robot: Robot, *, gravity_mps2: float = 9.81) -> None:
        self.spec = spec
        self.body = robot.body
        self.client = robot.client
        self.tcp_link = robot.link_index(spec.tcp_link, "TCP link")
        self._fingers = [robot.joint_index(name, "finger joint") for name in spec.joints]
        links = [robot.link_index(name, "finger link") for name in spec.links]
        self.contact_links: Mapping[int, int] = {link: i for i, link in enumerate(links)}
        self.joint_names = spec.joints
        self.max_command = spec.max_opening_m
        self.engaged_radius_m = spec.max_opening_m
        self._effort = [
            max(float(robot.infos[j][10]), spec.min_finger_force_N) for j in self._fingers
        ]
        self._span = tuple(zip(spec.joint_open, spec.joint_closed, strict=True))
        self._offset = None if not any(spec.tcp_offset_m) else spec.tcp_offset_m
        self._target_m = spec.max_opening_m
        self._applied_m = math.nan
        self._gravity_mps2 = gravity_mps2
        self._accelerometer = TcpAccelerometer(self.body, self.tcp_link, self.client)
        self._held: HeldObject | None = None
        self._capacity_N: float | None = None
        self._pads = links if spec.grip_force_N is not None else []
        self._slipped = False
        self._pad_friction(PAD_FRICTION)

    def reset_state(self) -> None:
        """Open the fingers at rest; the finger motors are set by the next :meth:`apply`."""
        for j, q in zip(self._fingers, self.spec.joint_open, strict=True):
            pb.resetJointState(self.body, j, q, 0.0, physicsClientId=self.client)
        self._target_m = self.spec.max_opening_m
        self._applied_m = math.nan
        self._accelerometer.reset()
        self.release()
        if self._slipped:
            self._slipped = False
            self._pad_friction(PAD_FRICTION)

    def _pad_friction(self, friction: float) -> None:
        """The lateral friction of the finger pads of a jaw with a grip force."""
        for link in self._pads:
            pb.changeDynamics(
                self.body, link, lateralFriction=friction, physicsClientId=self.client
            )

    def command(self, value: float) -> None:
        """Set the opening target in metres (0 = closed, ``max_opening_m`` = open)."""
        self._target_m = float(np.clip(value, 0.0, self.spec.max_opening_m))

    def apply(self) -> None:
        """Drive the finger joints to the opening target, if it changed since last applied."""
        if not self._fingers or self._target_m == self._applied_m:
            return
        self._applied_m = self._target_m
        frac = self._target_m / self.spec.max_opening_m
        targets = [c + frac * (o - c) for o, c in self._span]
        pb.setJointMotorControlArray(
            self.body,
            self._fingers,
            pb.POSITION_CONTROL,
            targetPositions=targets,
            forces=self._effort,
            physicsClientId=self.client,
        )

    @property
    def target_m(self) -> float:
        """The commanded opening."""
        return self._target_m

    def measured(self) -> float:
        """Measured opening (m), from the finger joints."""
        if not self._fingers:
            return 0.0
        states = pb.getJointStates(self.body, self._fingers, physicsClientId=self.client)
        fracs = [
            (s[0] - c) / (o - c) if o != c else 0.0
            for s, (o, c) in zip(states, self._span, strict=True)
        ]
        return float(np.clip(np.mean(fracs), 0.0, 1.0) * self.spec.max_opening_m)

    def joint_report(self) -> tuple[list[float], list[float]]:
        """Each finger joint's own share of the opening (half the opening when the fingers
        are symmetric), velocity 0: the fingers' links in ``/tf`` are the forward kinematics
        of what is reported, even when a grasp pushed them apart unevenly."""
        if not self._fingers:
            return [], []
        states = pb.getJointStates(self.body, self._fingers, physicsClientId=self.client)
        half = 0.5 * self.spec.max_opening_m
        report = [
            float(np.clip((s[0] - c) / (o - c), 0.0, 1.0) * half) if o != c else 0.0
            for s, (o, c) in zip(states, self._span, strict=True)
        ]
        return report, [0.0] * len(report)

    def link_pose(self) -> Pose:
        """Pose of the TCP link's frame, world."""
        return link_pose(self.body, self.tcp_link, self.client)

    def tcp_pose(self) -> Pose:
        """Pose of the TCP (the TCP link's frame moved by ``tcp_offset_m``), world."""
        return offset_pose(self.link_pose(), self._offset)

    def contact_name(self, index: int) -> str:
        """The finger link's name."""
        return self.spec.links[index]

    def gap_m(self) -> float:
        """Commanded minus measured opening: below ``-GRIP_TOLERANCE_M`` the fingers press (a
        grip on an object wider than half the opening is a grip too), above ``RELEASE_GAP_M``
        they let go."""
        return self._target_m - self.measured()

    def tick(self, time_s: float) -> None:
        """After a slip: the pads get their friction back once the jaw has opened. The TCP's
        velocity is sampled for the carry's acceleration."""
        self._accelerometer.sample(time_s)
        if self._slipped and self.releases():
            self._slipped = False
            self._pad_friction(PAD_FRICTION)

    def grasps(self, candidate: Candidate) -> bool:
        """The TCP box has overlapped the object for the dwell, both fingers touch it from
        opposite sides and the gripper presses (and has opened since a slip)."""
        return (
            not self._slipped
            and candidate.overlap_s >= self.spec.dwell_s - 1e-9
            and self._opposite(candidate.touching)
            and self.gap_m() < -GRIP_TOLERANCE_M
        )

    def releases(self) -> bool:
        """The gripper no longer presses."""
        return self.gap_m() > RELEASE_GAP_M

    def hold(self, held: HeldObject, time_s: float) -> None:
        """Start carrying ``held``: its friction capacity, if the jaw has a grip force."""
        self._held = held
        force = self.spec.grip_force_N
        self._capacity_N = None if force is None else 2.0 * held.friction * force
        del time_s

    def carry(self, time_s: float) -> str | None:
        """``released`` once the gripper no longer presses; ``slipped`` once the load exceeds
        the friction capacity; None while it holds."""
        if self.releases():
            return RELEASED
        if self._capacity_N is not None and self._held is not None:
            load = self._held.mass_kg * (self._gravity_mps2 + self._accelerometer.magnitude(time_s))
            if self._capacity_N < load:
                self._slipped = True
                self._pad_friction(0.0)
                return SLIPPED
        return None

    def release(self) -> None:
        """Forget the held object."""
        self._held = None
        self._capacity_N = None

    def _opposite(self, touching: Mapping[int, Normal]) -> bool:
        n = len(self.contact_links)
        if n < 2 or len(touching) < n:
            return False
        normals = list(touching.values())
        dot = sum(a * b for a, b in zip(normals[0], normals[1], strict=True))
        return dot < 0.0
