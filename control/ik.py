"""Forward and inverse kinematics of the arm's tool centre point with Pinocchio.

The model is built from the same URDF the twin loads; every joint that is not an arm joint
(fingers, ...) is locked at its neutral position, so configurations ``q`` are ``(n_arm,) float``
in the order of the robot's ``arm_joints``. Poses are Pinocchio ``SE3`` objects named
``aMb`` (pose of frame b in frame a); ``o`` is the world frame, ``base`` the robot base.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from control.config import IkConfig
from control.errors import RobotModelError
from interfaces.cell import StationSpec
from interfaces.errors import ConfigError
from interfaces.robots import RobotSpec, resolve_urdf
from interfaces.urdf import station_urdf

FloatArray = NDArray[np.float64]

_TCP_FRAME = "cdw_tcp"


def _frozen(values: FloatArray) -> FloatArray:
    out = np.array(values, dtype=np.float64)
    out.flags.writeable = False
    return out


def _reach(model: pin.Model, tcp_frame_id: int) -> tuple[FloatArray, float]:
    """The first joint's origin in the base frame ``(3,)`` and an upper bound (m) of the TCP's
    distance from it in any configuration: the sum of the lengths of the fixed offsets between
    the following joints' origins and on to the TCP (the triangle inequality; every arm joint
    is revolute, so the first joint's turn does not move its origin). Loose where the links
    are offset sideways (a UR10 with a cup: 1.9 m against its 1.3 m reach), but what lies
    beyond it can never be reached."""
    for joint_id in range(1, model.njoints):
        if not model.joints[joint_id].shortname().startswith("JointModelR"):
            msg = f"joint {model.names[joint_id]!r} is not revolute: the reach bound needs it"
            raise RobotModelError(msg)
    origin = np.array(model.jointPlacements[1].translation, dtype=np.float64)
    length_m = sum(
        float(np.linalg.norm(model.jointPlacements[j].translation)) for j in range(2, model.njoints)
    )
    frame = model.frames[tcp_frame_id]
    length_m += float(np.linalg.norm(frame.placement.translation))
    return _frozen(origin), length_m + 1e-6


WRIST_REACH_MARGIN_M = 0.01
"""Added to the farthest wrist distance the search of :func:`_farthest_wrist_m` finds."""


def _farthest_wrist_m(model: pin.Model, joint_id: int) -> float:
    """The farthest (m) the origin of joint ``joint_id`` gets from the first joint's origin
    within the joint limits: the best of a projected gradient ascent on the squared distance
    from the 16 farthest of 2,048 seeded random configurations and every corner of the limits
    of the joints before it (deterministic: the same model gives the same figure)."""
    data = model.createData()
    lower = np.asarray(model.lowerPositionLimit, dtype=np.float64)
    upper = np.asarray(model.upperPositionLimit, dtype=np.float64)
    origin = np.asarray(model.jointPlacements[1].translation, dtype=np.float64)

    def squared(q: FloatArray) -> float:
        pin.forwardKinematics(model, data, q)
        offset = np.asarray(data.oMi[joint_id].translation) - origin
        return float(offset @ offset)

    rng = np.random.default_rng(0)
    starts = list(rng.uniform(lower, upper, size=(2048, model.nq)))
    moving = range(1, min(joint_id, model.nq))  # the first joint's turn keeps the distance
    for corner in itertools.product((0, 1), repeat=len(moving)):
        q = 0.5 * (lower + upper)
        for j, side in zip(moving, corner, strict=True):
            q[j] = upper[j] if side else lower[j]
        starts.append(q)
    starts.sort(key=lambda q: -squared(q))
    best = 0.0
    for start in starts[:16]:
        q, step = start, 0.1
        value = squared(q)
        for _ in range(200):
            pin.computeJointJacobians(model, data, q)  # and the placements at q
            offset = np.asarray(data.oMi[joint_id].translation) - origin
            jac = pin.getJointJacobian(model, data, joint_id, pin.LOCAL_WORLD_ALIGNED)[:3]
            gradient = 2.0 * jac.T @ offset
            trial = np.clip(q + step * gradient, lower, upper)
            trial_value = squared(trial)
            if trial_value > value:
                q, value, step = trial, trial_value, step * 1.5
            else:
                step *= 0.5
                if step < 1e-9:
                    break
        best = max(best, math.sqrt(value))
    return best


_WRIST_REACH: dict[tuple[str, int], float] = {}
""":func:`_farthest_wrist_m` per robot model (URDF, arm joints) and joint, once per process."""


def _wrist_reach(model: pin.Model, tcp_frame_id: int, key: str) -> tuple[FloatArray, float]:
    """The origin ``(3,)`` of the joint that carries the TCP, in the TCP's frame, and an upper
    bound (m) of its distance from the first joint's origin in any configuration within the
    joint limits. A tool pose fixes where that joint's origin is: farther than the bound from
    the first joint's, no configuration reaches the pose (tighter than :func:`_reach`, which
    adds the wrist and the tool at any angle).

    The bound is the smaller of the sum of the offsets between the joints' origins up to it
    (the triangle inequality: certain, but 1.66 m on a UR10 whose wrist gets 1.31 m out) and
    the farthest distance a search over the joint limits finds (:func:`_farthest_wrist_m`,
    ``key`` names the model for its cache) plus :data:`WRIST_REACH_MARGIN_M`: a search, not a
    proof, hence the margin, and ``tests/control/test_ik_reach.py`` checks it against random
    configurations and the solver. Out there the solver only failed after all its iterations:
    the idle stations' schedulers asked about every piece coming into reach."""
    frame = model.frames[tcp_frame_id]
    length_m = sum(
        float(np.linalg.norm(model.jointPlacements[j].translation))
        for j in range(2, frame.parentJoint + 1)
    )
    cache_key = (key, frame.parentJoint)
    if cache_key not in _WRIST_REACH:
        _WRIST_REACH[cache_key] = _farthest_wrist_m(model, frame.parentJoint)
    searched_m = _WRIST_REACH[cache_key] + WRIST_REACH_MARGIN_M
    return _frozen(frame.placement.inverse().translation), min(length_m, searched_m)


