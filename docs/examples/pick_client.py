"""A pick-and-place client for the reference cell, written from the contract alone.

It uses only what ``docs/interfaces.md``, ``docs/metrics.md`` and the ``cdw_interfaces``
messages state: topic names, types and QoS; the Panda's URDF (``franka_panda/panda.urdf`` of
``pybullet_data``) with the page's joint limits in force; the TCP frame, the jaws' closing
axis and geometry; the pick-success rule (TCP box, dwell, pick window); the bins, read from
the wire (``cell/bins``). It imports nothing of the project's ``twin``, ``control`` or
``interfaces`` packages: a stranger's controller, realtime only (no lockstep handshake).

What it does, naively:

- tracks the camera's detections with the belt's measured speed (``/conveyor/state``): each
  detection joins the nearest track predicted to its capture time, and is averaged in;
- targets only pieces the Panda hand takes comfortably: narrow side at most
  :data:`MAX_WIDTH_M`, at least the pads' height tall, lying on the belt, its centroid on the
  piece, no neighbour where the open fingers or the palm come down, a class some bin sorts,
  and a path the arm can follow at the grasp height;
- announces each target on ``controller/target`` (the twin counts one pursuit per target: the
  ``targeted`` of the success rate), meets it above its predicted position with one joint-space
  move ending at the belt's velocity, follows it down to the grasp height, dwells, closes,
  lifts, carries it to the bin of its class and opens there;
- streams one ``JointTrajectory`` point (positions and velocities, within the limits) per
  control tick, stamped with the ``joint_states`` stamp it was computed from.

Run it beside a twin node on the same ``ROS_DOMAIN_ID``; it exits when ``joint_states`` stop::

    cdw-twin twin-node --speed 0.2 --mode realtime --duration 60 --out runs/ep0 &
    python docs/examples/pick_client.py --duration 60 --stats runs/ep0/client.json
"""

# rclpy's annotations are partial.
# mypy: disable-error-code="no-untyped-call,misc"

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet_data
import rclpy
from cdw_interfaces.msg import BeltState, DetectionArray, PickTarget, SortingBins
from numpy.typing import NDArray
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import try_shutdown
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

Vec = NDArray[np.float64]

# -- the contract's numbers (docs/interfaces.md: The robot, Joint limits, Stations, Tools) -------
URDF = Path(pybullet_data.getDataPath()) / "franka_panda" / "panda.urdf"
ARM_JOINTS = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGER_JOINTS = ("panda_finger_joint1", "panda_finger_joint2")
TCP_FRAME = "panda_grasptarget"
LOWER_RAD = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
UPPER_RAD = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
VELOCITY_RPS = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])
ACCELERATION_RPS2 = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])
PICK_WINDOW_X_M = (-0.35, 0.35)
FULL_OPENING_M = 0.08
PADS_GAP_M = 0.0778  # the pads' gap at full opening
PAD_HEIGHT_M = 0.02
FINGER_HALF_X_M = 0.0115  # the open fingers, TCP frame: |x| up to this, |y| up to the outer faces
FINGER_OUTER_Y_M = 0.0674
FINGERTIP_BEYOND_TCP_M = 0.0082
PALM_ABOVE_TCP_M = 0.038
PALM_HALF_X_M, PALM_HALF_Y_M = 0.0326, 0.105
DWELL_S = 0.6

# -- this client's choices ----------------------------------------------------------------------
MAX_WIDTH_M = PADS_GAP_M - 0.018  # narrow side: room for the errors of width and position
CLEARANCE_M = 0.01  # between a neighbour's footprint and the open fingers or the palm
APPROACH_ABOVE_TOP_M = 0.05
GRASP_BELOW_TOP_M = 0.02
MIN_TCP_Z_M = FINGERTIP_BEYOND_TCP_M + 0.004  # the fingertips 4 mm clear of the belt
DESCEND_S, CLOSE_AFTER_S, LIFT_S, RELEASE_S = 0.35, 0.35, 0.5, 0.35
HOLD_S = DWELL_S - CLOSE_AFTER_S + 0.3  # closed, following: the dwell ends meanwhile
LIFT_M = 0.15
DROP_ABOVE_RIM_M = 0.25
READY_TCP_M = (-0.15, 0.45, 0.22)
SPEED_SCALE, ACCEL_SCALE = 0.6, 0.4  # of the joint limits, for every planned move
CONTROL_HZ = 100.0
CYCLE_S = 9.0  # the longest a pick takes from its choice to the release, waiting included


