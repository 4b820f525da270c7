"""Errors raised by the controller package.

The controller is its own process and imports nothing from ``twin``; its errors derive from the
project's base error in :mod:`interfaces.errors`, which every package may import.
"""

from __future__ import annotations

from interfaces.errors import CdwTwinError, ConfigError


class ControlError(CdwTwinError):
    """Base class of every error the controller raises on purpose."""


class ControlConfigError(ControlError, ConfigError):
    """The controller configuration (parameter file, cell, dataclass field) is invalid."""


class RobotModelError(ControlError):
    """The robot description (URDF, joint or link names) cannot be used."""


class IkError(ControlError):
    """Inverse kinematics failed or produced a configuration outside the joint limits."""


class PlanningError(ControlError):
    """The trajectory generator rejected its input or failed to compute a trajectory."""