def down_rotation(yaw_rad: float) -> FloatArray:
    """Rotation ``(3, 3) float`` of a tool pointing down (tool z = -world z), turned by yaw.

    Equals ``Rz(yaw) @ Rx(pi)``; the tool's y axis (the Panda's finger axis) is
    ``(sin yaw, -cos yaw, 0)``.
    """
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])


def tool_pose(position_m: FloatArray | tuple[float, float, float], yaw_rad: float) -> pin.SE3:
    """The world pose ``oMtool`` of a downward-pointing tool at ``position_m`` ``(3,) float``."""
    return pin.SE3(down_rotation(yaw_rad), np.asarray(position_m, dtype=np.float64))


def yaw_of(oMtool: pin.SE3) -> float:  # noqa: N803
    """Yaw of a (nearly) downward-pointing tool pose, the inverse of :func:`down_rotation`."""
    rotation = np.asarray(oMtool.rotation)
    return math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))


@dataclass(frozen=True, kw_only=True, eq=False)
class IkResult:
    """Outcome of one IK solve.

    ``q`` is ``(n_arm,) float`` (read-only) and always within the joint limits; ``success`` is
    True when ``error_norm`` (norm of the ``log6`` pose error) fell below the tolerance within
    ``iterations`` iterations.
    """

    q: FloatArray
    success: bool
    iterations: int
    error_norm: float