def qos(depth: int, *, latched: bool = False) -> QoSProfile:
    """Reliable, keep last ``depth``, transient local when ``latched`` (the page's QoS)."""
    durability = DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE
    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE, durability=durability)


def stamp_s(stamp: object) -> float:
    """Seconds of a ``builtin_interfaces/Time``."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)  # type: ignore[attr-defined]


def down(yaw_rad: float) -> Vec:
    """Rotation ``(3, 3)`` of a TCP pointing down with yaw ``yaw_rad`` (``Rz(yaw) Rx(pi)``):
    x = (cos, sin, 0), and y = (sin, -cos, 0), the axis the jaws close along."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])


def smooth(u: float) -> tuple[float, float]:
    """Minimum-jerk blend ``s(u)`` and ``ds/du`` for ``u`` in [0, 1] (clipped)."""
    u = min(max(u, 0.0), 1.0)
    return 10 * u**3 - 15 * u**4 + 6 * u**5, 30 * u**2 - 60 * u**3 + 30 * u**4


Rect = tuple[Vec, float, float, float]
"""A rectangle on the belt: centre ``(2,)``, yaw (rad), half extents along its x and y (m)."""


def overlap(a: Rect, b: Rect) -> bool:
    """Whether two rectangles intersect (separating axes)."""

    def corners(r: Rect) -> Vec:
        c, yaw, hx, hy = r
        u = np.array([math.cos(yaw), math.sin(yaw)])
        v = np.array([-u[1], u[0]])
        return np.array([c + sx * hx * u + sy * hy * v for sx in (-1, 1) for sy in (-1, 1)])

    ca, cb = corners(a), corners(b)
    for yaw in (a[1], a[1] + 0.5 * math.pi, b[1], b[1] + 0.5 * math.pi):
        axis = np.array([math.cos(yaw), math.sin(yaw)])
        pa, pb = ca @ axis, cb @ axis
        if pa.max() < pb.min() or pb.max() < pa.min():
            return False
    return True


class Arm:
    """Forward and inverse kinematics of the TCP (Pinocchio, the fingers locked)."""

    def __init__(self) -> None:
        full = pin.buildModelFromUrdf(str(URDF))
        locked = [full.getJointId(name) for name in FINGER_JOINTS]
        self.model = pin.buildReducedModel(full, locked, pin.neutral(full))
        self.data = self.model.createData()
        self.frame = self.model.getFrameId(TCP_FRAME)

    def fk(self, q: Vec) -> pin.SE3:
        """``oMtcp``: the TCP's pose in ``world`` (the robot's base is ``world``)."""
        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.frame].copy()

    def ik(self, oMgoal: pin.SE3, seed: Vec) -> Vec | None:  # noqa: N803
        """Joint positions ``(7,)`` putting the TCP at ``oMgoal``, 0.05 rad inside the limits
        in force, by damped least squares from ``seed``; None when it does not converge."""
        q = np.clip(seed, LOWER_RAD + 0.05, UPPER_RAD - 0.05)
        for _ in range(60):
            error = pin.log6(self.fk(q).actInv(oMgoal)).vector
            if np.linalg.norm(error) < 1e-5:
                return q
            jac = pin.computeFrameJacobian(self.model, self.data, q, self.frame, pin.LOCAL)
            step = jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), error)
            q = np.clip(q + step, LOWER_RAD + 0.05, UPPER_RAD - 0.05)
        return None

    def joint_velocity(self, q: Vec, tcp_velocity_mps: Vec) -> Vec:
        """Joint velocities ``(7,)`` moving the TCP at ``tcp_velocity_mps`` ``(3,)``, unturned."""
        jac = pin.computeFrameJacobian(
            self.model, self.data, q, self.frame, pin.LOCAL_WORLD_ALIGNED
        )
        twist = np.concatenate([tcp_velocity_mps, np.zeros(3)])
        return np.asarray(jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), twist))


