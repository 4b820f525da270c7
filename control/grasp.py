"""The tool's side of the pick: what to command, whether it holds, the overlap and the seal.

Pure functions of the controller's configuration, phase, target (:class:`control.pick_state.
Pursuit`) and the measured tool (:class:`control.pick_state.TcpMeasurement`), one part of
:class:`control.pick.PickController`: the tool (:mod:`control.tools`) says what to command to
grasp and release and whether the grasp holds anything; these say when.
"""

from __future__ import annotations

import math

from control.config import ControllerConfig
from control.pick_state import Pursuit, TcpMeasurement, Vec3
from control.scheduler import base_lift_m
from interfaces.phases import Phase

OVERLAP_MARGIN_M = 0.003
"""How far into the grasp box's reach the measured TCP must be before :func:`note_overlap`
counts the overlap as begun (the box's edge against the top's, measured)."""


def grasp_command(cfg: ControllerConfig, pursuit: Pursuit) -> float:
    """The tool's command when it grasps the target."""
    target = pursuit.target
    width = target.width_m if target is not None else 0.0
    return cfg.tool.grasp_command(width, cfg.pick.grip_squeeze_m)


def tool_command(cfg: ControllerConfig, phase: Phase, pursuit: Pursuit) -> float:
    """The tool's command in ``phase``: grasping while it closes, carries, and (a tool that
    grasps on the descent) descends and dwells; open otherwise."""
    grasping = (
        phase == Phase.CLOSE
        or (pursuit.carrying and phase in (Phase.LIFT, Phase.CARRY))
        or (cfg.timing.grasp_on_descent and phase in (Phase.DESCEND, Phase.DWELL))
    )
    return grasp_command(cfg, pursuit) if grasping else cfg.tool.open_command


def grasp_complete(
    cfg: ControllerConfig, phase: Phase, pursuit: Pursuit, measured: TcpMeasurement
) -> bool:
    """The tool, commanded to grasp, measures its grasp complete
    (:meth:`~control.tools.ControllerTool.grasp_complete`)."""
    return tool_command(cfg, phase, pursuit) != cfg.tool.open_command and (
        cfg.tool.grasp_complete(measured.tool_measured)
    )


def holds_nothing(cfg: ControllerConfig, pursuit: Pursuit, measured: TcpMeasurement) -> bool:
    """The tool, commanded to grasp, measured within ``pick.grip_check_margin_m`` of its
    command: nothing held it back (:meth:`~control.tools.ControllerTool.holds_nothing`)."""
    return cfg.tool.holds_nothing(
        measured.tool_measured, grasp_command(cfg, pursuit), cfg.pick.grip_check_margin_m
    )


def note_overlap(
    cfg: ControllerConfig, pursuit: Pursuit, measured: TcpMeasurement, t_s: float, aim_m: Vec3
) -> None:
    """With ``pick.dwell_from_overlap``: note (``pursuit.overlap_s``) when the measured TCP's
    grasp box (a jaw's ``tcp_half_extents_m``) first reaches down onto the target, within the
    box's half width of the grasp point ``aim_m`` and its half height of the target's top. The
    twin's grasp rule (the reference's) counts the dwell from that overlap, which begins during
    the descent: the dwell then need not wait its whole length again at the bottom."""
    half = getattr(cfg.station.tool, "tcp_half_extents_m", None)
    if not cfg.pick.dwell_from_overlap or half is None or math.isfinite(pursuit.overlap_s):
        return
    target = pursuit.target
    if target is None:
        return
    x, y, z = measured.position_m
    top_z = cfg.belt.surface_z_m + base_lift_m(target, cfg) + target.height_m
    near = math.hypot(x - aim_m[0], y - aim_m[1]) <= min(half[0], half[1])
    if near and z <= top_z + half[2] - OVERLAP_MARGIN_M:
        pursuit.overlap_s = t_s


def seal_search(
    cfg: ControllerConfig, pursuit: Pursuit, measured: TcpMeasurement, setpoint_z_m: float
) -> float:
    """One control period of the seal search (:class:`~control.config.PickConfig`): the
    seconds the close has waited so far for a seal to start. A cup that reads any vacuum
    has sealed (the search stops where it is); one that reads none waits, and goes lower
    once the arm has caught up with the setpoint's height ``setpoint_z_m``."""
    pick = cfg.pick
    vacuum = measured.tool_measured
    if (
        pick.seal_search_m <= 0.0
        or cfg.timing.close_max_s is None
        or not math.isfinite(vacuum)
        or vacuum > 0.0
    ):
        return pursuit.seal_wait_s
    period_s = cfg.motion.control_period_s
    if pursuit.seal_wait_s + period_s > pick.seal_search_max_s:
        return pursuit.seal_wait_s
    pursuit.seal_wait_s += period_s
    lag_m = measured.position_m[2] - setpoint_z_m
    if abs(lag_m) <= pick.seal_search_settled_m:
        pursuit.seal_depth_m = min(
            pick.seal_search_m, pursuit.seal_depth_m + pick.seal_search_speed_mps * period_s
        )
    return pursuit.seal_wait_s


__all__ = [
    "OVERLAP_MARGIN_M",
    "grasp_command",
    "grasp_complete",
    "holds_nothing",
    "note_overlap",
    "seal_search",
    "tool_command",
]