class Kinematics:
    """FK and damped-least-squares IK of the tool centre point for one arm."""

    def __init__(
        self,
        robot: RobotSpec,
        *,
        tcp_link: str,
        tcp_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
        base_position_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
        base_yaw_rad: float = 0.0,
        ik: IkConfig | None = None,
        urdf_path: Path | None = None,
    ) -> None:
        """Build the reduced Pinocchio model of ``robot`` (arm joints only) and its TCP frame.

        The TCP is ``tcp_link`` plus ``tcp_offset_m`` in that link's frame; the base stands at
        ``base_position_m`` turned by ``base_yaw_rad`` about the world z axis. Raises
        ``RobotModelError`` when the URDF cannot be found or parsed or a joint/link is missing.
        """
        self._ik = ik if ik is not None else IkConfig()
        try:
            path = urdf_path if urdf_path is not None else resolve_urdf(robot.urdf)
        except ConfigError as exc:
            raise RobotModelError(str(exc)) from None
        try:
            full = pin.buildModelFromUrdf(str(path))
        except (RuntimeError, ValueError) as exc:
            msg = f"{path}: cannot build a Pinocchio model: {exc}"
            raise RobotModelError(msg) from exc
        model = self._reduced(full, robot.arm_joints, path)
        if not model.existFrame(tcp_link):
            msg = f"{path}: tool.tcp_link: no link or frame {tcp_link!r} in the URDF"
            raise RobotModelError(msg)
        link = model.frames[model.getFrameId(tcp_link)]
        offset = pin.SE3(np.eye(3), np.asarray(tcp_offset_m, dtype=np.float64))
        self._tcp_id = model.addFrame(
            pin.Frame(
                _TCP_FRAME,
                link.parentJoint,
                model.getFrameId(tcp_link),
                link.placement * offset,
                pin.FrameType.OP_FRAME,
            )
        )
        self._model = model
        self._data = model.createData()
        self._urdf_joints = frozenset(full.names)
        self.urdf_path = path
        """Resolved URDF file the model was built from."""
        self.joint_names: tuple[str, ...] = tuple(robot.arm_joints)
        """Arm joint names, the order of every ``q``."""
        self.lower_rad: FloatArray = _frozen(model.lowerPositionLimit)
        """Lower joint limits ``(n_arm,) float``."""
        self.upper_rad: FloatArray = _frozen(model.upperPositionLimit)
        """Upper joint limits ``(n_arm,) float``."""
        self.velocity_limit_rps: FloatArray = _frozen(model.velocityLimit)
        """Joint velocity limits ``(n_arm,) float`` from the URDF."""
        self.acceleration_limit_rps2: FloatArray = _frozen(
            np.asarray(robot.joint_max_acceleration_rps2, dtype=np.float64)
        )
        """Joint acceleration limits ``(n_arm,) float`` (the robot's datasheet)."""
        self.jerk_limit_rps3: FloatArray = _frozen(
            np.asarray(robot.joint_max_jerk_rps3, dtype=np.float64)
        )
        """Joint jerk limits ``(n_arm,) float`` (the robot's datasheet)."""
        half = 0.5 * base_yaw_rad
        base_rotation = pin.Quaternion(math.cos(half), 0.0, 0.0, math.sin(half)).toRotationMatrix()
        self.oMbase = pin.SE3(base_rotation, np.asarray(base_position_m, dtype=np.float64))
        """World pose of the robot base."""
        self._baseMo = self.oMbase.inverse()
        self.reach_origin_m, self.reach_m = _reach(model, self._tcp_id)
        """The first joint's origin in the base frame ``(3,)`` and the farthest the TCP can be from
        it (m, an upper bound): a pose beyond is refused by :meth:`solve` without iterating."""
        self._wrist_in_tcp_m, wrist_reach_m = _wrist_reach(
            model, self._tcp_id, f"{path}:{robot.arm_joints}"
        )
        margin_m = self._ik.accept_tolerance * (1.0 + float(np.linalg.norm(self._wrist_in_tcp_m)))
        self.wrist_reach_m = wrist_reach_m
        """The farthest (m) the joint carrying the TCP gets from the first joint's origin
        (:func:`_wrist_reach`; :meth:`wrist_distance_m` of a reachable pose is within it)."""
        self._wrist_reach_sq = (wrist_reach_m + margin_m + 1e-6) ** 2
        self._damping = self._ik.damping * np.eye(6)

    @classmethod
    def of_station(cls, station: StationSpec, ik: IkConfig | None = None) -> Kinematics:
        """The kinematics of a station's robot with its tool's TCP, at the station's base."""
        try:
            urdf_path = station_urdf(station.robot, station.tool)
        except ConfigError as exc:
            raise RobotModelError(str(exc)) from None
        return cls(
            station.robot,
            urdf_path=urdf_path,
            tcp_link=station.tool.tcp_link,
            tcp_offset_m=station.tool.tcp_offset_m,
            base_position_m=station.base_position_m,
            base_yaw_rad=station.base_yaw_rad,
            ik=ik,
        )

    @staticmethod
    def _reduced(full: pin.Model, arm_joints: tuple[str, ...], path: Path) -> pin.Model:
        """``full`` with every joint but the arm's locked at its neutral position."""
        for name in arm_joints:
            if not full.existJointName(name):
                msg = f"{path}: robot.arm_joints: no joint {name!r} in the URDF"
                raise RobotModelError(msg)
            joint = full.joints[full.getJointId(name)]
            if joint.nq != 1:
                msg = f"{path}: arm joint {name!r} has {joint.nq} position variables, expected 1"
                raise RobotModelError(msg)
        lock = [j for j in range(1, full.njoints) if full.names[j] not in arm_joints]
        model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
        order = [model.getJointId(name) for name in arm_joints]
        if order != sorted(order):
            msg = f"{path}: robot.arm_joints {arm_joints} are not in chain order"
            raise RobotModelError(msg)
        return model

    def has_joint(self, name: str) -> bool:
        """Whether the URDF has a joint called ``name`` (arm or not)."""
        return name in self._urdf_joints

    @property
    def nq(self) -> int:
        """Number of arm joints."""
        return int(self._model.nq)

    def within_limits(self, q: FloatArray, *, tolerance_rad: float = 1e-9) -> bool:
        """True when ``q`` ``(n_arm,) float`` is finite and inside the joint limits."""
        q = np.asarray(q, dtype=np.float64)
        return bool(
            q.shape == (self.nq,)
            and np.all(np.isfinite(q))
            and np.all(q >= self.lower_rad - tolerance_rad)
            and np.all(q <= self.upper_rad + tolerance_rad)
        )

    def fk(self, q: FloatArray) -> pin.SE3:
        """World pose ``oMtool`` of the TCP at configuration ``q`` ``(n_arm,) float``."""
        pin.framesForwardKinematics(self._model, self._data, np.asarray(q, dtype=np.float64))
        return self.oMbase * self._data.oMf[self._tcp_id]

    def beyond_reach(self, position_m: tuple[float, float, float]) -> bool:
        """Whether the world point ``position_m`` lies farther from the first joint than
        :attr:`reach_m`: :meth:`solve` then fails at once for a TCP there, whatever its
        orientation (the same test, the same arithmetic), so a caller about to try several
        yaws there can skip them all."""
        reach = self._baseMo.act(np.asarray(position_m, dtype=np.float64)) - self.reach_origin_m
        return float(reach @ reach) > self.reach_m * self.reach_m

    def solve(self, oMtool: pin.SE3, q_init: FloatArray) -> IkResult:  # noqa: N803
        """Damped least squares on the ``log6`` error from the warm start ``q_init``.

        Every iterate is clipped to the joint limits and each step to ``max_joint_step_rad``; a
        joint at a limit that the step would push beyond it is left out of that step's solve;
        iterations stop at ``tolerance``; the result is the last iterate, a ``success`` when its
        error is below ``accept_tolerance`` (near joint limits the last digits converge slowly).
        A pose farther from the first joint than :attr:`reach_m` fails at once (no iterations):
        a station's scheduler asks about every object the camera sees, most of them metres
        away along the line; so does one that puts the joint carrying the TCP beyond that
        joint's own bound (:meth:`_beyond_wrist`: a UR10's TCP 1.3-1.9 m out, where the
        iterations would fail after all of them).
        """
        cfg = self._ik
        model, data = self._model, self._data
        baseMdes = self._baseMo * oMtool  # noqa: N806
        q = np.clip(np.asarray(q_init, dtype=np.float64), self.lower_rad, self.upper_rad)
        if not np.all(np.isfinite(q)) or not np.all(np.isfinite(oMtool.homogeneous)):
            return IkResult(
                q=_frozen(np.clip(np.nan_to_num(q), self.lower_rad, self.upper_rad)),
                success=False,
                iterations=0,
                error_norm=math.inf,
            )
        reach = baseMdes.translation - self.reach_origin_m
        if float(reach @ reach) > self.reach_m * self.reach_m or self._beyond_wrist(baseMdes):
            return IkResult(q=_frozen(q), success=False, iterations=0, error_norm=math.inf)
        damping = self._damping
        error_norm = math.inf
        for iteration in range(cfg.max_iterations + 1):
            pin.framesForwardKinematics(model, data, q)
            tcpMdes = data.oMf[self._tcp_id].actInv(baseMdes)  # noqa: N806
            err = pin.log6(tcpMdes).vector
            error_norm = math.sqrt(float(err @ err))
            if error_norm < cfg.tolerance:
                return IkResult(
                    q=_frozen(q), success=True, iterations=iteration, error_norm=error_norm
                )
            if iteration == cfg.max_iterations:
                break
            jac = pin.computeFrameJacobian(model, data, q, self._tcp_id, pin.LOCAL)
            jac = -pin.Jlog6(tcpMdes.inverse()) @ jac
            dq = self._step_within_limits(jac, err, damping, q)
            if cfg.step != 1.0:
                dq *= cfg.step
            largest = float(np.abs(dq).max())
            if largest > cfg.max_joint_step_rad:
                dq *= cfg.max_joint_step_rad / largest
            # every joint is revolute with one variable (_reduced, _reach): integrating is q + dq
            q = np.minimum(np.maximum(q + dq, self.lower_rad), self.upper_rad)
        return IkResult(
            q=_frozen(q),
            success=error_norm < cfg.accept_tolerance,
            iterations=cfg.max_iterations,
            error_norm=error_norm,
        )

    def wrist_distance_m(self, oMtool: pin.SE3) -> float:  # noqa: N803
        """How far (m) the world TCP pose ``oMtool`` puts the origin of the joint carrying
        the TCP from the first joint's origin (what :attr:`wrist_reach_m` bounds)."""
        wrist = (self._baseMo * oMtool).act(self._wrist_in_tcp_m) - self.reach_origin_m
        return float(np.linalg.norm(wrist))

    def _beyond_wrist(self, baseMdes: pin.SE3) -> bool:  # noqa: N803
        """Whether the pose ``baseMdes`` (the TCP's in the base frame) puts the origin of the
        joint that carries the TCP farther from the first joint's than any configuration can
        (:func:`_wrist_reach`), by more than an accepted solution's error could move it
        (``accept_tolerance`` times one plus the wrist's distance from the TCP): such a pose
        fails after every iteration, so it is refused without one. Exact: no pose the
        iterations would accept is refused."""
        wrist = baseMdes.act(self._wrist_in_tcp_m) - self.reach_origin_m
        return float(wrist @ wrist) > self._wrist_reach_sq

    def _step_within_limits(
        self, jac: FloatArray, err: FloatArray, damping: FloatArray, q: FloatArray
    ) -> FloatArray:
        """The damped least-squares step ``(n_arm,)`` for the error ``err`` ``(6,)``, solved
        again without the joints it would push beyond a limit they are at (an active set):
        a clipped step of such a joint is lost, and the others, solved as if it moved, leave
        the error to shrink only slowly."""
        at_lower, at_upper = q <= self.lower_rad, q >= self.upper_rad
        dq = np.asarray(-jac.T @ np.linalg.solve(jac @ jac.T + damping, err))
        if not (at_lower.any() or at_upper.any()):
            return dq  # the common case: one solve
        free = np.ones(q.shape, dtype=bool)
        for _ in range(q.size - 1):
            blocked = free & ((at_lower & (dq < 0.0)) | (at_upper & (dq > 0.0)))
            if not blocked.any():
                break
            free &= ~blocked
            masked = jac * free
            dq = np.asarray(-masked.T @ np.linalg.solve(masked @ masked.T + damping, err))
        return dq

    def _jacobian_xyz_yaw(self, q: FloatArray) -> FloatArray:
        """``(4, n_arm)`` Jacobian of the world ``(x, y, z, yaw)`` of the TCP."""
        model, data = self._model, self._data
        jac = pin.computeFrameJacobian(
            model, data, np.asarray(q, dtype=np.float64), self._tcp_id, pin.LOCAL_WORLD_ALIGNED
        )
        rotation = np.asarray(self.oMbase.rotation)
        linear = rotation @ jac[:3]
        angular = rotation @ jac[3:]
        return np.vstack([linear, angular[2:3]])

    def tcp_velocity(self, q: FloatArray, dq: FloatArray) -> FloatArray:
        """World ``(vx, vy, vz, yaw rate)`` ``(4,) float`` of the TCP for joint speeds ``dq``."""
        return np.asarray(self._jacobian_xyz_yaw(q) @ np.asarray(dq, dtype=np.float64))

    def tilt_held_rates(self, q: FloatArray) -> FloatArray:
        """Joint rates ``(n_arm, 4)`` per unit world ``(vx, vy, vz, yaw rate)`` of the TCP that
        keep the tool's tilt (roll and pitch rates zero): the columns of the full Jacobian's
        pseudo-inverse for those four rates, as the IK moves a tool pointing down. Row ``j``
        times an acceleration of the TCP gives joint ``j``'s acceleration (less the velocity
        product terms)."""
        model, data = self._model, self._data
        jac = pin.computeFrameJacobian(
            model, data, np.asarray(q, dtype=np.float64), self._tcp_id, pin.LOCAL_WORLD_ALIGNED
        )
        rotation = np.asarray(self.oMbase.rotation)
        world = np.vstack([rotation @ jac[:3], rotation @ jac[3:]])
        return np.asarray(np.linalg.pinv(world)[:, [0, 1, 2, 5]])

    def joint_velocity(self, q: FloatArray, tcp_velocity: FloatArray) -> FloatArray:
        """Least-squares joint velocities ``(n_arm,)`` giving the TCP velocity ``(4,)``."""
        jac = self._jacobian_xyz_yaw(q)
        solution, *_ = np.linalg.lstsq(jac, np.asarray(tcp_velocity, dtype=np.float64), rcond=None)
        return np.asarray(solution)