@dataclass(frozen=True, kw_only=True)
class JointMove:
    """A quintic from ``(q0, v0)`` at ``t0_s`` to ``(q1, v1)`` at ``t1_s`` (each ``(7,)``),
    accelerations zero at both ends; after ``t1_s`` it goes on at ``v1``."""

    q0: Vec
    v0: Vec
    q1: Vec
    v1: Vec
    t0_s: float
    t1_s: float

    def at(self, t_s: float) -> tuple[Vec, Vec, Vec]:
        """Positions, velocities and accelerations ``(7,)`` at ``t_s``."""
        if t_s >= self.t1_s:
            return self.q1 + self.v1 * (t_s - self.t1_s), self.v1, np.zeros(7)
        d = self.t1_s - self.t0_s
        u = max(t_s - self.t0_s, 0.0) / d
        dq, a0, a1 = self.q1 - self.q0, self.v0 * d, self.v1 * d
        c3, c4, c5 = 10 * dq - 6 * a0 - 4 * a1, -15 * dq + 8 * a0 + 7 * a1, 6 * dq - 3 * a0 - 3 * a1
        q = self.q0 + a0 * u + c3 * u**3 + c4 * u**4 + c5 * u**5
        v = (a0 + 3 * c3 * u**2 + 4 * c4 * u**3 + 5 * c5 * u**4) / d
        return q, v, (6 * c3 * u + 12 * c4 * u**2 + 20 * c5 * u**3) / d**2

    @classmethod
    def within_limits(
        cls, q0: Vec, v0: Vec, q1: Vec, v1: Vec, t0_s: float, end_s: float = 0.0
    ) -> JointMove:
        """The shortest such move ending no earlier than ``end_s`` whose velocities and
        accelerations stay within the scaled limits (a joint faster than that at an end may
        keep its end speed); the duration grows by 5 % until they do."""
        speed = np.maximum(SPEED_SCALE * VELOCITY_RPS, np.maximum(np.abs(v0), np.abs(v1)))
        duration = max(0.2, end_s - t0_s, float(np.max(np.abs(q1 - q0) / speed)))
        for _ in range(100):
            move = cls(q0=q0, v0=v0, q1=q1, v1=v1, t0_s=t0_s, t1_s=t0_s + duration)
            samples = [move.at(t0_s + duration * k / 40) for k in range(41)]
            if all(
                np.all(np.abs(v) <= speed) and np.all(np.abs(a) <= ACCEL_SCALE * ACCELERATION_RPS2)
                for _, v, a in samples
            ):
                break
            duration *= 1.05
        return move


@dataclass
class Track:
    """One piece seen by the camera: its footprint centroid ``(2,)`` at ``stamp_s``, its last
    seen extents, and the confidence each class got over its detections."""

    track_id: int
    xy_m: Vec
    stamp_s: float
    yaw_rad: float = 0.0
    width_m: float = 0.0
    length_m: float = 0.0
    height_m: float = 0.0
    base_z_m: float = 0.0
    off_piece: bool = False
    hits: int = 0
    votes: dict[str, float] = field(default_factory=dict)

    def at(self, t_s: float, speed_mps: float) -> Vec:
        """The centroid ``(2,)`` predicted to ``t_s``: it rides the belt along +x."""
        return np.asarray(self.xy_m + np.array([speed_mps * (t_s - self.stamp_s), 0.0]))

    @property
    def class_name(self) -> str:
        """The class with the most confidence."""
        return max(self.votes, key=self.votes.__getitem__)

    @property
    def grasp_z_m(self) -> float:
        """The TCP's height at the grasp: below the top, the fingertips clear of the belt."""
        top = self.base_z_m + self.height_m
        return max(top - GRASP_BELOW_TOP_M, 0.5 * top, MIN_TCP_Z_M)


@dataclass
class Pick:
    """The pick under way: its piece, the grasp yaw, the phase and when it started."""

    track: Track
    yaw_rad: float
    above_z_m: float
    meet_s: float
    meet_xy_m: Vec
    phase: str
    phase_s: float
    lift_from: Vec = field(default_factory=lambda: np.zeros(3))


class PickClient(Node):
    """The client: inputs in callbacks, one control step per timer tick."""

    def __init__(self, *, last_start_s: float = math.inf) -> None:
        super().__init__("pick_client")
        self.last_start_s = last_start_s
        self.arm = Arm()
        self.bins: dict[str, tuple[float, float, float]] = {}
        self.tracks: list[Track] = []
        self.next_id = 1
        self.speed_mps, self.setpoint_mps = 0.0, 0.0
        self.stamp: object | None = None
        self.now_s = 0.0
        self.q, self.opening_m, self.seen_wall_s = np.zeros(7), FULL_OPENING_M, 0.0
        self.move: JointMove | None = None
        self.cmd_q, self.cmd_v = np.zeros(7), np.zeros(7)
        self.pick: Pick | None = None
        self.chosen_s = 0.0
        self.gripper_m, self.gripper_sent_s, self.announced_s = FULL_OPENING_M, -1.0, -1.0
        self.stats: dict[str, int] = {"targeted": 0, "completed": 0, "aborted": 0}
        self.create_subscription(JointState, "joint_states", self.on_joints, qos(10))
        self.create_subscription(BeltState, "/conveyor/state", self.on_belt, qos(10))
        self.create_subscription(DetectionArray, "/objects/detections", self.on_frame, qos(10))
        self.create_subscription(SortingBins, "cell/bins", self.on_bins, qos(1, latched=True))
        self.arm_pub = self.create_publisher(
            JointTrajectory, "arm_controller/joint_trajectory", qos(10)
        )
        self.gripper_pub = self.create_publisher(Float64, "gripper/command", qos(10))
        self.target_pub = self.create_publisher(PickTarget, "controller/target", qos(10))
        self.create_timer(1.0 / CONTROL_HZ, self.step)

    # -- inputs ---------------------------------------------------------------------------------
    def on_joints(self, msg: JointState) -> None:
        """The arm's joints, by name, and the opening: twice the fingers' mean."""
        pos = dict(zip(msg.name, msg.position, strict=True))
        self.q = np.array([pos[name] for name in ARM_JOINTS])
        self.opening_m = pos[FINGER_JOINTS[0]] + pos[FINGER_JOINTS[1]]
        self.stamp, self.now_s = msg.header.stamp, stamp_s(msg.header.stamp)
        self.seen_wall_s = time.monotonic()

    def on_belt(self, msg: BeltState) -> None:
        """The belt's measured speed: the velocity of every piece lying on it."""
        self.speed_mps, self.setpoint_mps = msg.speed_mps, msg.setpoint_mps

    def on_bins(self, msg: SortingBins) -> None:
        """Where each class goes: over the bin's centre, above its rim."""
        for b in msg.bins:
            self.bins[b.class_name] = (b.position.x, b.position.y, b.position.z + DROP_ABOVE_RIM_M)

    def on_frame(self, msg: DetectionArray) -> None:
        """Each detection joins the nearest track predicted to the capture time (within 3 cm),
        or starts one; a track unseen for 0.3 s is dropped."""
        t = stamp_s(msg.header.stamp)
        free = list(self.tracks)
        for det in msg.detections:
            xy = np.array([det.position.x, det.position.y])
            dist = {id(k): float(np.linalg.norm(k.at(t, self.speed_mps) - xy)) for k in free}
            near = min(free, key=lambda k: dist[id(k)], default=None)
            if near is None or dist[id(near)] > 0.03:
                near = Track(track_id=self.next_id, xy_m=xy, stamp_s=t)
                self.next_id += 1
                self.tracks.append(near)
            else:
                free.remove(near)
                near.xy_m, near.stamp_s = 0.5 * (near.at(t, self.speed_mps) + xy), t
            suction = math.hypot(det.suction_point.x - xy[0], det.suction_point.y - xy[1])
            near.off_piece = det.suction_radius_m > 0 and suction > det.suction_radius_m
            near.yaw_rad, near.width_m, near.length_m = det.yaw_rad, det.width_m, det.length_m
            near.height_m, near.base_z_m, near.hits = det.height_m, det.position.z, near.hits + 1
            near.votes[det.class_name] = near.votes.get(det.class_name, 0.0) + det.confidence
        self.tracks = [k for k in self.tracks if t - k.stamp_s < 0.3]

    # -- control --------------------------------------------------------------------------------
    def step(self) -> None:
        """One control tick: choose or follow the pick, command the arm, the jaws, the target."""
        if self.stamp is None:
            return
        if time.monotonic() - self.seen_wall_s > 2.0:
            raise SystemExit(0)  # the twin has stopped
        t = self.now_s
        if self.move is None:
            self.cmd_q, self.move = self.q.copy(), self.to_ready(self.q, np.zeros(7), t)
        steady = abs(self.speed_mps - self.setpoint_mps) < 0.005  # predictions hold
        if self.pick is None and self.bins and steady and self.last_start_s > t >= self.chosen_s:
            self.chosen_s = t + 0.1  # look for a target at 10 Hz
            self.choose(t)
        q, v = self.follow(t)
        self.cmd_q = np.clip(q, LOWER_RAD, UPPER_RAD)
        self.cmd_v = np.clip(v, -0.95 * VELOCITY_RPS, 0.95 * VELOCITY_RPS)
        point = JointTrajectoryPoint(positions=self.cmd_q.tolist(), velocities=self.cmd_v.tolist())
        msg = JointTrajectory(joint_names=list(ARM_JOINTS), points=[point])
        msg.header.stamp = self.stamp
        self.arm_pub.publish(msg)
        if t - self.gripper_sent_s > 0.2:
            self.grip(self.gripper_m, t)
        if self.pick is not None and t - self.announced_s > 0.1:
            self.announce(t)

    def to_ready(self, q: Vec, v: Vec, t: float) -> JointMove:
        """A move to the ready pose, above the belt upstream of the window."""
        seed = np.array([0.8, 0.0, 0.0, -2.2, 0.0, 2.2, 0.785])
        goal = self.arm.ik(pin.SE3(down(0.0), np.array(READY_TCP_M)), seed)
        return JointMove.within_limits(q, v, q if goal is None else goal, np.zeros(7), t)

    def grip(self, opening_m: float, t: float) -> None:
        """Command the jaws' opening (repeated every 0.2 s)."""
        self.gripper_m, self.gripper_sent_s = opening_m, t
        self.gripper_pub.publish(Float64(data=opening_m))

    def announce(self, t: float) -> None:
        """``controller/target``: the piece pursued, where the TCP grasps it, the phase."""
        pick = self.pick
        assert pick is not None
        k = pick.track
        msg = PickTarget(
            track_id=k.track_id, class_name=k.class_name, yaw_rad=pick.yaw_rad, phase=pick.phase
        )
        msg.header.stamp, msg.header.frame_id = self.stamp, "world"
        x, y = k.at(t, self.speed_mps)
        msg.grasp_point.x, msg.grasp_point.y, msg.grasp_point.z = float(x), float(y), k.grasp_z_m
        msg.velocity.x = self.speed_mps
        self.target_pub.publish(msg)
        self.announced_s = t

    def fits(self, k: Track, t: float) -> bool:
        """Whether the hand takes this piece comfortably, clear of its neighbours."""
        if (
            k.hits < 3
            or k.class_name not in self.bins
            or k.off_piece
            or k.base_z_m > 0.005
            or min(k.width_m, k.length_m) > MAX_WIDTH_M
            or k.height_m < PAD_HEIGHT_M
        ):
            return False
        centre = k.at(t, self.speed_mps)
        fingers = (centre, k.yaw_rad, FINGER_HALF_X_M + CLEARANCE_M, FINGER_OUTER_Y_M + CLEARANCE_M)
        palm = (centre, k.yaw_rad, PALM_HALF_X_M + CLEARANCE_M, PALM_HALF_Y_M + CLEARANCE_M)
        for o in self.tracks:
            other = (o.at(t, self.speed_mps), o.yaw_rad, 0.5 * o.length_m, 0.5 * o.width_m)
            tall = o.base_z_m + o.height_m > k.grasp_z_m + PALM_ABOVE_TCP_M - CLEARANCE_M
            if o is not k and (overlap(fingers, other) or (tall and overlap(palm, other))):
                return False
        return True

    def choose(self, t: float) -> None:
        """Target the most downstream piece that fits and can be met in time; announce it."""
        assert self.move is not None
        q0, v0, _ = self.move.at(t)
        for k in sorted(self.tracks, key=lambda k: -k.at(t, self.speed_mps)[0]):
            above_z = k.base_z_m + k.height_m + APPROACH_ABOVE_TOP_M
            plan = self.meeting(k, q0, v0, t, above_z) if self.fits(k, t) else None
            if plan is not None:
                self.move, yaw = plan
                self.pick = Pick(
                    track=k,
                    yaw_rad=yaw,
                    above_z_m=above_z,
                    meet_s=self.move.t1_s,
                    meet_xy_m=k.at(self.move.t1_s, self.speed_mps),
                    phase="approach",
                    phase_s=t,
                )
                self.stats["targeted"] += 1
                self.log(f"target {k.track_id} ({k.class_name}, {k.width_m:.3f} m wide)")
                self.announce(t)
                return

    def meeting(
        self, k: Track, q0: Vec, v0: Vec, t: float, above_z: float
    ) -> tuple[JointMove, float] | None:
        """A joint move from ``(q0, v0)`` ending above the piece at its velocity, early enough
        that the grasp completes in the pick window, and the grasp yaw (the meeting time is a
        fixed point: no earlier than the move can end, nor than the piece reaches 5 cm into the
        window); None when there is none."""
        window_lo, window_hi = PICK_WINDOW_X_M
        grasp_s = DESCEND_S + CLOSE_AFTER_S + HOLD_S
        latest_x = window_hi - self.speed_mps * grasp_s - 0.05
        wait_s = (window_lo + 0.05 - k.at(t, self.speed_mps)[0]) / max(self.speed_mps, 0.01)
        meet_s = t + max(0.5, wait_s)
        for _ in range(4):
            if meet_s > t + 3.0 or k.at(meet_s, self.speed_mps)[0] > latest_x:
                return None
            x, y = k.at(meet_s, self.speed_mps)
            q1, yaw = self.grasp_pose(k.yaw_rad, np.array([x, y, above_z]), q0)
            if q1 is None:
                return None
            v1 = self.arm.joint_velocity(q1, np.array([self.speed_mps, 0.0, 0.0]))
            move = JointMove.within_limits(q0, v0, q1, v1, t, meet_s)
            if move.t1_s - meet_s < 0.01:
                return (move, yaw) if self.reachable(k, meet_s, yaw, q1) else None
            meet_s = move.t1_s
        return None

    def reachable(self, k: Track, meet_s: float, yaw: float, q1: Vec) -> bool:
        """Whether the TCP can follow the piece at the grasp height until it closes, and lift
        it (checked every 0.1 s of the piece's path)."""
        close_s = meet_s + DESCEND_S + CLOSE_AFTER_S + HOLD_S
        points = [[*k.at(s, self.speed_mps), k.grasp_z_m] for s in np.arange(meet_s, close_s, 0.1)]
        points.append([*k.at(close_s, self.speed_mps), k.grasp_z_m + LIFT_M])
        q: Vec | None = q1
        for p in points:
            q = self.arm.ik(pin.SE3(down(yaw), np.array(p)), q1 if q is None else q)
            if q is None:
                return False
        return True

    def grasp_pose(self, piece_yaw: float, p: Vec, q0: Vec) -> tuple[Vec | None, float]:
        """Joint positions with the TCP at ``p``, its x along the piece's long axis (of the two
        yaws, the one that turns the last joint least), and that yaw."""
        best: tuple[Vec | None, float] = (None, 0.0)
        for turn in (0.0, math.pi):
            yaw = math.atan2(math.sin(piece_yaw + turn), math.cos(piece_yaw + turn))
            seed = q0.copy()
            seed[0] = math.atan2(p[1], p[0])
            q = self.arm.ik(pin.SE3(down(yaw), p), seed)
            if q is not None and (best[0] is None or abs(q[6] - q0[6]) < abs(best[0][6] - q0[6])):
                best = (q, yaw)
        return best

    def follow(self, t: float) -> tuple[Vec, Vec]:
        """The joint positions and velocities ``(7,)`` to command at ``t``: the joint move, or,
        while the TCP is with the piece, its Cartesian path by IK."""
        if self.pick is not None:
            self.advance(self.pick, t)
        pick = self.pick
        assert self.move is not None
        if pick is None or pick.phase not in ("descend", "dwell", "close", "lift", "retreat"):
            q, v, _ = self.move.at(t)
            return q, v
        p = np.array([*pick.track.at(t, self.speed_mps), pick.track.grasp_z_m])
        vel = np.array([self.speed_mps, 0.0, 0.0])
        if pick.phase == "descend":
            s, ds = smooth((t - pick.phase_s) / DESCEND_S)
            p[2] = pick.above_z_m + (pick.track.grasp_z_m - pick.above_z_m) * s
            vel[2] = (pick.track.grasp_z_m - pick.above_z_m) * ds / DESCEND_S
        elif pick.phase in ("lift", "retreat"):  # up, the belt's velocity fading out
            u = min((t - pick.phase_s) / LIFT_S, 1.0)
            s, ds = smooth(u)
            p = pick.lift_from + np.array(
                [self.speed_mps * LIFT_S * (u - 0.5 * u * u), 0, LIFT_M * s]
            )
            vel = np.array([self.speed_mps * (1.0 - u), 0.0, LIFT_M * ds / LIFT_S])
        found = self.arm.ik(pin.SE3(down(pick.yaw_rad), p), self.cmd_q)
        if found is None:
            if pick.phase == "lift":
                self.carry(pick, t)  # held: carry it from here
            elif pick.phase == "retreat":
                self.move, self.pick = self.to_ready(self.cmd_q, self.cmd_v, t), None
            else:
                self.abort(t, "ik")
            q, v, _ = self.move.at(t)
            return q, v
        return found, self.arm.joint_velocity(found, vel)

    def advance(self, pick: Pick, t: float) -> None:
        """Move the pick to its next phase when the current one is over."""
        since = t - pick.phase_s
        if pick.phase == "approach" and t >= pick.meet_s:
            if np.linalg.norm(pick.track.at(t, self.speed_mps) - pick.meet_xy_m) > 0.02:
                self.abort(t, "moved")  # the piece is not where the approach was planned
            else:
                self.enter(pick, "descend", t)
        elif pick.phase == "descend" and since >= DESCEND_S:
            self.enter(pick, "dwell", t)
        elif pick.phase == "dwell" and since >= CLOSE_AFTER_S:
            self.grip(0.0, t)
            self.enter(pick, "close", t)
        elif pick.phase == "close" and since >= HOLD_S:
            if self.opening_m < 0.003:  # closed on nothing
                self.abort(t, "empty")
                return
            pick.lift_from = np.array([*pick.track.at(t, self.speed_mps), pick.track.grasp_z_m])
            self.enter(pick, "lift", t)
        elif pick.phase == "lift" and since >= LIFT_S:
            self.carry(pick, t)
        elif pick.phase == "carry" and self.move is not None and t >= self.move.t1_s:
            self.grip(FULL_OPENING_M, t)
            self.enter(pick, "release", t)
        elif pick.phase == "release" and since >= RELEASE_S:
            self.stats["completed"] += 1
            self.move, self.pick = self.to_ready(self.cmd_q, self.cmd_v, t), None
        elif pick.phase == "retreat" and since >= LIFT_S:
            self.move, self.pick = self.to_ready(self.cmd_q, self.cmd_v, t), None

    def carry(self, pick: Pick, t: float) -> None:
        """Move over the bin of the piece's class: mostly a turn of the base, the wrist's yaw
        turning with it."""
        x, y, z = self.bins[pick.track.class_name]
        tcp = self.arm.fk(self.cmd_q).translation
        turn = math.atan2(y, x) - math.atan2(tcp[1], tcp[0])
        seed = self.cmd_q.copy()
        seed[0] += turn
        goal = self.arm.ik(pin.SE3(down(pick.yaw_rad + turn), np.array([x, y, z])), seed)
        if goal is None:
            self.abort(t, "ik")
            return
        self.move = JointMove.within_limits(self.cmd_q, self.cmd_v, goal, np.zeros(7), t)
        self.enter(pick, "carry", t)

    def enter(self, pick: Pick, phase: str, t: float) -> None:
        """Start ``phase`` now and announce it."""
        pick.phase, pick.phase_s = phase, t
        self.announce(t)
        self.log(f"{phase} {pick.track.track_id} (opening {self.opening_m:.4f} m)")

    def abort(self, t: float, reason: str) -> None:
        """Give the pick up: open, and go back to the ready pose; from down by the belt, up
        first (a joint move from there would sweep through the pieces)."""
        self.stats["aborted"] += 1
        self.stats[f"aborted_{reason}"] = self.stats.get(f"aborted_{reason}", 0) + 1
        self.grip(FULL_OPENING_M, t)
        pick = self.pick
        if pick is not None and pick.phase in ("descend", "dwell", "close"):
            pick.lift_from = np.asarray(self.arm.fk(self.cmd_q).translation)
            self.enter(pick, "retreat", t)  # not a pursuit phase: the pursuit ends
            return
        if pick is not None:
            self.enter(pick, "abort", t)
        self.move, self.pick = self.to_ready(self.cmd_q, self.cmd_v, t), None

    def log(self, text: str) -> None:
        """One line on the node's log, with the sim time."""
        self.get_logger().info(f"t={self.now_s:.2f} s: {text}")


def main(argv: list[str] | None = None) -> int:
    """Run the client until the twin stops; write its counts to ``--stats``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stats", type=Path, default=None, help="write the client's counts here")
    parser.add_argument(
        "--duration",
        type=float,
        default=math.inf,
        help="the episode's sim seconds: start no pick that could not end before them",
    )
    args = parser.parse_args(argv)
    rclpy.init()
    node = PickClient(last_start_s=args.duration - CYCLE_S)
    try:
        rclpy.spin(node)
    except (SystemExit, KeyboardInterrupt, ExternalShutdownException):
        pass  # the twin stopped, or Ctrl-C / SIGTERM
    finally:
        if args.stats is not None:
            args.stats.write_text(json.dumps(node.stats, indent=2) + "\n", encoding="utf-8")
        node.destroy_node()
        try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
